"""ONNX export of a pose network (opset 18, dynamic batch) and of a detector, and their onnxruntime sessions.

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
import onnx
import onnxruntime as ort
import torch
import torchvision.ops.boxes as box_ops
from onnxscript import opset18 as op
from torch import Tensor, nn

from posenet.detection.detect import fcos_best_box
from posenet.detection.segmenter import MaskDetector, mask_box
from posenet.models import PoseNet

OPSET = 18
logging.getLogger("onnxscript").setLevel(logging.ERROR)  # its optimiser's notes on every export
INPUTS = ("roi_img", "roi_coord2d")
OUTPUTS = ("mask", "xyz", "region", "rot6d", "site")
DETECTOR_SCORE_KEY = "posenet.score_thresh"  # a detector graph's metadata: boxes scoring below are misses


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
    """An onnxruntime CPU session of an exported graph, `threads` intra-op threads (default: torch's).
    Its idle threads sleep rather than spin: predict calls the detector's and the pose network's sessions
    in turn, and one's spinning threads took the cores from the other (70.5 and 24.1 ms a call against
    38.1 and 10.7 without spinning, on 2 cores)."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads or torch.get_num_threads()
    options.inter_op_num_threads = 1
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
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


class DetectorBestBox(nn.Module):
    """A torchvision FCOS detector reduced to what predict reads of it: the best box ([x0, y0, x1, y1]
    pixel edges) and its score, for one RGB image in [0, 1] (1 x 3 x H x W). Its own resize, normalisation
    and box decoding are inside the graph; the best-scoring box is the one its NMS keeps first, so this
    equals the full detector's first detection (tests/test_posenet_predict.py)."""

    def __init__(self, fcos: nn.Module) -> None:
        super().__init__()
        self.fcos = fcos

    def forward(self, image: Tensor) -> tuple[Tensor, Tensor]:
        height, width = image.shape[-2:]
        images, _ = self.fcos.transform([image[0]])
        features = list(self.fcos.backbone(images.tensors).values())
        head = self.fcos.head(features)
        anchors = self.fcos.anchor_generator(images, features)[0]
        box, score = fcos_best_box(self.fcos, head, anchors)
        rh, rw = images.image_sizes[0]
        box = box_ops.clip_boxes_to_image(box, (rh, rw))
        scale = torch.tensor([width / rw, height / rh, width / rw, height / rh], dtype=box.dtype)
        return box[0] * scale, score[0]


class MaskProbabilities(nn.Module):
    """A mask detector reduced to its graph: the target's probability per pixel (1 x H x W) of one RGB
    image in [0, 1] (1 x 3 x H x W); the box is taken from it outside the graph (segmenter.mask_box)."""

    def __init__(self, detector: MaskDetector) -> None:
        super().__init__()
        self.detector = detector

    def forward(self, image: Tensor) -> Tensor:
        return torch.sigmoid(self.detector.logits(image)[:, 0])


def export_detector_onnx(model: nn.Module, path: Path, size: tuple[int, int], score_thresh: float) -> None:
    """Write the detector as an ONNX graph for images of `size` (width, height): the pose network's
    training camera, which predict warps every image into. FCOS becomes its DetectorBestBox (outputs box,
    score), a mask detector its MaskProbabilities (output prob). The score threshold travels in the
    graph's metadata (DETECTOR_SCORE_KEY)."""
    example = torch.rand(1, 3, size[1], size[0])
    model = model.cpu().eval()
    graph, outputs = (
        (MaskProbabilities(model), ["prob"])
        if isinstance(model, MaskDetector)
        else (DetectorBestBox(model), ["box", "score"])
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        program = torch.onnx.export(
            graph,
            (example,),
            dynamo=True,
            opset_version=OPSET,
            input_names=["image"],
            output_names=outputs,
            verbose=False,
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    program.save(str(tmp))
    graph = onnx.load(str(tmp))
    onnx.helper.set_model_props(graph, {DETECTOR_SCORE_KEY: repr(float(score_thresh))})
    onnx.save(graph, str(tmp))
    os.replace(tmp, path)


def input_shape(session: ort.InferenceSession, name: str) -> list[Any]:
    """The declared shape of a graph input (a dynamic axis is a string)."""
    return next(i.shape for i in session.get_inputs() if i.name == name)


def run_detector_onnx(session: ort.InferenceSession, image: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The best box [x0, y0, x1, y1] and score of a detector graph (DetectorBestBox or MaskProbabilities)
    for one RGB image (H x W x 3 float32 in [0, 1]), or None under the graph's score threshold."""
    feed = np.ascontiguousarray(image.transpose(2, 0, 1))[None]
    thresh = float(session.get_modelmeta().custom_metadata_map.get(DETECTOR_SCORE_KEY, "0"))
    if [o.name for o in session.get_outputs()] == ["prob"]:
        (prob,) = session.run(None, {"image": feed})
        return mask_box(prob[0], thresh)
    box, score = session.run(None, {"image": feed})
    return (np.asarray(box, np.float64), float(score)) if float(score) > thresh else None
