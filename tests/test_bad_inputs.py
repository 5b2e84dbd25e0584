"""Every command keeps the README's promise: a bad input gives one `Error:` line, a non-zero exit, and
leaves no file or folder behind; a missing parent folder of an output is made (the one output rule,
scgen.io.output_path).

The Click groups are walked, so a new scgen or posenet command joins the matrix by being registered: it
fails test_every_command_is_in_the_matrix until it has a SPECS entry (how to call it well) and, for the
cases that cannot apply to it, a NOT_APPLICABLE entry with the reason. The datasets are tiny real renders
(4 samples, 64x48, Mitsuba draft) and the checkpoints one-step runs, shared by the whole module. Outputs
where nothing can be written: /proc, and real tmpfs mounts (read-only; full; 64 KiB) where this machine
lets the tests mount (as root), else those cases are skipped with the reason.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from clishell.group import OneLineErrorGroup
from posenet.cli import main as posenet_main
from scgen.cli import main as scgen_main
from scgen.run.runner import RenderJob, run_render

GROUPS = {"scgen": scgen_main, "posenet": posenet_main}
MOUNTED = ("read_only", "full_disk")  # the output cases that need a mount
STORAGE = ("special_fs", *MOUNTED)  # an output where nothing can be written
CASES = (
    "missing_parent",
    "under_file",
    "existing_output",
    "wrong_checkpoint",
    "corrupt_image",
    "bad_config",
    "empty_folder",
    *STORAGE,
)
POSE_CONFIG = """\
preset: smoke
model: {input_res: 64, output_res: 16, head_channels: 32, pnp_channels: 32, fc_dims: [64, 32]}
data: {workers: 0}
optim: {batch_size: 2, epochs: 1, threads: 1}
"""
DETECTOR_CONFIG = "preset: cpu\noptim: {threads: 1, batch_size: 2, epochs: 1}\n"
SCGEN_CONFIG = "camera:\n  preset: ideal\n"
# per config kind: a file YAML cannot parse, and a value of the wrong type
BAD_CONFIGS = {
    "scgen": ("shadow: {caster_prob: [\n", "shadow: {caster_prob: often}\n"),
    "pose": ("optim: {lr: [\n", "preset: smoke\noptim: {lr: fast}\n"),
    "detector": ("optim: {lr: [\n", "preset: cpu\noptim: {lr: fast}\n"),
}
MITSUBA = "--backend mitsuba --resolution 64x48 --quality draft"
RUN = "--data {data} --out {out} --config {config} --max-steps 1"


@dataclass(frozen=True)
class Spec:
    """How to call a command well. `argv` (split at spaces) holds {placeholders}: {data} (a dataset, or
    the input folder the corrupt-image and empty-folder cases replace), {pose} and {det} (checkpoints),
    {config}, and one per output, named in `outputs` with its kind: 'file', 'folder', or 'folder/NAME'
    (a folder whose file NAME is the output). `resume`: the kind of OUT/last.pt that --resume continues."""

    argv: str
    outputs: dict[str, str] = field(default_factory=dict)
    config: str | None = None  # scgen | pose | detector
    resume: str | None = None
    input_kind: str = "dataset"  # what {data} is: dataset | backgrounds


SPECS: dict[str, Spec] = {
    "scgen render": Spec(
        f"--n 2 --out {{out}} {MITSUBA} --workers 1 --quiet --config {{config}} --backgrounds {{data}}",
        {"out": "folder"},
        config="scgen",
        input_kind="backgrounds",
    ),
    "scgen preview": Spec(
        f"--out {{out}} --n 1 {MITSUBA} --config {{config}}", {"out": "folder/preview.png"}, "scgen"
    ),
    "scgen stats": Spec(
        "{data} --json {json} --csv {csv} --plots {plots}", {"json": "file", "csv": "file", "plots": "folder"}
    ),
    "scgen validate": Spec("{data} --workers 1 --quiet"),
    "scgen merge": Spec("{out} {data}", {"out": "folder"}),
    "scgen export": Spec("{data} --format coco --out {out} --quiet", {"out": "folder"}),
    "scgen annotate": Spec("{data} --workers 1 --quiet"),
    "scgen doctor": Spec(""),
    "posenet train": Spec(RUN, {"out": "folder"}, config="pose", resume="pose"),
    "posenet train-detector": Spec(RUN, {"out": "folder"}, config="detector", resume="detector"),
    "posenet eval": Spec(
        "--data {data} --ckpt {pose} --workers 0 --json {json} --predictions {predictions} "
        "--bop-csv {bop_csv}",
        {"json": "file", "predictions": "file", "bop_csv": "file"},
    ),
    "posenet boxes": Spec("--data {data} --detector {det} --out {out}", {"out": "file"}),
    "posenet calibrate": Spec("--data {data} --ckpt {pose} --split test --workers 0 --min-confidence 0"),
    "posenet export": Spec("--ckpt {pose} --onnx {onnx}", {"onnx": "file"}),
    "posenet viz": Spec("--data {data} --ckpt {pose} --samples {test_id} --out {out}", {"out": "folder"}),
    "posenet bench": Spec("--variant gdrnet --smoke --warmup 0 --iters 1 --json {json}", {"json": "file"}),
    "posenet predict": Spec(
        "--data {data} --ckpt {pose} --detector {det} --out {out} --no-vis --device cpu", {"out": "folder"}
    ),
}

NO_OUTPUT = "writes no file"
IN_PLACE = "labels its dataset in place: no output path"
NO_STORAGE = dict.fromkeys(STORAGE, NO_OUTPUT)
NO_CHECKPOINT = "reads no checkpoint"
NO_CONFIG = "takes no config file"
NO_IMAGE = "decodes no image"
NOT_APPLICABLE: dict[str, dict[str, str]] = {
    "scgen render": {
        "existing_output": "resumes: an existing dataset is continued (a different one refused)",
        "wrong_checkpoint": NO_CHECKPOINT,
    },
    "scgen preview": {
        "wrong_checkpoint": NO_CHECKPOINT,
        "corrupt_image": "renders in memory: reads no image file",
        "empty_folder": "reads no folder",
    },
    "scgen stats": {
        "wrong_checkpoint": NO_CHECKPOINT,
        "corrupt_image": "reads the metadata table only: " + NO_IMAGE,
        "bad_config": NO_CONFIG,
    },
    "scgen validate": {
        "missing_parent": NO_OUTPUT,
        "under_file": NO_OUTPUT,
        "existing_output": NO_OUTPUT,
        "wrong_checkpoint": NO_CHECKPOINT,
        "bad_config": NO_CONFIG,
        **NO_STORAGE,
    },
    "scgen merge": {
        "wrong_checkpoint": NO_CHECKPOINT,
        "corrupt_image": "copies the files as they are: " + NO_IMAGE + " (validate does)",
        "bad_config": NO_CONFIG,
    },
    "scgen export": {"wrong_checkpoint": NO_CHECKPOINT, "bad_config": NO_CONFIG},
    "scgen annotate": {
        "missing_parent": IN_PLACE,
        "under_file": IN_PLACE,
        "existing_output": "labels its dataset in place and resumes",
        "wrong_checkpoint": NO_CHECKPOINT,
        "corrupt_image": "labels by ray casting the models: decodes no RGB image",
        "bad_config": NO_CONFIG,
        **{case: IN_PLACE + " (its input dataset, checked by the same rule)" for case in NO_STORAGE},
    },
    "scgen doctor": {
        case: "checks the machine: --out is only measured for free space, nothing is written or read"
        for case in CASES
    },
    "posenet train": {},
    "posenet train-detector": {},
    "posenet eval": {"bad_config": NO_CONFIG},
    "posenet boxes": {"bad_config": NO_CONFIG},
    "posenet calibrate": {
        **dict.fromkeys(
            ("missing_parent", "under_file", *STORAGE), "writes beside its checkpoint: no output path"
        ),
        "existing_output": "replaces the checkpoint's noise file, as re-calibrating is meant to",
        "bad_config": NO_CONFIG,
    },
    "posenet export": {
        "corrupt_image": "reads a checkpoint only",
        "bad_config": NO_CONFIG,
        "empty_folder": "takes no folder",
    },
    "posenet viz": {"bad_config": NO_CONFIG},
    "posenet bench": {
        "wrong_checkpoint": "random weights: " + NO_CHECKPOINT,
        "corrupt_image": NO_IMAGE,
        "bad_config": NO_CONFIG,
        "empty_folder": "takes no folder",
    },
    "posenet predict": {
        "corrupt_image": "a user's unreadable image is recorded in predictions.jsonl and the run goes on, "
        "exit 1 at the end (docs/posenet.md): by design, not a refusal",
        "bad_config": NO_CONFIG,
    },
}


def walk(group: click.Group, prefix: str) -> Iterator[str]:
    for name, command in sorted(group.commands.items()):
        if isinstance(command, click.Group):
            yield from walk(command, f"{prefix} {name}")
        else:
            yield f"{prefix} {name}"


COMMANDS = [name for prog, group in GROUPS.items() for name in walk(group, prog)]


def test_every_command_is_in_the_matrix():
    """A new command fails here until SPECS says how to call it and NOT_APPLICABLE what does not apply."""
    assert sorted(SPECS) == sorted(COMMANDS)
    assert sorted(NOT_APPLICABLE) == sorted(COMMANDS)
    assert all(set(cases) <= set(CASES) for cases in NOT_APPLICABLE.values())
    # every command's errors become one line through its group, without a decorator of its own
    assert all(isinstance(group, OneLineErrorGroup) for group in GROUPS.values())


# --------------------------------------------------------------------------------------------- fixtures


@dataclass
class World:
    """The shared inputs, good and bad (read-only for the tests)."""

    root: Path
    dataset: Path
    corrupt_dataset: Path
    corrupt_files: list[Path]
    backgrounds: Path
    corrupt_backgrounds: Path
    pose: Path
    det: Path
    garbage: Path
    configs: dict[str, Path]
    test_id: int


def _invoke(command: str, argv: list[str]) -> click.testing.Result:
    prog, name = command.split(" ", 1)
    return CliRunner().invoke(GROUPS[prog], [*name.split(" "), *argv])


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    root = tmp_path_factory.mktemp("bad_inputs")
    dataset = root / "ds"
    job = RenderJob(out=dataset, n=4, seed=0, backend="mitsuba", quality="draft", resolution=(64, 48),
                    camera="ideal", split_by="random", ratios=(0.5, 0.25, 0.25), workers=1)  # fmt: skip
    run_render(job, progress=False)
    corrupt = root / "ds_corrupt"
    shutil.copytree(dataset, corrupt)
    # the first image of every split: whichever split a command reads holds one
    corrupt_files = [sorted(split.glob("*/rgb/*"))[0] for split in sorted(p for p in corrupt.iterdir()
                     if p.is_dir() and p.name in ("train", "val", "test"))]  # fmt: skip
    for f in corrupt_files:
        f.write_bytes(b"not an image")
    backgrounds = root / "backgrounds"
    backgrounds.mkdir()
    shutil.copy(sorted(dataset.glob("train/*/rgb/*"))[0], backgrounds / "sky.png")
    corrupt_bg = root / "backgrounds_corrupt"
    corrupt_bg.mkdir()
    (corrupt_bg / "sky.png").write_bytes(b"not an image")
    configs = {}
    for kind, text in (("scgen", SCGEN_CONFIG), ("pose", POSE_CONFIG), ("detector", DETECTOR_CONFIG)):
        configs[kind] = root / f"{kind}.yaml"
        configs[kind].write_text(text)
    runs = root / "runs"
    for command, kind in (("posenet train", "pose"), ("posenet train-detector", "detector")):
        res = _invoke(command, ["--data", str(dataset), "--out", str(runs / kind), "--config",
                                str(configs[kind]), "--max-steps", "1"])  # fmt: skip
        assert res.exit_code == 0, res.output
    garbage = root / "garbage.pt"
    garbage.write_text("not a checkpoint\n")
    test_id = int(sorted(dataset.glob("test/*/rgb/*"))[0].stem)
    return World(root, dataset, corrupt, corrupt_files, backgrounds, corrupt_bg, runs / "pose" / "last.pt",
                 runs / "detector" / "best.pt", garbage, configs, test_id)  # fmt: skip


@dataclass
class Mounts:
    """tmpfs file systems of 64 KiB: `read_only`; `full` (a file fills it: not one block free); `tiny`
    (empty: room for a small file, not for a dataset's first files)."""

    read_only: Path
    full: Path
    tiny: Path


def fill(folder: Path) -> None:
    """Write one file until the file system has no block left."""
    fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, bytes(4096))
    except OSError as exc:
        assert exc.errno == errno.ENOSPC, exc
    finally:
        os.close(fd)


