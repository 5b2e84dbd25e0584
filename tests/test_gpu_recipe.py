"""The GPU runbook's chain, CPU-sized: `python benchmarks/gpu_recipe.py --tiny --out DIR`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_tiny_chain_renders_trains_in_bf16_evaluates_and_reports(tmp_path: Path) -> None:
    out = tmp_path / "recipe"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "gpu_recipe.py"), "--tiny", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    text = (out / "report.md").read_text()
    assert report["dataset"]["rendered"] == report["dataset"]["n"] == 24
    t = report["training"]
    assert t["amp"] == "bf16" and 1 <= t["steps_run"] <= t["steps"]
    summary = report["evaluation"]["summary"]
    assert summary["n"] == report["dataset"]["splits"]["test"] and summary["latency_ms"] > 0
    factors = report["evaluation"]["by_factor"]
    assert factors["columns"] == ["gdrnet"] and "occlusion" in factors["groups"]
    assert "## ADD@0.02 m by factor group" in text and "occlusion/none" in text
    assert "batch-1 latency of the network" in text and "ADD@0.02m (%)" in text
    assert text in proc.stdout
