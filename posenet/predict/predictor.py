"""A pose from an image and its camera: detector (or a given box) -> the training crop -> pose network.

`Predictor.load(ckpt, detector=...)` needs no dataset: a checkpoint carries the object (mesh, extent,
diameter, symmetries) and the camera it was trained with. `predictor(image, camera)` warps the image into
that camera (posenet.data.camera), finds the box, crops it with the code training and `posenet eval`
use (posenet.data.dataset.roi_image / roi_geometry), runs the network and decodes the pose with
posenet.geometry.decode_pose, so predict and eval cannot disagree on a convention.
"""

from __future__ import annotations

import time
import warnings
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from posenet.checkpoint import load_checkpoint, model_from_state
from posenet.config import config_from_dict
from posenet.data.boxes import Box, edges_box
from posenet.data.camera import (
    Camera,
    make_camera,
    map_box,
    project,
    to_training_camera,
    training_camera,
)
from posenet.data.crop import roi_from_box
from posenet.data.dataset import image_tensor, roi_geometry, roi_image
from posenet.data.layout import image_size, scan_split
from posenet.data.object_model import ObjectModel, load_object_model, object_from_record
from posenet.detection.options import MIN_SCORE
from posenet.errors import PosenetError
from posenet.geometry import decode_pose, mask_probability
from posenet.predict.confidence import pose_confidence
from posenet.predict.options import LOW_CONFIDENCE, PREDICT_PASSES, SAME_CROP_IOU
from posenet.predict.pixels import to_bgr8
from posenet.predict.recrop import next_crop

FLAGS = ("no_detection", "behind_camera", "outside_view", "low_confidence")
STAGES = ("decode", "detector", "crop", "pose_network", "solve", "drawing")  # timed per image (ms)


@dataclass(frozen=True)
class Pose:
    """One image's answer. R, t: model to camera (X_cam = R X + t, metres) in the user's camera, None
    without a detection; box [x, y, w, h] in the user's image; score: the detector's (1 for a given box; with
    no_detection, its best under the score floor, 0 for none);
    confidence: the share of the predicted visible pixels whose predicted model point the pose projects
    back within one output cell (0 to 1); flags: those of FLAGS that hold."""

    R: np.ndarray | None
    t: np.ndarray | None
    box: Box | None
    score: float
    confidence: float
    flags: tuple[str, ...] = ()
    crops: tuple[Box, ...] = ()  # each pass's crop box in the user's image: `box`, then the re-crops

    @property
    def quaternion(self) -> list[float] | None:
        """R as a scalar-first unit quaternion (w, x, y, z), SPEED+'s q_vbs2tango convention."""
        if self.R is None:
            return None
        from scipy.spatial.transform import Rotation  # here: predict runs on a node without scipy

        x, y, z, w = Rotation.from_matrix(self.R).as_quat()
        q = np.array([w, x, y, z])
        return (q if w >= 0 else -q).tolist()

    def to_json(self) -> dict[str, Any]:
        return {
            "R": None if self.R is None else self.R.ravel().tolist(),
            "t": None if self.t is None else self.t.tolist(),
            "quaternion": self.quaternion,
            "box": None if self.box is None else [round(float(v), 2) for v in self.box],
            "score": round(float(self.score), 4),
            "confidence": round(float(self.confidence), 4),
            "flags": list(self.flags),
            "crops": [[round(float(v), 2) for v in b] for b in self.crops[1:]],
        }


NO_DETECTION = Pose(None, None, None, 0.0, 0.0, ("no_detection",))


@dataclass(frozen=True)
class Prepared:
    """An image ready for the pose network (Predictor.prepare): as the training camera sees it, the
    camera fitted to it, its box in it and in the training camera, and the detector's score (1 for a
    given box)."""

    seen: np.ndarray
    user: Camera
    box: Box
    train_box: Box
    score: float


@dataclass
class Timings:
    """Milliseconds spent per stage (STAGES), for predict's latency line: a stage may run more than once
    for an image (the warp and each pass's crop, each pass's network), so a figure per image is the
    stage's total over the images, not the mean of its runs."""

    ms: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))

    def add(self, stage: str, seconds: float) -> None:
        self.ms[stage].append(seconds * 1000.0)

    def merge(self, other: Timings) -> None:
        """Add `other`'s runs (a frame's, timed in another thread) to these."""
        for stage, runs in other.ms.items():
            self.ms[stage] += runs

    def per_image_ms(self, images: int) -> dict[str, float]:
        """Each stage's milliseconds per image over `images` images."""
        return {s: float(np.sum(self.ms[s])) / max(images, 1) for s in STAGES if self.ms.get(s)}