@pytest.fixture(scope="module")
def mounts(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Mounts]:
    """Real mounts, unmounted afterwards; skipped, with the reason, where mounting is not permitted."""
    root = tmp_path_factory.mktemp("mounts")
    made: list[Path] = []
    try:
        for name, options in (("read_only", "ro,size=64k"), ("full", "size=64k"), ("tiny", "size=64k")):
            (root / name).mkdir()
            if shutil.which("mount") is None:
                pytest.skip("no mount command here: the read-only and full-disk cases need a tmpfs")
            done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(root / name)],
                                  capture_output=True, text=True)  # fmt: skip
            if done.returncode != 0:  # not root, or a container without CAP_SYS_ADMIN
                pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip()}): the read-only and "
                            "full-disk cases need one")  # fmt: skip
            made.append(root / name)
        fill(root / "full")
        assert os.statvfs(root / "full").f_bavail == 0
        yield Mounts(root / "read_only", root / "full", root / "tiny")
    finally:
        for folder in reversed(made):
            subprocess.run(["umount", str(folder)], check=True)


def snapshot(*roots: Path) -> dict[str, tuple]:
    """Every path under `roots` with its kind, size and modification time: what a failed command must
    leave as it was."""
    found = {}
    for root in roots:
        for dirpath, dirnames, filenames in os.walk(root):
            for name in dirnames:
                found[os.path.join(dirpath, name)] = ("dir",)
            for name in filenames:
                st = os.stat(os.path.join(dirpath, name))
                found[os.path.join(dirpath, name)] = ("file", st.st_size, st.st_mtime_ns)
    return found


