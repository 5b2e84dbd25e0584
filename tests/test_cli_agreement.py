"""scgen and posenet agree: `--version`, exit status 1 with one `Error:` line, and the same words for a
dataset argument that is not a dataset folder."""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

import pytest
from click.testing import CliRunner

from posenet.cli import main as posenet
from scgen.cli import main as scgen
from scgen.io import NOT_A_FOLDER, not_a_dataset


def invoke(cli, *args: str | Path) -> tuple[int, list[str]]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.output.strip().splitlines()


@pytest.mark.parametrize("kind", ["missing", "file", "empty folder"])
def test_both_clis_refuse_what_is_not_a_dataset_in_the_same_words(tmp_path: Path, kind: str) -> None:
    data = tmp_path / "data"
    if kind == "file":
        data.write_text("not a dataset")
    elif kind == "empty folder":
        data.mkdir()
    commands = [
        (scgen, "validate", data, "--quiet"),
        (scgen, "stats", data),
        (scgen, "export", data, "--format", "coco", "--out", tmp_path / "coco", "--quiet"),
        (posenet, "train", "--data", data, "--out", tmp_path / "run", "--config", "smoke"),
    ]
    for cli, *args in commands:
        code, lines = invoke(cli, *args)
        assert code == 1 and len(lines) == 1, (args, lines)
        if kind == "empty folder":  # each names the file it looked for
            assert lines[0].startswith(f"Error: {not_a_dataset(data, 'has no ')}"), (args, lines)
        else:
            assert lines[0] == f"Error: {not_a_dataset(data, NOT_A_FOLDER)}", (args, lines)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data"][: int(kind != "missing")]


def test_both_clis_print_the_distribution_version() -> None:
    (code_s, [scgen_line]), (code_p, [posenet_line]) = (invoke(cli, "--version") for cli in (scgen, posenet))
    assert code_s == code_p == 0
    name_s, version_s = scgen_line.split(", version ")
    name_p, version_p = posenet_line.split(", version ")
    assert (name_s, name_p) == ("scgen", "posenet") and version_s == version_p == version("scgen")