class _Clock:
    def __init__(self, timings: Timings, stage: str) -> None:
        self.timings, self.stage = timings, stage

    def __enter__(self) -> None:
        self.tic = time.perf_counter()

    def __exit__(self, *_: object) -> None:
        self.timings.add(self.stage, time.perf_counter() - self.tic)


Network = Callable[[torch.Tensor, torch.Tensor], dict[str, torch.Tensor]]  # (roi_img, roi_coord2d) -> heads
Detector = Callable[[np.ndarray], tuple[np.ndarray, float] | None]  # RGB [0, 1] -> best [x0, y0, x1, y1]


class Predictor:
    """A pose network (and optionally a detector), in torch or onnxruntime, ready for images from any
    camera."""

    def __init__(
        self,
        network: Network,
        state: dict[str, Any],
        obj: ObjectModel,
        camera: Camera,
        detector: Detector | None = None,
        device: torch.device | None = None,
        min_score: float = 0.0,
        passes: int = PREDICT_PASSES,
        same_crop_iou: float = SAME_CROP_IOU,
    ) -> None:
        cfg = config_from_dict(state["config"])
        self.network, self.obj, self.camera, self.detector = network, obj, camera, detector
        self.min_score = min_score  # a detection scoring less is none (no_detection)
        self.passes = passes  # network runs per image: 1 on the given box, then re-crops (predict.recrop)
        self.same_crop_iou = same_crop_iou  # a re-crop whose box overlaps the one before this much is none
        self.device = device or torch.device("cpu")
        self.pad_scale, self.mask_type = cfg.data.pad_scale, cfg.loss.mask_type
        model_cfg = state["model_config"]
        self.input_res, self.output_res = model_cfg["input_res"], model_cfg["output_res"]
        self.variant = cfg.variant
        self.timings = Timings()

    @classmethod
    def load(
        cls,
        ckpt: Path,
        detector: Path | None = None,
        device: str | torch.device = "cpu",
        data: Path | None = None,
        onnx: Path | None = None,
        min_score: float | None = None,
        passes: int = PREDICT_PASSES,
        same_crop_iou: float = SAME_CROP_IOU,
    ) -> Predictor:
        """The pose checkpoint `ckpt` and a detector (its checkpoint, or its ONNX graph from `posenet
        export`: a `.onnx` file runs in onnxruntime) on `device`; `onnx`, the pose network's exported
        graph, runs in onnxruntime instead of torch (the checkpoint still gives the object and camera). A
        checkpoint written before predict existed has no object or camera: `data`, the dataset it was
        trained on, supplies them. A detection scoring under `min_score` (None: the detector's floor,
        posenet.detection.options.MIN_SCORE) is no detection. `passes`: the network's most runs per image,
        each after the first re-cropped around the model's box at the pose before, where that box overlaps
        the box before by less than `same_crop_iou` (posenet.predict.recrop.next_crop; the defaults
        measured in posenet.predict.options)."""

        dev = torch.device(device)
        state = load_checkpoint(ckpt, kind="pose")
        obj, camera = _object_and_camera(state, ckpt, data)
        if onnx is not None:
            network = onnx_network(onnx, state["model_config"]["input_res"])
        else:
            network = model_from_state(state, ckpt, dev)  # the checkpoint is read once
        floor = MIN_SCORE if min_score is None else min_score
        detect = load_box_detector(detector, camera, dev)
        return cls(network, state, obj, camera, detect, dev, floor, passes, same_crop_iou)

    def detect(self, image: np.ndarray) -> tuple[Box, float] | None:
        """The detector's best box [x, y, w, h] and score in an image of the training camera, or None."""
        return detect_box(self.detector, image)

    def __call__(self, image: np.ndarray, camera: Camera | np.ndarray, box: Box | None = None) -> Pose:
        """The pose in `image` seen by `camera` (a Camera, or a 3x3 K for a pinhole camera), at `box`
        ([x, y, w, h] in the image) or at the detector's box. `image` is what the CLI reads too
        (posenet.predict.pixels.to_bgr8): grey, BGR or BGRA in OpenCV's order, uint8, uint16 (12-bit data
        in it is found and warned of) or float in [0, 1]; another kind is one PosenetError, and an image
        the camera cannot take (posenet.data.camera.Camera.for_image) one CameraMismatch."""
        ready = self.prepare(image, camera, box)
        return ready if isinstance(ready, Pose) else self.finish(ready)

    def prepare(
        self,
        image: np.ndarray,
        camera: Camera | np.ndarray,
        box: Box | None = None,
        timings: Timings | None = None,
    ) -> Prepared | Pose:
        """__call__'s first half, which needs no pose network: the image in the training camera and its
        box (the detector's where `box` is None), or NO_DETECTION. `timings` (default: the predictor's)
        take its stages' times: predict runs it a frame ahead in another thread (posenet.predict.run)."""
        clock = timings or self.timings
        image, note = to_bgr8(image)
        if note is not None:
            warnings.warn(note, stacklevel=3)
        user = camera if isinstance(camera, Camera) else make_camera(camera)
        user = user.for_image((image.shape[1], image.shape[0]))
        with _Clock(clock, "crop"):
            seen = to_training_camera(image, user, self.camera)
        if box is None:
            with _Clock(clock, "detector"):
                found = self.detect(seen)
            if found is None or found[1] < self.min_score:
                return replace(NO_DETECTION, score=found[1] if found else 0.0)
            train_box, score = found
            box = map_box(train_box, self.camera, user)
        else:
            train_box, score = map_box(box, user, self.camera), 1.0
        return Prepared(seen, user, tuple(float(v) for v in box), train_box, score)  # type: ignore[arg-type]

    def finish(self, ready: Prepared) -> Pose:
        """__call__'s second half: the pose network's passes on a prepared image, and the pose's flags."""
        seen, user, train_box = ready.seen, ready.user, ready.train_box
        R, t, confidence = self._estimate(seen, train_box)
        crops = [train_box]
        for _ in range(self.passes - 1):  # re-crop around the box of the model at the pose just decoded
            with _Clock(self.timings, "crop"):
                again = next_crop(self.obj, R, t, self.camera, crops[-1], self.same_crop_iou)
            if again is None:
                break
            R, t, confidence = self._estimate(seen, again)
            crops.append(again)
        flags = pose_flags(R, t, self.obj, user, confidence)
        user_crops = [ready.box, *(map_box(b, self.camera, user) for b in crops[1:])]
        return Pose(R, t, ready.box, ready.score, confidence, flags, tuple(user_crops))

    def _estimate(self, seen: np.ndarray, train_box: Box) -> tuple[np.ndarray, np.ndarray, float]:
        """One pass: the pose (R, t) and its confidence from the crop around `train_box` of `seen`, an
        image of the training camera."""
        with _Clock(self.timings, "crop"):
            roi = roi_from_box(train_box, self.camera.size, self.pad_scale)
            batch = {"roi_img": image_tensor(roi_image(seen, roi, self.input_res))}
            batch |= roi_geometry(roi, self.camera.K, self.camera.size, self.output_res)
            batch = {k: v[None].to(self.device) for k, v in batch.items()}
        with _Clock(self.timings, "pose_network"), torch.inference_mode():
            out = self.network(batch["roi_img"], batch["roi_coord2d"])
        with _Clock(self.timings, "solve"):
            R, t = (x[0].double().cpu().numpy() for x in decode_pose(out, batch))
            return R, t, self._confidence(out, roi, R, t)

    def _confidence(self, out: dict[str, torch.Tensor], roi: Any, R: np.ndarray, t: np.ndarray) -> float:
        """posenet.predict.confidence of one pass's heads at its pose, in the training camera."""
        visible = (mask_probability(out["mask"].float(), self.mask_type)[0, 0] > 0.5).cpu().numpy()
        xyz = out["xyz"][0].float().cpu().numpy()
        return pose_confidence(xyz, visible, self.obj.extent, roi.center, roi.scale, R, t, self.camera)