def output_path(where: Path, name: str, kind: str) -> Path:
    return where / (name + (".json" if kind == "file" else ""))


def argv_for(spec: Spec, w: World, case_dir: Path, **over: Path | str) -> list[str]:
    """The spec's argv with every placeholder filled: good inputs and fresh outputs, unless `over` says."""
    values: dict[str, str] = {
        "data": str(w.backgrounds if spec.input_kind == "backgrounds" else w.dataset),
        "pose": str(w.pose),
        "det": str(w.det),
        "config": str(w.configs.get(spec.config or "", "")),
        "test_id": str(w.test_id),
    }
    for name, kind in spec.outputs.items():
        values[name] = str(output_path(case_dir / "fresh", name, kind.split("/")[0]))
    values.update({k: str(v) for k, v in over.items()})
    return [a.format(**values) for a in spec.argv.split()]


def assert_refused(res: click.testing.Result, before: dict, after: dict, naming: str | None = None) -> str:
    """One `Error:` line (the last), a non-zero exit without a traceback, nothing written; the output (a
    report such as validate's FAIL lines may come before the line)."""
    lines = res.output.strip().splitlines()
    errors = [line for line in lines if line.startswith("Error:")]
    assert res.exit_code != 0 and isinstance(res.exception, SystemExit), res.output
    assert len(errors) == 1 and lines[-1] == errors[0], res.output
    assert "Traceback" not in res.output, res.output
    assert after == before, f"left behind or changed: {sorted(set(after) ^ set(before))[:5]}\n{res.output}"
    if naming is not None:
        assert naming in errors[0], (naming, errors[0])
    return res.output


