"""The floors and never-rules, checked on the real import graph, and the README's API example, run as
written."""

from __future__ import annotations

import ast
import graphlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RENDERERS = ("bpy", "mitsuba", "drjit", "scgen.render")
# scgen's floors, bottom first (docs/architecture.md): a module imports from its own floor and those below
# only. "scgen" is the package root alone (its version; Generator is a lazy attribute).
FLOORS = (
    ("scgen", "scgen.errors", "scgen.io"),
    ("scgen.scenes",),
    ("scgen.render",),
    ("scgen.annotate",),
    ("scgen.generator",),
    ("scgen.dataset",),
    ("scgen.run",),
    ("scgen.assets", "scgen.preview", "scgen.doctor", "scgen.cli"),
)
# the package root's lazy `scgen.Generator` (__getattr__): the API's front door, loaded on first use only
FRONT_DOOR = "scgen -> scgen.generator"
# posenet's floors, bottom first (docs/architecture.md), held as scgen's are
POSENET_FLOORS = (
    ("posenet", "posenet.errors", "posenet.geometry"),
    ("posenet.models",),
    ("posenet.config", "posenet.checkpoint"),
    ("posenet.data",),
    ("posenet.navigation",),
    ("posenet.training",),
    ("posenet.detection",),
    ("posenet.export",),
    ("posenet.predict",),
    ("posenet.evaluation",),
    ("posenet.cli", "posenet.console", "posenet.doctor"),
)
# the package root's lazy facade (posenet.API): the Python API's front door, loaded on first use only
POSENET_FACADE = {
    "posenet.train": "posenet.training.train",
    "posenet.evaluate": "posenet.evaluation.evaluate",
    "posenet.Predictor": "posenet.predict.predictor",
    "posenet.Pose": "posenet.predict.predictor",
    "posenet.ObjectsPredictor": "posenet.predict.objects",
    "posenet.ObjectPose": "posenet.predict.objects",
    "posenet.Tracker": "posenet.predict.track",
    "posenet.make_camera": "posenet.data.camera",
}
LAZY = {
    "scgen.Generator": "scgen.generator",
    "scgen.Sample": "scgen.generator",
    **POSENET_FACADE,
}  # `from scgen import Generator`
POSENET_GATE = "scgen.io"  # the one module posenet reads scgen datasets through
# the dynamics scgen simulates, which posenet's navigation filter predicts with (one home: HCW, Euler's
# equations, a mesh's mass properties); pure numpy/scipy, loaded without the rest of scgen.scenes
POSENET_PHYSICS = ("scgen.scenes.motion.orbit", "scgen.scenes.motion.tumble")
CLI_MODULES = {"scgen/cli.py", "posenet/cli.py", "posenet/console.py"}
CLI_IMPORTS = {"click", "scgen.cli", "posenet.cli", "clishell.group"}
PACKAGES = ("scgen", "posenet")


def loaded_modules(*modules: str) -> set[str]:
    """Every module a fresh interpreter has loaded after importing `modules`."""
    code = f"import sys; import {', '.join(modules)}; print('\\n'.join(sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return set(out.stdout.split())


@pytest.mark.parametrize(
    "modules",
    [
        (
            "scgen.scenes",
            "scgen.annotate",
            "scgen.annotate.bop_labels",
            "scgen.scenes.factors",
            "scgen.io",
            "scgen.dataset.bop_dataset",
        ),
    ],
    ids=["scenes-annotate"],
)
def test_no_renderer_is_imported(modules: tuple[str, ...]) -> None:
    assert renderer_modules(loaded_modules(*modules)) == set()


def renderer_modules(names: set[str]) -> set[str]:
    return {m for m in names if m.split(".")[0] in RENDERERS or m.startswith(RENDERERS)}


def test_posenet_never_imports_a_renderer() -> None:
    """A training node has no bpy and no Mitsuba (`pip install 'scgen[train]'`): no posenet module
    imports one, or scgen's render layer, at any depth (function-level imports too), and importing every
    posenet module loads none."""
    paths = sorted(ROOT.glob("posenet/**/*.py"))
    static = {f"{p.relative_to(ROOT)}: {n}" for p in paths for n in renderer_modules(imported_names(p))}
    assert static == set()
    assert renderer_modules(loaded_modules(*(module_name(ROOT, p) for p in paths))) == set()


