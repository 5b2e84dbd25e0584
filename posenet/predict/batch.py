"""Predict's batched path: frames warped into the training camera in a thread pool, the detector on the whole
batch, the crops into the pose network as one batch, the poses decoded together.

`BatchPredictor(predictor, size=N)(images, cameras, boxes)` gives the poses `predictor(image, camera, box)`
gives one at a time, to float rounding (tests/test_posenet_predict.py). At fixed shapes (the default on
CUDA) every batch is padded to N, so a network sees one input shape; on CUDA the two networks can then be
replayed as CUDA graphs (`graphs`), run channels-last, and under bf16 autocast (`bf16`). A `.pt` detector
runs batched (posenet.detection.detect.BatchBestBox); an ONNX graph, made for one image, runs on the
batch's images side by side in the thread pool, each run on one intra-op thread: on 2 cores the light
detector took 7.9 ms an image so against 12.5 ms one image at a time on both (docs/benchmarks.md).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.utils._pytree import tree_map

from posenet.data.camera import Camera, make_camera, map_box, to_training_camera
from posenet.data.crop import Roi, roi_from_box
from posenet.data.dataset import image_tensor, roi_geometry, roi_image
from posenet.errors import PosenetError
from posenet.geometry import decode_pose
from posenet.predict.pixels import to_bgr8
from posenet.predict.predictor import (
    NO_DETECTION,
    Box,
    Pose,
    Predictor,
    TorchBestBox,
    detect_box,
    detector_box,
    load_box_detector,
    pose_flags,
)
from posenet.predict.recrop import next_crop
from scgen.io import usable_cores

WARMUP = 3  # eager runs on a side stream before a capture (cuDNN picks its kernels; lazy buffers made)


class FixedShape:
    """`fn` of batched tensors run at one batch size `size`: a shorter batch is padded with zeros and the
    answers cut back to it, so `fn` sees one shape; with `graph`, `fn` is captured as a CUDA graph on the
    first call and replayed after (its inputs copied into the captured ones). `size` None: any batch runs
    as it is. `autocast`: a dtype to run `fn` under torch.autocast (answers back in float32), or None."""

    def __init__(
        self,
        fn: Callable[..., Any],
        size: int | None,
        graph: bool = False,
        autocast: torch.dtype | None = None,
    ) -> None:
        self.fn, self.size, self.graph, self.autocast = fn, size, graph, autocast
        self._captured: torch.cuda.CUDAGraph | None = None
        self._inputs: list[Tensor] = []
        self._out: Any = None

    def __call__(self, *inputs: Tensor) -> Any:
        n, size = len(inputs[0]), self.size or len(inputs[0])
        if n > size:
            raise ValueError(f"a batch of {n} for a fixed size of {size}")
        padded = [torch.cat([x, x.new_zeros((size - n, *x.shape[1:]))]) if n < size else x for x in inputs]
        out = self._replay(padded) if self.graph else self._run(*padded)
        return tree_map(lambda t: t[:n].clone() if self.graph else t[:n], out)

    def _run(self, *inputs: Tensor) -> Any:
        if self.autocast is None:
            return self.fn(*inputs)
        # a capture needs autocast's weight cache off (torch.cuda.graph's notes)
        with torch.autocast(inputs[0].device.type, self.autocast, cache_enabled=False):
            out = self.fn(*inputs)
        return tree_map(lambda t: t.float() if t.is_floating_point() else t, out)

    def _replay(self, inputs: list[Tensor]) -> Any:
        if self._captured is None:
            self._inputs = [x.clone() for x in inputs]
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                for _ in range(WARMUP):
                    self._run(*self._inputs)
            torch.cuda.current_stream().wait_stream(side)
            self._captured = torch.cuda.CUDAGraph()
            with torch.cuda.graph(self._captured):
                self._out = self._run(*self._inputs)
        for mine, x in zip(self._inputs, inputs, strict=True):
            mine.copy_(x)
        self._captured.replay()
        return self._out


class BatchPredictor:
    """A Predictor's pose network (and detector) run on batches of up to `size` images.

    `detector`: the `.pt` checkpoint the predictor's detector came from, run batched here (a `.onnx`
    graph or None: the predictor's own, per image). `fixed` (default: on CUDA) pads every batch to
    `size`; `graphs` (CUDA only, needs fixed shapes) replays both networks as CUDA graphs; `bf16` runs them
    under bf16 autocast; `threads` warp and crop images in parallel (default: the CPU count)."""

    def __init__(
        self,
        predictor: Predictor,
        size: int,
        detector: Path | None = None,
        fixed: bool | None = None,
        graphs: bool = False,
        bf16: bool = False,
        threads: int | None = None,
    ) -> None:
        cuda = predictor.device.type == "cuda"
        fixed = cuda if fixed is None else fixed
        if graphs and not (cuda and fixed):
            raise PosenetError("CUDA graphs need a CUDA device and fixed shapes")
        if size < 1:
            raise PosenetError(f"the batch size must be at least 1, got {size}")
        self.predictor, self.size, self.cuda = predictor, size, cuda
        self.pool = ThreadPoolExecutor(threads or usable_cores(), thread_name_prefix="predict")
        run_size = size if fixed else None
        autocast = torch.bfloat16 if bf16 else None
        network = predictor.network
        if cuda and isinstance(network, nn.Module):
            network.to(memory_format=torch.channels_last)
        self.network = FixedShape(lambda img, coord: network(img, coord), run_size, graphs, autocast)
        self.boxes = None
        self.per_image = predictor.detector  # a detector without a batched form runs image by image
        if detector is not None and Path(detector).suffix == ".onnx":
            self.per_image = load_box_detector(detector, predictor.camera, predictor.device, threads=1)
        elif detector is not None:
            from posenet.detection.detect import BatchBestBox, load_detector  # torchvision: when asked for

            known = predictor.detector
            if isinstance(known, TorchBestBox) and known.path == Path(detector):
                model = known.model  # the predictor's own network: the checkpoint is not read twice
            else:
                model, _ = load_detector(detector, predictor.device)
            if cuda:
                model.to(memory_format=torch.channels_last)
            self.boxes = BatchBestBox(model)
            self.detector = FixedShape(self.boxes.run, run_size, graphs, autocast)

    def close(self) -> None:
        self.pool.shutdown()

    def __call__(
        self,
        images: Sequence[np.ndarray],
        cameras: Camera | np.ndarray | Sequence[Camera],
        boxes: Sequence[Box | None] | None = None,
    ) -> list[Pose]:
        """The pose in each image, as Predictor.__call__ gives it: `cameras` one for all or one per image,
        `boxes` one per image (None: the detector's), in chunks of `size`."""
        n = len(images)
        cams = [cameras] * n if isinstance(cameras, Camera | np.ndarray) else list(cameras)
        given = list(boxes) if boxes is not None else [None] * n
        if len(cams) != n or len(given) != n:
            raise PosenetError(f"{n} images need as many cameras and boxes, got {len(cams)} and {len(given)}")
        poses: list[Pose] = []
        with torch.inference_mode():
            for s in range(0, n, self.size):
                chunk = slice(s, s + self.size)
                poses += self._batch(images[chunk], cams[chunk], given[chunk])
        return poses

    def _batch(self, images: Sequence[np.ndarray], cameras: list[Any], boxes: list[Box | None]) -> list[Pose]:
        p, n = self.predictor, len(images)
        tic = time.perf_counter()
        seen_user = list(self.pool.map(self._seen, images, cameras))
        self._spent("crop", tic, n)
        train_boxes: list[Box | None] = []
        scores: list[float] = []
        poses: list[Pose | None] = [None] * n
        found = self._detect([s for (s, _), b in zip(seen_user, boxes, strict=True) if b is None])
        for i, ((_, user), box) in enumerate(zip(seen_user, boxes, strict=True)):
            if box is not None:
                train_boxes.append(map_box(box, user, p.camera))
                scores.append(1.0)
                continue
            hit = found.pop(0)
            if hit is None or hit[1] < p.min_score:
                poses[i] = replace(NO_DETECTION, score=hit[1] if hit else 0.0)
                train_boxes.append(None)
                scores.append(0.0)
                continue
            train_boxes.append(hit[0])
            scores.append(hit[1])
            boxes[i] = map_box(hit[0], p.camera, user)
        todo = [i for i in range(n) if poses[i] is None]
        crops = {i: [train_boxes[i]] for i in todo}
        solved: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        for k in range(p.passes):  # after the first, re-crops around the model's box at the pose before
            if k:  # as Predictor.__call__: an image whose next crop is none (recrop.next_crop) stops there
                tic = time.perf_counter()
                again = {
                    i: next_crop(p.obj, *solved[i][:2], p.camera, crops[i][-1], p.same_crop_iou) for i in todo
                }
                self._spent("crop", tic, len(todo))
                todo = [i for i in todo if again[i] is not None]
                for i in todo:
                    crops[i].append(again[i])  # type: ignore[arg-type]
            estimates = self._estimate([seen_user[i][0] for i in todo], [crops[i][-1] for i in todo])
            solved |= zip(todo, estimates, strict=True)
        for i, (R, t, confidence) in solved.items():
            user = seen_user[i][1]
            flags = pose_flags(R, t, p.obj, user, confidence)
            user_crops = [
                tuple(float(v) for v in boxes[i]),
                *(map_box(b, p.camera, user) for b in crops[i][1:]),
            ]  # type: ignore[union-attr]
            poses[i] = Pose(R, t, user_crops[0], scores[i], confidence, flags, tuple(user_crops))
        return poses  # type: ignore[return-value]

    def _seen(self, image: np.ndarray, camera: Camera | np.ndarray) -> tuple[np.ndarray, Camera]:
        """The image as the training camera sees it, and its own camera fitted to it (Predictor.__call__)."""
        image, note = to_bgr8(image)
        if note is not None:
            warnings.warn(note, stacklevel=4)
        user = camera if isinstance(camera, Camera) else make_camera(camera)
        user = user.for_image((image.shape[1], image.shape[0]))
        return to_training_camera(image, user, self.predictor.camera), user

    def _detect(self, seen: list[np.ndarray]) -> list[tuple[Box, float] | None]:
        """The detector's best box ([x, y, w, h], training camera) and score per image, or None."""
        if not seen:
            return []
        p, tic = self.predictor, time.perf_counter()
        if self.boxes is None:
            found = list(self.pool.map(lambda image: detect_box(self.per_image, image), seen))
        else:
            batch = torch.from_numpy(np.stack(seen)).to(p.device, non_blocking=True)
            rgb = batch.permute(0, 3, 1, 2).flip(1).float() / 255.0  # BGR uint8 -> RGB [0, 1], as detect
            if self.cuda:
                rgb = rgb.contiguous(memory_format=torch.channels_last)
            hits = self.boxes.boxes(self.detector(self.boxes.prepare(rgb)))
            found = [None if h is None else detector_box(*h) for h in hits]
        self._spent("detector", tic, len(seen))
        return found

    def _estimate(
        self, seen: list[np.ndarray], train_boxes: list[Box | None]
    ) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """One pass per image: (R, t, confidence) from the crop around its box (Predictor._estimate)."""
        if not seen:
            return []
        p, n, tic = self.predictor, len(seen), time.perf_counter()
        crops = list(self.pool.map(self._crop, seen, train_boxes))
        rois = [roi for roi, _ in crops]
        batch = {
            k: torch.stack([c[k] for _, c in crops]).to(p.device, non_blocking=True) for k in crops[0][1]
        }
        if self.cuda:
            batch["roi_img"] = batch["roi_img"].contiguous(memory_format=torch.channels_last)
        self._spent("crop", tic, n)
        tic = time.perf_counter()
        out = self.network(batch["roi_img"], batch["roi_coord2d"])
        if self.cuda:
            torch.cuda.synchronize(p.device)
        self._spent("pose_network", tic, n)
        tic = time.perf_counter()
        R, t = (x.double().cpu().numpy() for x in decode_pose(out, batch))
        heads = {k: out[k].float().cpu() for k in ("mask", "xyz")}
        confidence = self.pool.map(
            lambda i: p._confidence({k: v[i : i + 1] for k, v in heads.items()}, rois[i], R[i], t[i]),
            range(n),
        )
        solved = list(zip(R, t, confidence, strict=True))
        self._spent("solve", tic, n)
        return solved

    def _crop(self, seen: np.ndarray, train_box: Box) -> tuple[Roi, dict[str, Tensor]]:
        p = self.predictor
        roi = roi_from_box(train_box, p.camera.size, p.pad_scale)
        batch = {"roi_img": image_tensor(roi_image(seen, roi, p.input_res))}
        return roi, batch | roi_geometry(roi, p.camera.K, p.camera.size, p.output_res)

    def _spent(self, stage: str, tic: float, n: int) -> None:
        """The stage's time since `tic`, shared by the batch's `n` images."""
        share = (time.perf_counter() - tic) / n
        for _ in range(n):
            self.predictor.timings.add(stage, share)
