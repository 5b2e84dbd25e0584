"""The docs say what the CLI does: every command and every option its --help lists appears in its manual
(docs/scgen.md for scgen, docs/posenet.md for posenet). The Click groups are walked, so a new command or
option joins the check by being registered."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

from posenet.cli import main as posenet_main
from scgen.cli import main as scgen_main

DOCS = Path(__file__).resolve().parents[1] / "docs"
MANUALS = {"scgen": (scgen_main, DOCS / "scgen.md"), "posenet": (posenet_main, DOCS / "posenet.md")}
# Commands another change is adding, with their docs still to come: checked once their options are all in
# the manual (then this entry must go, see test_pending_commands_are_still_pending).
PENDING: set[str] = set()


def commands(group: click.Group, prefix: str) -> Iterator[tuple[str, click.Command]]:
    """(`prog [group] name`, command) for the group itself and every command below it."""
    yield prefix, group
    for name, command in sorted(group.commands.items()):
        if isinstance(command, click.Group):
            yield from commands(command, f"{prefix} {name}")
        else:
            yield f"{prefix} {name}", command


def undocumented(command: click.Command, text: str) -> list[str]:
    """The long options of `command` shown by --help (both sides of a --x/--no-x flag; --help itself
    left out) that `text` never names as a whole word."""
    names = [
        name
        for param in command.params
        if isinstance(param, click.Option) and not param.hidden
        for name in (*param.opts, *param.secondary_opts)
        if name.startswith("--")
    ]
    return [name for name in names if not re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text)]


def every_command() -> Iterator[tuple[str, click.Command, str]]:
    for prog, (group, manual) in MANUALS.items():
        text = manual.read_text()
        for name, command in commands(group, prog):
            yield name, command, text


@pytest.mark.parametrize("prog", list(MANUALS))
def test_every_command_and_option_is_in_its_manual(prog: str):
    group, manual = MANUALS[prog]
    text = manual.read_text()
    missing = {}
    for name, command in commands(group, prog):
        if name in PENDING:
            continue
        gaps = undocumented(command, text) + ([] if name in text else ["(the command itself)"])
        if gaps:
            missing[name] = gaps
    assert missing == {}, f"not in {manual.name}: {missing}"


def test_pending_commands_are_still_pending():
    """A pending command whose options are all documented is checked like the others: drop it from PENDING."""
    done = [
        name for name, command, text in every_command() if name in PENDING and not undocumented(command, text)
    ]
    assert done == []


def test_the_check_sees_a_missing_option():
    @click.command()
    @click.option("--split", default="test")
    @click.option("--depth/--no-depth", default=True)
    def command(split: str, depth: bool) -> None: ...

    assert undocumented(command, "`--split-by` and `--no-depth`") == ["--split", "--depth"]
    assert undocumented(command, "`--split`, `--depth` / `--no-depth`") == []
