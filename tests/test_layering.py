"""The never-rules, checked on the real import graph, and the README's API example, run as written."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RENDERERS = ("bpy", "mitsuba", "drjit", "scgen.render")
CLI_MODULES = {"scgen/cli.py", "scgen/cli_errors.py", "posenet/cli.py"}
CLI_IMPORTS = {"click", "scgen.cli", "scgen.cli_errors", "posenet.cli"}


def loaded_modules(*modules: str) -> set[str]:
    """Every module a fresh interpreter has loaded after importing `modules`."""
    code = f"import sys; import {', '.join(modules)}; print('\\n'.join(sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return set(out.stdout.split())


@pytest.mark.parametrize(
    "modules",
    [("scgen.scenes", "scgen.annotate", "scgen.factors", "scgen.bop", "scgen.bop_dataset"), ("posenet.cli",)],
    ids=["scenes-annotate", "posenet"],
)
def test_no_renderer_is_imported(modules: tuple[str, ...]) -> None:
    loaded = loaded_modules(*modules)
    assert not [m for m in loaded if m.split(".")[0] in RENDERERS or m.startswith(RENDERERS)]


def imported_names(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_no_library_module_imports_a_command_line() -> None:
    offenders = []
    for path in sorted([*ROOT.glob("scgen/**/*.py"), *ROOT.glob("posenet/**/*.py")]):
        rel = str(path.relative_to(ROOT))
        if rel in CLI_MODULES:
            continue
        offenders += [f"{rel}: {n}" for n in imported_names(path) & CLI_IMPORTS]
    assert offenders == []


def test_the_readme_api_example_runs_as_written(tmp_path: Path) -> None:
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("### Python API") :]
    example = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    out = subprocess.run([sys.executable, "-c", example], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    level, group, box = out.stdout.split(maxsplit=2)
    assert level in ("weak", "normal", "strong") and group in ("none", "slight", "moderate", "heavy")
    assert box.startswith("[") and len(box.strip("[]\n").split(",")) == 4