def applies(command: str, case: str) -> None:
    reason = NOT_APPLICABLE[command].get(case)
    if reason is not None:
        pytest.skip(f"{command}: {reason}")


def run_refused(
    command: str, argv: list[str], w: World, case_dir: Path, naming: str | None = None, *also: Path
) -> str:
    """Run `command` and assert_refused (nothing changed under the world, `case_dir` and `also`); its
    output."""
    before = snapshot(w.root, case_dir, *also)
    res = _invoke(command, argv)
    return assert_refused(res, before, snapshot(w.root, case_dir, *also), naming)


# --------------------------------------------------------------------------------------------- the matrix


@pytest.mark.parametrize("command", COMMANDS)
def test_missing_parent_folders_are_made(command: str, world: World, tmp_path: Path):
    applies(command, "missing_parent")
    spec = SPECS[command]
    outs = {
        n: output_path(tmp_path / f"new_{n}" / "deeper", n, k.split("/")[0]) for n, k in spec.outputs.items()
    }
    res = _invoke(command, argv_for(spec, world, tmp_path, **outs))
    assert res.exit_code == 0, res.output
    for name, kind in spec.outputs.items():
        target = outs[name] / kind.split("/")[1] if "/" in kind else outs[name]
        assert target.is_dir() if kind == "folder" else target.is_file(), (name, res.output)


