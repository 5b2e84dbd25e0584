"""ONNX export: onnxruntime gives torch's outputs (to float32 rounding) at any batch; bench times both."""

from __future__ import annotations

import json
from pathlib import Path

import onnx
import pytest
import torch
from click.testing import CliRunner
from float_bounds import forward_rel
from posenet_helpers import posenet_dataset, tiny_pose_checkpoint

from posenet.checkpoint import load_model
from posenet.cli import main
from posenet.export.onnx_export import OUTPUTS, onnx_session, run_onnx


def assert_same_outputs(model: torch.nn.Module, path: Path, batches: tuple[int, ...] = (1, 3)) -> None:
    """onnxruntime's kernels sum in another order than torch's: each output agrees to float_bounds' rounding
    of its scale (its largest entry)."""
    session = onnx_session(path)
    rel = forward_rel(model)
    c = model.config
    gen = torch.Generator().manual_seed(1)
    for b in batches:
        img = torch.rand(b, 3, c.input_res, c.input_res, generator=gen)
        coord = torch.rand(b, 2, c.output_res, c.output_res, generator=gen)
        with torch.no_grad():
            ours = model(img, coord)
        theirs = run_onnx(session, img, coord)
        for k in OUTPUTS:
            assert theirs[k].shape == ours[k].shape, (b, k)
            scale = float(ours[k].abs().max())
            assert torch.allclose(theirs[k], ours[k], rtol=0, atol=rel * scale), (b, k)


def test_cli_export_of_a_trained_gap_gdrnet(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path) -> None:
    """A trained GAP-GDRNet (its MECS takes a channel median, which ONNX gets as TopK) through `posenet
    export`: opset >= 17, a symbolic batch, onnxruntime's outputs those of torch at batch 1 and 3."""
    ckpt = tiny_pose_checkpoint(posenet_dataset(tmp_path_factory), tmp_path_factory, "gap-gdrnet")
    out = tmp_path / "pose.onnx"
    res = CliRunner().invoke(main, ["export", "--ckpt", str(ckpt), "--onnx", str(out)])
    assert res.exit_code == 0, res.output
    assert "opset 18, dynamic batch" in res.output
    graph = onnx.load(str(out))
    assert max(o.version for o in graph.opset_import if o.domain in ("", "ai.onnx")) >= 17
    assert any(node.op_type == "TopK" for node in graph.graph.node)  # the median
    batch_dims = [i.type.tensor_type.shape.dim[0] for i in graph.graph.input]
    assert all(d.dim_param and not d.dim_value for d in batch_dims)  # symbolic: any batch size
    model, _ = load_model(ckpt, torch.device("cpu"))
    assert model.config.mecs
    assert_same_outputs(model, out)


def test_bench_times_onnxruntime_beside_torch(tmp_path: Path) -> None:
    args = ["bench", "--smoke", "--variant", "pgsa", "--device", "cpu", "--onnx", "--warmup", "1"]
    res = CliRunner().invoke(main, [*args, "--iters", "2", "--json", str(tmp_path / "b.json")])
    assert res.exit_code == 0, res.output
    assert "onnxruntime ms" in res.output
    row = json.loads((tmp_path / "b.json").read_text())["variants"][0]
    assert row["onnx_latency_ms"] > 0 and row["latency_ms"] > 0
