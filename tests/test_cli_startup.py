"""The command lines answer at once: building them, rendering every command's --help and refusing a
mistyped option load none of the heavy stacks (torch alone takes seconds to import). Checked by module,
in a fresh interpreter, not by the clock: what is imported is the same on every CPU."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

# what each command line must not load before a command runs: the networks' stack for posenet, the
# renderers and the mesh / geometry stack for scgen
HEAVY = {
    "posenet": ("torch", "timm", "torchvision", "onnxruntime", "cv2", "scipy", "trimesh"),
    "scgen": ("bpy", "mitsuba", "drjit", "torch", "trimesh", "scipy", "OpenEXR"),
}

PROBE = """
import json, sys
from click.testing import CliRunner
from {package}.cli import main
runner = CliRunner()
calls = [["--help"], ["--nope"]] + [[name, "--help"] for name in main.commands]
calls += [[name, "--nope"] for name in main.commands]
codes = {{" ".join(args): runner.invoke(main, args).exit_code for args in calls}}
print(json.dumps({{"codes": codes, "modules": sorted(sys.modules)}}))
"""


@pytest.mark.parametrize("package", sorted(HEAVY))
def test_help_and_a_bad_option_load_no_heavy_stack(package: str) -> None:
    probe = subprocess.run([sys.executable, "-c", PROBE.format(package=package)], capture_output=True,
                           text=True, check=True)  # fmt: skip
    report = json.loads(probe.stdout)
    codes = report["codes"]
    assert len(codes) >= 4, codes  # the group and at least one command, each with --help and --nope
    for args, code in codes.items():
        assert code == (2 if args.endswith("--nope") else 0), (args, code)  # Click's usage error is 2
    loaded = {m.split(".")[0] for m in report["modules"]}
    assert not loaded & set(HEAVY[package]), sorted(loaded & set(HEAVY[package]))