@pytest.mark.parametrize("command", COMMANDS)
def test_an_output_under_a_file_is_refused(command: str, world: World, tmp_path: Path):
    applies(command, "under_file")
    spec = SPECS[command]
    (tmp_path / "afile").write_text("mine\n")
    for name, kind in spec.outputs.items():
        out = output_path(tmp_path / "afile", name, kind.split("/")[0])
        run_refused(command, argv_for(spec, world, tmp_path, **{name: out}), world, tmp_path, "afile")


@pytest.mark.parametrize("command", COMMANDS)
def test_an_existing_output_is_refused(command: str, world: World, tmp_path: Path):
    applies(command, "existing_output")
    spec = SPECS[command]
    for name, kind in spec.outputs.items():
        out = output_path(tmp_path / "there", name, kind.split("/")[0])
        if kind == "file":
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text("mine\n")
        else:
            out.mkdir(parents=True)
            (out / (kind.split("/")[1] if "/" in kind else "keep.txt")).write_text("mine\n")
        run_refused(command, argv_for(spec, world, tmp_path, **{name: out}), world, tmp_path, str(out))


@pytest.mark.parametrize("command", COMMANDS)
def test_a_checkpoint_of_the_wrong_kind_is_named(command: str, world: World, tmp_path: Path):
    applies(command, "wrong_checkpoint")
    spec = SPECS[command]
    files = {"pose": world.pose, "det": world.det}
    wrong = {"pose": [world.det, world.garbage], "det": [world.pose, world.garbage]}
    tried = 0
    for slot in ("pose", "det"):
        if f"{{{slot}}}" in spec.argv:
            for bad in wrong[slot]:
                run_refused(
                    command, argv_for(spec, world, tmp_path, **{slot: bad}), world, tmp_path, str(bad)
                )
                tried += 1
    if spec.resume is not None:  # --resume continues OUT/last.pt: one of the other kind, or no checkpoint
        right = files["pose" if spec.resume == "pose" else "det"]
        for bad in (files["det" if spec.resume == "pose" else "pose"], world.garbage):
            out = tmp_path / f"run_{bad.stem}_{bad.parent.name}"
            out.mkdir()
            shutil.copy(bad, out / "last.pt")
            argv = [*argv_for(spec, world, tmp_path, out=out), "--resume"]
            run_refused(command, argv, world, tmp_path, str(out / "last.pt"))
            tried += 1
        assert right.is_file()
    assert tried, f"{command} reads no checkpoint: declare it in NOT_APPLICABLE"


@pytest.mark.parametrize("command", [c for c in COMMANDS if SPECS[c].resume is not None])
def test_a_resumed_run_removes_what_a_killed_write_left(command: str, world: World, tmp_path: Path):
    """A run killed while writing its checkpoint (SIGKILL: no handler runs) leaves the temporary of its
    atomic write, last.pt.tmp-PID; resuming the run removes it, and the run goes on."""
    spec = SPECS[command]
    out = tmp_path / "run"
    out.mkdir()
    shutil.copy(world.pose if spec.resume == "pose" else world.det, out / "last.pt")
    (out / "last.pt.tmp-4242").write_bytes(b"")
    argv = [*argv_for(spec, world, tmp_path, out=out), "--resume"]
    group, *name = command.split()
    result = CliRunner().invoke(GROUPS[group], [*name, *map(str, argv)])
    assert result.exit_code == 0, result.output
    assert not (out / "last.pt.tmp-4242").exists() and (out / "last.pt").is_file()