def detect_box(detector: Detector | None, image: np.ndarray) -> tuple[Box, float] | None:
    """`detector`'s best box [x, y, w, h] and score in a BGR uint8 image, or None; no detector is an
    error naming the options that give one."""
    if detector is None:
        raise PosenetError("no detector loaded: give --detector, --box or --boxes")
    found = detector(image[..., ::-1].astype(np.float32) / 255.0)
    return None if found is None else detector_box(*found)


def detector_box(edges: np.ndarray, score: float) -> tuple[Box, float]:
    """A detector's [x0, y0, x1, y1] pixel edges as the box [x, y, w, h] of the pixels they span
    (`edges_box`: the box `posenet boxes --detector` writes for the same image), with its score."""
    return edges_box(edges), score


def onnx_network(path: Path, input_res: int) -> Network:
    """The pose network's exported graph as a Network; one made for another input size is refused."""
    from posenet.export.onnx_export import (  # onnxruntime: only when asked for
        input_shape,
        onnx_session,
        run_onnx,
    )

    session = _session(path, onnx_session)
    if input_shape(session, "roi_img")[-1] != input_res:
        raise PosenetError(f"{path} takes {input_shape(session, 'roi_img')[-1]} px RoIs; the checkpoint's "
                           f"network takes {input_res} px: export that checkpoint")  # fmt: skip
    return lambda roi_img, coord2d: run_onnx(session, roi_img.cpu(), coord2d.cpu())


