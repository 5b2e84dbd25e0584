"""`posenet bench` end to end on the smoke presets (real models, 1 timed forward each)."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from posenet.cli import main


def test_bench_prints_table_and_writes_json(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    args = ["--smoke", "--device", "cpu", "--threads", "1", "--warmup", "0", "--iters", "1"]
    args += ["--variant", "gdrnet", "--variant", "gap-gdrnet", "--json", str(out)]
    result = CliRunner().invoke(main, ["bench", *args])
    assert result.exit_code == 0, result.output
    assert "latency ratio gap-gdrnet / gdrnet" in result.output
    assert "FLOPs/2" in result.output
    payload = json.loads(out.read_text())
    assert payload["device"].startswith("cpu")
    assert [v["name"] for v in payload["variants"]] == ["gdrnet", "gap-gdrnet"]
    for row in payload["variants"]:
        assert set(row) == {"name", "backbone", "params_m", "macs_g", "latency_ms", "fps", "onnx_latency_ms"}
        assert row["onnx_latency_ms"] is None  # onnxruntime is timed with --onnx only
        assert row["backbone"] == "tf_efficientnet_lite0"  # the smoke preset's, for every variant
        assert row["params_m"] > 0 and row["macs_g"] > 0 and row["latency_ms"] > 0
        assert row["fps"] == 1000 / row["latency_ms"]


def test_bench_counts_any_timm_backbone(tmp_path: Path) -> None:
    """--backbone swaps the backbone: a bigger one counts more parameters; no weights are needed."""
    out = {name: tmp_path / f"{name}.json" for name in ("lite0", "resnet18")}
    for name, backbone in (("lite0", None), ("resnet18", "resnet18")):
        args = ["--smoke", "--device", "cpu", "--threads", "1", "--warmup", "0", "--iters", "1"]
        args += ["--variant", "gdrnet", "--json", str(out[name])]
        result = CliRunner().invoke(main, ["bench", *args, *(["--backbone", backbone] if backbone else [])])
        assert result.exit_code == 0, result.output
    rows = {name: json.loads(path.read_text())["variants"][0] for name, path in out.items()}
    assert rows["resnet18"]["backbone"] == "resnet18"
    assert rows["resnet18"]["params_m"] > rows["lite0"]["params_m"] + 5  # ResNet-18 11.2 M vs Lite0 3.4 M