@pytest.mark.parametrize("command", COMMANDS)
def test_a_corrupt_image_is_named_before_anything_is_written(command: str, world: World, tmp_path: Path):
    applies(command, "corrupt_image")
    spec = SPECS[command]
    assert "{data}" in spec.argv, f"{command} reads no image folder: declare it in NOT_APPLICABLE"
    if spec.input_kind == "backgrounds":
        data, names = world.corrupt_backgrounds, ["sky.png"]
    else:
        data, names = world.corrupt_dataset, [f"rgb/{f.name}" for f in world.corrupt_files]
    output = run_refused(command, argv_for(spec, world, tmp_path, data=data), world, tmp_path)
    assert any(n in output for n in names), output


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("which", ["unparsable", "wrong_type"])
def test_a_bad_config_is_named(command: str, which: str, world: World, tmp_path: Path):
    applies(command, "bad_config")
    spec = SPECS[command]
    assert spec.config is not None, f"{command} takes no config: declare it in NOT_APPLICABLE"
    bad = tmp_path / "inputs" / f"{which}.yaml"
    bad.parent.mkdir()
    bad.write_text(BAD_CONFIGS[spec.config][which == "wrong_type"])
    line = run_refused(command, argv_for(spec, world, tmp_path, config=bad), world, tmp_path).splitlines()[-1]
    assert str(bad) in line or ("caster_prob" in line or "lr" in line), line


@pytest.mark.parametrize("command", COMMANDS)
def test_an_empty_folder_is_refused(command: str, world: World, tmp_path: Path):
    applies(command, "empty_folder")
    spec = SPECS[command]
    assert "{data}" in spec.argv, f"{command} reads no folder: declare it in NOT_APPLICABLE"
    empty = tmp_path / "inputs" / "empty"
    empty.mkdir(parents=True)
    run_refused(command, argv_for(spec, world, tmp_path, data=empty), world, tmp_path, "empty")


@pytest.mark.parametrize("command", COMMANDS)
def test_an_output_on_a_special_file_system_is_refused(command: str, world: World, tmp_path: Path):
    """/proc holds no storage: mkdir there fails with ENOENT after any amount of work; refused first."""
    applies(command, "special_fs")
    spec = SPECS[command]
    for name, kind in spec.outputs.items():
        out = output_path(Path("/proc") / f"scgen_{tmp_path.name}", name, kind.split("/")[0])
        run_refused(command, argv_for(spec, world, tmp_path, **{name: out}), world, tmp_path, str(out))
        assert not out.exists()


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("case", MOUNTED)
def test_an_output_on_a_read_only_or_full_file_system_is_refused(
    command: str, case: str, world: World, mounts: Mounts, tmp_path: Path
):
    """A read-only mount stops root too (chmod does not); a full one has not one block for a first file."""
    applies(command, case)
    spec = SPECS[command]
    where = mounts.read_only if case == "read_only" else mounts.full
    for name, kind in spec.outputs.items():
        out = output_path(where / "new", name, kind.split("/")[0])
        argv = argv_for(spec, world, tmp_path, **{name: out})
        run_refused(command, argv, world, tmp_path, str(out), where)


def test_a_disk_that_fills_during_the_work_is_one_line_naming_the_file(world: World, mounts: Mounts,
                                                                        tmp_path: Path):  # fmt: skip
    """64 KiB pass the check before work but cannot hold a dataset's static files (the target's models
    alone are larger): the late OSError is one line naming the file that did not fit, and the new OUT is
    removed again."""
    out = mounts.tiny / "ds"
    argv = argv_for(SPECS["scgen render"], world, tmp_path, out=out)
    line = run_refused("scgen render", argv, world, tmp_path, str(out), mounts.tiny).splitlines()[-1]
    assert "No space left on device" in line, line
    assert list(mounts.tiny.iterdir()) == []


# a node installed without albumentations: not found by find_spec, and not importable
NO_ALBUMENTATIONS = """import sys
sys.modules["albumentations"] = None
from posenet.console import main
sys.argv[0] = "posenet"
main()
"""


