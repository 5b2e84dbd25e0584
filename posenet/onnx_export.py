"""ONNX export of a pose network (opset 18, dynamic batch) and its onnxruntime session.

The graph takes `roi_img` (B x 3 x R x R, RGB in [0, 1]) and `roi_coord2d` (B x 2 x r x r) and returns
the head outputs pose decoding needs, in OUTPUTS order (mask and region logits, xyz, allocentric rot6d,
SITE); `posenet.geometry.decode_pose` turns them into (R, t) with the RoI geometry, outside the graph.
MECS's channel median (torch.median, which no ONNX exporter translates) becomes ONNX TopK: the same
lower median, exactly.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort
import torch
from onnxscript import opset18 as op
from torch import Tensor, nn

from posenet.models import PoseNet

OPSET = 18
logging.getLogger("onnxscript").setLevel(logging.ERROR)  # its optimiser's notes on every export
INPUTS = ("roi_img", "roi_coord2d")
OUTPUTS = ("mask", "xyz", "region", "rot6d", "site")


class PoseOutputs(nn.Module):
    """The network with its outputs as a tuple in OUTPUTS order (what an ONNX graph returns)."""

    def __init__(self, model: PoseNet) -> None:
        super().__init__()
        self.model = model

    def forward(self, roi_img: Tensor, roi_coord2d: Tensor) -> tuple[Tensor, ...]:
        out = self.model(roi_img, roi_coord2d)
        return tuple(out[k] for k in OUTPUTS)


def median_dim(self: Any, dim: int, keepdim: bool = False) -> tuple[Any, Any]:
    """aten.median.dim in ONNX: the lower median along `dim` (torch's), the (n - (n - 1) // 2)-th
    largest value, with its index, by TopK."""
    n = op.Shape(self, start=dim, end=dim + 1)
    k = op.Sub(n, op.Div(op.Sub(n, op.Constant(value_ints=[1])), op.Constant(value_ints=[2])))
    values, indices = op.TopK(self, k, axis=dim, largest=1, sorted=1)
    last = op.Sub(k, op.Constant(value_ints=[1]))
    value, index = op.Gather(values, last, axis=dim), op.Gather(indices, last, axis=dim)
    if not keepdim:
        axes = op.Constant(value_ints=[dim])
        value, index = op.Squeeze(value, axes), op.Squeeze(index, axes)
    return value, index


def export_onnx(model: PoseNet, path: Path) -> None:
    """Write `model` (its eval-mode forward, on the CPU) as an ONNX graph with a dynamic batch size."""
    model = model.cpu().eval()
    c = model.config
    example = (torch.rand(2, 3, c.input_res, c.input_res), torch.rand(2, 2, c.output_res, c.output_res))
    batch = torch.export.Dim("batch")
    with warnings.catch_warnings():  # the exporter's deprecation notes on its own internals
        warnings.simplefilter("ignore")
        program = torch.onnx.export(
            PoseOutputs(model),
            example,
            dynamo=True,
            opset_version=OPSET,
            input_names=list(INPUTS),
            output_names=list(OUTPUTS),
            dynamic_shapes=({0: batch}, {0: batch}),
            custom_translation_table={torch.ops.aten.median.dim: median_dim},
            verbose=False,
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    program.save(str(tmp))
    os.replace(tmp, path)


def onnx_session(path: Path, threads: int | None = None) -> ort.InferenceSession:
    """An onnxruntime CPU session of an exported graph, `threads` intra-op threads (default: torch's)."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads or torch.get_num_threads()
    options.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def run_onnx(session: ort.InferenceSession, roi_img: Tensor, roi_coord2d: Tensor) -> dict[str, Tensor]:
    """The session's outputs for one batch, as the network's output dict (OUTPUTS keys)."""
    feeds = {"roi_img": roi_img.numpy(), "roi_coord2d": roi_coord2d.numpy()}
    return {
        k: torch.from_numpy(np.asarray(v)) for k, v in zip(OUTPUTS, session.run(None, feeds), strict=True)
    }


@torch.no_grad()
def max_difference(model: PoseNet, session: ort.InferenceSession, batch: int = 2, seed: int = 0) -> float:
    """The largest |onnxruntime - torch| over every output for one random batch of the model's input sizes."""
    c = model.config
    gen = torch.Generator().manual_seed(seed)
    img = torch.rand(batch, 3, c.input_res, c.input_res, generator=gen)
    coord = torch.rand(batch, 2, c.output_res, c.output_res, generator=gen)
    ours, theirs = model.cpu().eval()(img, coord), run_onnx(session, img, coord)
    return max(float((ours[k] - theirs[k]).abs().max()) for k in OUTPUTS)
