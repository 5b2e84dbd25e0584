"""Every script under benchmarks/ runs, and benchmarks/MANIFEST.toml catalogues them (issues 59 and 60).

Each script's --help exits 0 (all Python scripts in one process, so that torch and the renderers are
imported once), the cheap ones' smallest real run (the manifest's `try`) exits 0, a bad input ends as one
`Error:` line, no script imports another, and the manifest names exactly the scripts on disk, each with a
docs section that exists and names the script's path, and the pictures in docs/ that each figure script
draws.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
DOCS = ROOT / "docs"
MANIFEST = tomllib.loads((BENCH / "MANIFEST.toml").read_text())
KEYS = {"section", "pictures", "try"}


def scripts_on_disk() -> list[str]:
    """Every script under benchmarks/ (its path there); harness/ holds the shared code, not scripts."""
    paths = [*BENCH.rglob("*.py"), *BENCH.rglob("*.sh")]
    return sorted(str(p.relative_to(BENCH)) for p in paths if "harness" not in p.relative_to(BENCH).parts)


SCRIPTS = scripts_on_disk()
PYTHON_SCRIPTS = [s for s in SCRIPTS if s.endswith(".py")]

# run in one child process: each script as `python SCRIPT --help` runs it (its own folder first on sys.path),
# its exit status and what it printed, as JSON
HELP_ALL = r"""
import contextlib, io, json, runpy, sys
from pathlib import Path

results = {}
for path in sys.argv[1:]:
    printed = io.StringIO()
    sys.argv = [path, "--help"]
    sys.path.insert(0, str(Path(path).parent))
    try:
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
            runpy.run_path(path, run_name="__main__")
        status = "ran to the end: --help did not stop it"
    except SystemExit as exc:
        status = exc.code or 0
    except Exception as exc:
        status = repr(exc)
    finally:
        sys.path.pop(0)
    results[path] = [status, printed.getvalue()]
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def helps() -> dict[str, tuple[object, str]]:
    """Every Python script's --help: script -> (exit status, what it printed)."""
    paths = [str(BENCH / s) for s in PYTHON_SCRIPTS]
    proc = subprocess.run([sys.executable, "-c", HELP_ALL, *paths], capture_output=True, text=True,
                          timeout=300, cwd=ROOT)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads(proc.stdout.splitlines()[-1])
    return {str(Path(p).relative_to(BENCH)): (status, text) for p, (status, text) in results.items()}


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_script_answers_help(script: str, helps: dict[str, tuple[object, str]]) -> None:
    if script.endswith(".sh"):  # read first: a script that takes --help for an argument would run for real
        assert "--help" in (BENCH / script).read_text(), f"{script} does not answer --help"
        proc = subprocess.run(
            ["bash", str(BENCH / script), "--help"], capture_output=True, text=True, timeout=60
        )
        status, text = proc.returncode, proc.stdout + proc.stderr
    else:
        status, text = helps[script]
    assert status == 0, text[-3000:]
    assert f"benchmarks/{script}" in text or "usage:" in text, text[-3000:]


TRIES = [(s, entry["try"]) for s, entry in MANIFEST.items() if "try" in entry]


@pytest.mark.parametrize(("script", "args"), TRIES, ids=[s for s, _ in TRIES])
def test_cheap_scripts_smallest_run_succeeds(script: str, args: list[str], small_dataset: Path,
                                             tmp_path: Path) -> None:  # fmt: skip
    values = {"data": str(small_dataset), "tmp": str(tmp_path)}
    command = [sys.executable, str(BENCH / script), *(a.format(**values) for a in args)]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]


def run_script(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(BENCH / script), *args], capture_output=True, text=True,
                          timeout=300, cwd=ROOT)  # fmt: skip


def test_bad_input_is_one_error_line(small_dataset: Path, tmp_path: Path) -> None:
    """A user error, a missing file and a bad option each end as the command lines' do: `Error: ...`."""
    # small_dataset's default camera writes JPEG images: the twin needs PNG ones
    twin = run_script("jpeg_twin.py", str(small_dataset), str(tmp_path / "twin"))
    assert (twin.returncode, twin.stderr) == (1, f"Error: {small_dataset} holds jpg images, not PNG\n")
    missing = tmp_path / "nowhere"
    tables = run_script("figures/camera_before_after.py", "--tables", str(missing), str(missing))
    line = f"Error: {missing / 'metadata.csv'}: No such file or directory\n"
    assert (tables.returncode, tables.stderr) == (1, line)
    option = run_script("split_leakage.py", "--n", "many")
    assert option.returncode == 2
    assert option.stderr.splitlines()[-1] == "Error: argument --n: invalid int value: 'many'"