def load_box_detector(
    path: Path | None, camera: Camera, device: torch.device, threads: int | None = None
) -> Detector | None:
    """A detector's best-box function: a checkpoint in torch, or a `.onnx` graph in onnxruntime (made for
    images of the training camera's size; `threads` intra-op threads, default torch's)."""
    if path is None:
        return None
    if Path(path).suffix == ".onnx":
        from posenet.export.onnx_export import input_shape, onnx_session, run_detector_onnx

        session = _session(path, lambda graph: onnx_session(graph, threads))
        size = tuple(input_shape(session, "image")[:-3:-1])
        if size != camera.size:
            w, h = camera.size or (0, 0)
            raise PosenetError(f"{path} takes {size[0]}x{size[1]} images; the pose network's camera is "
                               f"{w}x{h}: export it with that checkpoint")  # fmt: skip
        return lambda rgb: run_detector_onnx(session, rgb)
    from posenet.detection.detect import load_detector  # torchvision's FCOS: only when asked for

    return TorchBestBox(Path(path), load_detector(path, device)[0], device)


@dataclass(frozen=True)
class TorchBestBox:
    """A detector checkpoint's best box in an image, in torch; its network (`model`, read from `path`) is
    also what predict --batch runs on whole batches (posenet.predict.batch), so the file is read once."""

    path: Path
    model: torch.nn.Module
    device: torch.device

    @torch.inference_mode()
    def __call__(self, rgb: np.ndarray) -> tuple[np.ndarray, float] | None:
        pred = self.model([image_tensor(rgb).to(self.device)])[0]
        if len(pred["scores"]) == 0:
            return None
        best = int(pred["scores"].argmax())
        return pred["boxes"][best].cpu().double().numpy(), float(pred["scores"][best])


def _session(path: Path, open_session: Callable[[Path], Any]) -> Any:
    if not Path(path).is_file():
        raise PosenetError(f"ONNX graph not found: {path}")
    try:
        return open_session(Path(path))
    except Exception as exc:  # onnxruntime raises its own types for a foreign or corrupt file
        raise PosenetError(f"{path} is not a readable ONNX graph: {str(exc).splitlines()[0]}") from exc


def pose_flags(
    R: np.ndarray, t: np.ndarray, obj: ObjectModel, camera: Camera, confidence: float
) -> tuple[str, ...]:
    """Which of behind_camera (the object's centre at z <= 0), outside_view (its centre projects outside
    the image) and low_confidence (under LOW_CONFIDENCE) hold."""
    flags = []
    if t[2] <= 0:
        flags.append("behind_camera")
    else:
        u, v = project(np.zeros((1, 3)), R, t, camera)[0]
        w, h = camera.size or (np.inf, np.inf)
        if not (-0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5):
            flags.append("outside_view")
    if confidence < LOW_CONFIDENCE:
        flags.append("low_confidence")
    return tuple(flags)


def _object_and_camera(state: dict[str, Any], ckpt: Path, data: Path | None) -> tuple[ObjectModel, Camera]:
    """The object and the training camera: from the checkpoint, else from the dataset `data`."""
    cfg = config_from_dict(state["config"])
    regions, pm = state["model_config"]["num_regions"], cfg.data.num_pm_points
    record, cam = state.get("object", {}), state.get("camera")
    if "vertices" in record and cam is not None:
        return object_from_record(record, regions, pm), Camera.from_dict(cam)
    if data is None:
        raise PosenetError(
            f"{ckpt} predates posenet predict (it holds no object mesh or training camera): "
            "give --data, the dataset it was trained on"
        )
    instances = scan_split(data, "train", cfg.data.obj_id)
    if not instances:
        raise PosenetError(f"{data} has no training images of object {cfg.data.obj_id}")
    camera, _ = training_camera([i.K for i in instances], image_size(data))
    return load_object_model(data, cfg.data.obj_id, regions, pm), camera