def test_posenet_loads_no_more_of_scgen_than_scgen_io() -> None:
    """A GPU node that runs posenet from a checkout carries what training reads: importing every posenet
    module loads no scgen module that importing scgen.io (each of its modules: it loads them on first
    use) and the physics do not (no export encoder and its pycocotools, no sampling, no config, no
    command line)."""
    paths = sorted(ROOT.glob("posenet/**/*.py"))
    loaded = loaded_modules(*(module_name(ROOT, p) for p in paths))
    io_modules = (module_name(ROOT, p) for p in sorted((ROOT / "scgen" / "io").glob("*.py")))
    gate = loaded_modules(*io_modules, *POSENET_PHYSICS)
    assert not {"scgen.scenes.sampler", "scgen.scenes.config.scene", "scgen.scenes.motion.sequence"} & gate
    assert {m for m in loaded - gate if m.split(".")[0] == "scgen"} == set()
    assert "pycocotools" not in loaded


def imported_names(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def module_name(root: Path, path: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_block(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(test)


def module_imports(tree: ast.AST, modules: set[str]) -> set[str]:
    """The modules of `modules` that `tree` imports, at any depth (function-level imports too: a cycle
    through a lazy import is still a cycle), except under `if TYPE_CHECKING:`."""
    found: set[str] = set()
    stack = [tree]
    while stack:
        node = stack.pop()
        if _type_checking_block(node):
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                found.add(full if full in modules else LAZY.get(full, node.module))
        stack.extend(ast.iter_child_nodes(node))
    return found & modules


def import_cycle(root: Path, packages: tuple[str, ...]) -> list[str]:
    """One import cycle among the modules of `packages` under `root` (graphlib's), or [] when none."""
    paths = {module_name(root, p): p for pkg in packages for p in (root / pkg).rglob("*.py")}
    graph = {m: module_imports(ast.parse(p.read_text()), set(paths)) - {m} for m, p in paths.items()}
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as exc:
        return list(exc.args[1])
    return []


def floor(name: str, floors: tuple[tuple[str, ...], ...]) -> int | None:
    """The index of the floor holding module `name` (a package root holds only itself), or None."""
    for level, prefixes in enumerate(floors):
        if any(name == p or (name.startswith(p + ".") and "." in p) for p in prefixes):
            return level
    return None


def upward_imports(root: Path, package: str, floors: tuple[tuple[str, ...], ...]) -> list[str]:
    """'module -> imported' for every import of a higher floor, at any depth (lazy imports too)."""
    paths = {module_name(root, p): p for p in (root / package).rglob("*.py")}
    found = []
    for name, path in sorted(paths.items()):
        for target in sorted(module_imports(ast.parse(path.read_text()), set(paths))):
            if floor(target, floors) is not None and floor(target, floors) > floor(name, floors):
                found.append(f"{name} -> {target}")
    return found


def test_scgen_imports_only_downward() -> None:
    modules = {module_name(ROOT, p) for p in (ROOT / "scgen").rglob("*.py")}
    assert [m for m in sorted(modules) if floor(m, FLOORS) is None] == []  # every module has a floor
    assert upward_imports(ROOT, "scgen", FLOORS) == [FRONT_DOOR]
    assert "scgen.generator" not in loaded_modules("scgen")


def test_posenet_imports_only_downward() -> None:
    modules = {module_name(ROOT, p) for p in (ROOT / "posenet").rglob("*.py")}
    assert [m for m in sorted(modules) if floor(m, POSENET_FLOORS) is None] == []  # every module has a floor
    assert upward_imports(ROOT, "posenet", POSENET_FLOORS) == []
    assert not set(POSENET_FACADE.values()) & loaded_modules("posenet")  # the facade loads on first use


def test_posenet_facade_is_the_documented_api() -> None:
    """`posenet.X` for each name of the facade is the object its module defines."""
    import posenet

    assert {f"posenet.{n}": m for n, m in posenet.API.items()} == POSENET_FACADE
    for name, module in posenet.API.items():
        assert getattr(posenet, name).__module__ == module


def test_posenet_top_level_holds_at_most_eight_modules() -> None:
    """The rest lives in the folders of the data flow: data, models, training, detection, export,
    predict, evaluation."""
    assert len(list((ROOT / "posenet").glob("*.py"))) <= 8


def test_the_floor_check_sees_the_api_reached_through_the_package_root() -> None:
    tree = ast.parse("from scgen import Generator\n")
    assert module_imports(tree, {"scgen", "scgen.generator"}) == {"scgen.generator"}


def test_the_floor_check_sees_an_upward_import(tmp_path: Path) -> None:
    (tmp_path / "pkg").mkdir()
    files = {"__init__": "", "low": "def f():\n    from pkg.high import g\n", "mid": "from pkg import low\n",
             "high": "import pkg.low\n"}  # fmt: skip
    for name, text in files.items():
        (tmp_path / "pkg" / f"{name}.py").write_text(text)
    floors = (("pkg", "pkg.low"), ("pkg.mid",), ("pkg.high",))
    assert upward_imports(tmp_path, "pkg", floors) == ["pkg.low -> pkg.high"]


def test_posenet_reads_scgen_through_one_module() -> None:
    """posenet imports scgen only through scgen.io (the BOP reader, atomic writes, EXR, images, the camera
    presets, the dataset errors), its command line included: the one-line errors are clishell's; and its
    navigation filter (posenet.navigation) the dynamics scgen simulates, from scgen.scenes.motion."""
    paths = sorted(ROOT.glob("posenet/**/*.py"))
    reached = {
        f"{p.relative_to(ROOT)}: {n}" for p in paths for n in imported_names(p) if n.split(".")[0] == "scgen"
    }
    allowed = {f"{p.relative_to(ROOT)}: {POSENET_GATE}" for p in paths}
    allowed |= {f"{p.relative_to(ROOT)}: {m}" for p in (ROOT / "posenet" / "navigation").glob("*.py")
                for m in POSENET_PHYSICS}  # fmt: skip
    assert reached - allowed == set()


def test_scgen_never_imports_posenet() -> None:
    """No arrow from scgen up into posenet, at any depth: the doctor reads posenet's training check from
    the entry points posenet registers (scgen.doctor.CHECK_GROUP)."""
    paths = sorted(ROOT.glob("scgen/**/*.py"))
    reached = {
        f"{p.relative_to(ROOT)}: {n}"
        for p in paths
        for n in imported_names(p)
        if n.split(".")[0] == "posenet"
    }
    assert reached == set()


def test_the_shell_belongs_to_neither_package() -> None:
    """clishell imports neither scgen nor posenet, and its errors module nothing at all: scgen's bottom
    floor derives ScgenError from it."""
    paths = sorted(ROOT.glob("clishell/*.py"))
    reached = {f"{p.name}: {n}" for p in paths for n in imported_names(p) if n.split(".")[0] in PACKAGES}
    assert paths and reached == set()
    assert imported_names(ROOT / "clishell" / "errors.py") == set()


def test_no_import_cycles() -> None:
    assert import_cycle(ROOT, (*PACKAGES, "clishell")) == []


def test_the_cycle_finder_sees_a_cycle_through_a_lazy_import(tmp_path: Path) -> None:
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "a.py").write_text("from pkg.b import f\n")
    (tmp_path / "pkg" / "b.py").write_text("def f():\n    from pkg import a\n")
    (tmp_path / "pkg" / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n"
    )
    assert sorted(set(import_cycle(tmp_path, ("pkg",)))) == ["pkg.a", "pkg.b"]


def test_scgen_top_level_holds_at_most_six_modules() -> None:
    """The rest lives in the folders of the data flow: scenes, render, annotate, dataset, run."""
    assert len(list((ROOT / "scgen").glob("*.py"))) <= 6


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
    section = readme[readme.index("## Python API") :]
    example = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    out = subprocess.run([sys.executable, "-c", example], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    level, group, box = out.stdout.split(maxsplit=2)
    assert level in ("weak", "normal", "strong") and group in ("none", "slight", "moderate", "heavy")
    assert box.startswith("[") and len(box.strip("[]\n").split(",")) == 4