def test_manifest_lists_exactly_the_scripts_on_disk() -> None:
    unlisted, gone = sorted(set(SCRIPTS) - set(MANIFEST)), sorted(set(MANIFEST) - set(SCRIPTS))
    assert not unlisted and not gone, f"not in benchmarks/MANIFEST.toml: {unlisted}; not on disk: {gone}"
    for script, entry in MANIFEST.items():
        assert set(entry) <= KEYS and "section" in entry, script


def test_figure_scripts_name_their_pictures_and_only_they_do() -> None:
    for script, entry in MANIFEST.items():
        pictures = entry.get("pictures", [])
        assert bool(pictures) == script.startswith("figures/"), script
        for picture in pictures:
            assert (DOCS / picture).is_file(), f"{script}: docs/{picture}"


def anchor(heading: str) -> str:
    """A Markdown heading's anchor as GitHub writes it: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def section_text(page: str, anchor_name: str | None) -> str:
    """The text of `page` under the heading whose anchor is `anchor_name`, down to the next heading of the
    same or a higher level (the whole page without an anchor); headings in code blocks are not headings."""
    lines = (DOCS / page).read_text().splitlines()
    if anchor_name is None:
        return "\n".join(lines)
    fenced, start, level = False, None, 0
    for i, line in enumerate(lines):
        fenced ^= line.startswith("```")
        m = None if fenced else re.match(r"(#+) (.*)", line)
        if m is None:
            continue
        if start is not None and len(m.group(1)) <= level:
            return "\n".join(lines[start:i])
        if start is None and anchor(m.group(2)) == anchor_name:
            start, level = i, len(m.group(1))
    assert start is not None, f"docs/{page} has no heading #{anchor_name}"
    return "\n".join(lines[start:])


@pytest.mark.parametrize("script", sorted(MANIFEST))
def test_each_scripts_section_exists_and_names_it(script: str) -> None:
    page, _, anchor_name = MANIFEST[script]["section"].partition("#")
    assert f"benchmarks/{script}" in section_text(page, anchor_name or None)


def imported_modules(path: Path) -> set[str]:
    """The top-level modules a Python file imports."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_no_script_imports_another() -> None:
    """Scripts share code through benchmarks/harness/ only."""
    names = {Path(s).stem for s in PYTHON_SCRIPTS}
    for path in [*(BENCH / s for s in PYTHON_SCRIPTS), *(BENCH / "harness").glob("*.py")]:
        assert not imported_modules(path) & names, path


PACKAGES = ("scgen", "posenet")


def private_uses(path: Path) -> list[str]:
    """What `path` reaches of scgen's and posenet's private parts: a module or name imported from them
    with a leading underscore, or a `_name` attribute of something imported from them (Python's
    convention for "not API"; dunders are not private)."""
    tree = ast.parse(path.read_text())
    ours: set[str] = set()
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in PACKAGES:
            found += [node.module] if any(p.startswith("_") for p in node.module.split(".")) else []
            found += [f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
            ours |= {a.asname or a.name for a in node.names}
        elif isinstance(node, ast.Import):
            for alias in (a for a in node.names if a.name.split(".")[0] in PACKAGES):
                found += [alias.name] if any(p.startswith("_") for p in alias.name.split(".")) else []
                ours.add(alias.asname or alias.name.split(".")[0])
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            base = node.value
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(base, ast.Name) and base.id in ours:
                found.append(ast.unparse(node))
    return found


def test_scripts_use_only_public_names() -> None:
    """Benchmarks measure the packages through what they publish: no private (`_`) module, name or
    attribute of scgen or posenet, in the scripts or their harness."""
    for path in [*(BENCH / s for s in PYTHON_SCRIPTS), *(BENCH / "harness").glob("*.py")]:
        assert not private_uses(path), (path, private_uses(path))