def test_posenet_starts_without_the_optional_augmentation_package(world: World, tmp_path: Path):
    """Only the albumentations chains need albumentations: the paper's chain trains without it, and a
    config that selects another chain is one line naming the package and the config key, before work."""

    def posenet(*argv: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", NO_ALBUMENTATIONS, *argv], capture_output=True,
                              text=True, timeout=600)  # fmt: skip

    spnv2 = tmp_path / "spnv2.yaml"
    spnv2.write_text(POSE_CONFIG.replace("data: {workers: 0}", "data: {workers: 0, augment: spnv2}"))
    before = snapshot(world.root, tmp_path)
    done = posenet("train", *argv_for(SPECS["posenet train"], world, tmp_path, config=spnv2))
    assert done.returncode == 1, done.stderr
    assert done.stderr.strip().splitlines() == [
        "Error: data.augment: spnv2 needs albumentations, not installed here: pip install 'scgen[train]' "
        "(or data.augment: paper, which needs none)"
    ]
    assert snapshot(world.root, tmp_path) == before
    done = posenet("train", *argv_for(SPECS["posenet train"], world, tmp_path))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "fresh" / "out" / "last.pt").is_file()


# Every numeric option and camera value that is not finite (a comparison with nan is always false, so a
# range check alone lets it through): each is one line naming it, nothing written. (command, argv with
# the matrix's placeholders and {tmp}, what the line names)
PREDICT_DATA = "--data {data} --ckpt {pose} --out {tmp}/p"
PREDICT_IMAGE = "{data} --ckpt {pose} --out {tmp}/p"
NOT_FINITE = [
    ("posenet predict", f"{PREDICT_DATA} --detector {{det}} --min-score nan", "--min-score"),
    ("posenet predict", f"{PREDICT_IMAGE} --camera training --box nan,10,20,20", "nan,10,20,20"),
    ("posenet predict", f"{PREDICT_IMAGE} --camera 300,300,inf,120 --box 1,1,9,9", "cx=inf"),
    ("posenet predict", f"{PREDICT_IMAGE} --camera 300,300,160,120,nan,0,0,0 --box 1,1,9,9", "distortion"),
    ("posenet predict", f"{PREDICT_DATA} --detector {{det}} --filter --dt inf", "--dt"),
    ("posenet predict", f"{PREDICT_DATA} --filter --accel-noise nan", "--accel-noise"),
    ("posenet boxes", "--data {data} --out {tmp}/b.json --noise inf", "--noise"),
    ("posenet calibrate", "--data {data} --ckpt {pose} --min-confidence nan", "--min-confidence"),
    ("posenet train", f"{RUN} --minutes nan", "--minutes"),
    ("scgen render", "--n 2 --out {tmp}/r --backend mitsuba --split nan,0,1", "nan,0,1"),
    ("scgen render", "--n 2 --out {tmp}/r --backend mitsuba --config {tmp}/fx.yaml", "fx=nan"),
]  # fmt: skip


@pytest.mark.parametrize(("command", "argv", "naming"), NOT_FINITE)
def test_a_number_that_is_not_finite_is_one_line(
    command: str, argv: str, naming: str, world: World, tmp_path: Path
):
    (tmp_path / "fx.yaml").write_text("camera:\n  fx: .nan\n")
    values = {"data": world.dataset, "pose": world.pose, "det": world.det, "tmp": tmp_path,
              "out": tmp_path / "o", "config": world.configs["pose"]}  # fmt: skip
    run_refused(command, [a.format(**values) for a in argv.split()], world, tmp_path, naming)


@pytest.mark.parametrize("command", ["scgen render", "scgen preview"])
def test_a_frame_that_cannot_fit_in_memory_is_refused_before_any_work(
    command: str, world: World, tmp_path: Path
):
    """99,999 x 99,999 pixels need at least 500 GiB for one sample (scgen.io.buffers.SAMPLE_BYTES_PER_PIXEL):
    refused from the config, before a folder is made or a sample tried."""
    out = tmp_path / "big"
    argv = ["--out", str(out), "--resolution", "99999x99999", "--backend", "mitsuba"]
    run_refused(
        command, [*(["--n", "1"] if command == "scgen render" else []), *argv], world, tmp_path, "99999x99999"
    )
    assert not out.exists()
