"""Render one small real sample in a child process: can a renderer run here, and with what.

A renderer can fail where no `except` reaches: LLVM aborts the whole process on a kernel it cannot
compile (libLLVM 15: `Cannot select: fmaximum`), a GPU driver can crash bpy. So the libLLVM check
(scgen.render.mitsuba.llvm) and `scgen doctor` ask a child process (scgen.render.probe_child).
The child reports what it found (the libLLVM it loaded, Cycles' GPUs) before it renders, so a crash still
leaves the report; exit status 0 means the sample rendered.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from dataclasses import dataclass
from typing import Any

SAMPLE = (0, 3)  # seed, index: props, the Earth and its earthshine: every light and pass a sample can have
RESOLUTION = (32, 24)
TIMEOUT_S = 300
REPORT = "scgen-probe: "  # marks the child's report lines among whatever the renderer prints


@dataclass(frozen=True)
class ProbeResult:
    """What the child reported, and why its sample did not render (None: it rendered)."""

    facts: dict[str, Any]
    error: str | None

    @property
    def reached_renderer(self) -> bool:
        """Whether the child got as far as the renderer (its scene was ready): if not, its failure says
        nothing about the renderer (a missing model, a bad config)."""
        return bool(self.facts.get("scene"))


def probe(backend: str, env: dict[str, str] | None = None) -> ProbeResult:
    """Render the probe sample with `backend` (mitsuba: its LLVM variant) in a child process.

    `env` is the child's environment (default: this process's), e.g. another DRJIT_LIBLLVM_PATH.
    """
    command = [sys.executable, "-m", "scgen.render.probe_child", backend]
    try:
        done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return ProbeResult({}, f"its test render did not finish in {TIMEOUT_S} s")
    facts: dict[str, Any] = {}
    for line in done.stdout.splitlines():
        if line.startswith(REPORT):
            facts.update(json.loads(line[len(REPORT) :]))
    return ProbeResult(facts, None if done.returncode == 0 else failure(done.stderr, done.returncode))


def failure(stderr: str, returncode: int) -> str:
    """The line of a failed child's stderr that says why: LLVM's or Dr.Jit's own, else the last one."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    own = (line for line in lines if line.startswith("LLVM ERROR") or re.match(r"jitc?_\w+\(\): ", line))
    cause = next(own, lines[-1] if lines else None)
    if cause is None:
        return f"it exited with status {returncode}" if returncode > 0 else f"it died of signal {-returncode}"
    return re.sub(r" ?0x[0-9a-f]+:?,?", "", cause).split(". ")[0][:200]  # without LLVM's node addresses
