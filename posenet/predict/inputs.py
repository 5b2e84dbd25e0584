"""Everything `posenet predict` reads, checked before its first output is written: the checkpoints, the
camera, the inputs and where each image's box comes from. A problem is one PosenetError line."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from posenet.data.boxes import read_boxes, read_misses
from posenet.data.camera import Camera, make_camera, parse_inline, read_camera_file
from posenet.errors import PosenetError
from posenet.navigation.config import NavConfig
from posenet.navigation.noise import NoiseModel, require_noise
from posenet.predict.objects import ObjectsPredictor
from posenet.predict.options import PREDICT_PASSES, SAME_CROP_IOU
from posenet.predict.predictor import Box, Predictor
from posenet.predict.run import MISS
from posenet.predict.sources import Frame, dataset_frames, read_frames, resolve_source
from posenet.predict.track import Tracker
from scgen.io import SequenceFrame, read_sequence_frames

PresetLookup = Callable[[str], tuple[list[list[float]], list[float], tuple[int, int]]]
TRAINING = "training"  # --camera training: the checkpoint's own camera


@dataclass
class PredictInputs:
    predictor: Predictor | ObjectsPredictor  # several pose checkpoints: an ObjectsPredictor
    frames: Iterable[Frame]
    total: int
    camera: Camera | None  # None with --data: each frame brings its own
    box_for: Callable[[Frame, int], Box | str | None]
    video_fps: float = 0.0
    tracker: Tracker | None = None  # --track or --filter
    sequences: dict[tuple[int, int], SequenceFrame] | None = None  # a sequence dataset's frames
    frame_dt: float | None = None  # the filter outside a sequence dataset: the seconds between frames

    def sequence_of(self, frame: Frame) -> SequenceFrame | None:
        """A dataset frame's sequence, frame number and time; None outside a sequence dataset."""
        return (self.sequences or {}).get(frame.key) if frame.key is not None else None


def resolve_camera(text: str, training: Camera, presets: PresetLookup) -> Camera:
    """--camera: 'training', a camera file, a scgen preset name, or inline numbers."""
    if text == TRAINING:
        return training
    if Path(text).is_file():
        return read_camera_file(Path(text))
    if text.replace("_", "").isalpha():
        try:
            K, dist, size = presets(text)
        except Exception as exc:  # the preset table's own one-line error
            raise PosenetError(f"--camera {text!r}: {exc}") from exc
        return make_camera(np.asarray(K), dist, size)
    return parse_inline(text)


def parse_box(text: str) -> Box:
    try:
        x, y, w, h = (float(v) for v in text.split(","))
    except ValueError as exc:
        raise PosenetError(f"--box must be x,y,w,h (pixels), got '{text}'") from exc
    if not all(map(math.isfinite, (x, y, w, h))):
        raise PosenetError(f"--box must be x,y,w,h finite numbers (pixels), got '{text}'")
    if w <= 0 or h <= 0:
        raise PosenetError(f"--box width and height must be positive, got '{text}'")
    return x, y, w, h


def check_several(
    ckpts: Sequence[Path], detector: Path | None, boxed: bool, onnx: Path | None, navigation: bool
) -> None:
    """Refuse what several pose checkpoints (one per object) cannot take: every box is the detector's."""
    if len(ckpts) < 2:
        return
    if detector is None or boxed:
        raise PosenetError("several pose checkpoints (one per object) take their boxes from the detector: "
                           "give --detector, and neither --box nor --boxes")  # fmt: skip
    if onnx is not None or navigation:
        raise PosenetError("several pose checkpoints (one per object) take no --onnx, --track or --filter")


def multi_object_frames(data: Path, split: str, obj_ids: list[int]) -> list[Frame]:
    """The split's images showing any of the objects, one Frame each (dataset_frames), in (scene, image)
    order."""
    frames: dict[tuple[int, int] | None, Frame] = {}
    for obj_id in obj_ids:
        for frame in dataset_frames(data, split, obj_id):
            frames.setdefault(frame.key, frame)
    return [frames[k] for k in sorted(frames, key=lambda k: k or (-1, -1))]


def predict_inputs(
    source: str | None,
    ckpt: Path | Sequence[Path],
    detector: Path | None,
    camera: str | None,
    data: Path | None,
    split: str,
    box: str | None,
    boxes: Path | None,
    device: torch.device,
    presets: PresetLookup,
    onnx: Path | None = None,
    min_score: float | None = None,
    passes: int = PREDICT_PASSES,
    track: bool = False,
    frame_dt: float | None = None,
    nav_config: NavConfig | None = None,
    filtered: bool = False,
    same_crop_iou: float = SAME_CROP_IOU,
) -> PredictInputs:
    """The checked inputs of one predict run (nothing is written here). A sequence dataset's frames come
    in time order, sequence by sequence (what the filter and the per-sequence overlay videos need). Several
    checkpoints (one per object) give an ObjectsPredictor behind the detector (check_several). With
    `filtered` (every frame's pose through the navigation filter) or `track` (also each crop seeded from
    it), the checkpoint's calibrated noise is read (posenet calibrate) and each frame's time is its
    sequence's, else its index times `frame_dt` (default: a video's own frame interval)."""
    if (source is None) == (data is None):
        raise PosenetError("give SOURCE (an image, folder, glob or video) or --data DIR, not both or neither")
    if box is not None and boxes is not None:
        raise PosenetError("give --box or --boxes, not both")
    if data is None and camera is None:
        raise PosenetError("--camera is required with SOURCE: fx,fy,cx,cy[,dist], a camera.json, a scgen "
                           "preset name, or 'training' (the checkpoint's own camera)")  # fmt: skip
    if track and (detector is None or box is not None or boxes is not None):
        raise PosenetError("--track seeds each frame from the last pose and finds the target with the "
                           "detector: give --detector, and neither --box nor --boxes")  # fmt: skip
    ckpts = [ckpt] if isinstance(ckpt, Path) else list(ckpt)
    check_several(ckpts, detector, box is not None or boxes is not None, onnx, track or filtered)
    fixed_box = parse_box(box) if box is not None else None
    noise = NoiseModel.load(require_noise(ckpts[0])) if track or filtered else None
    predictor: Predictor | ObjectsPredictor
    if len(ckpts) > 1:
        assert detector is not None
        predictor = ObjectsPredictor.load(ckpts, detector, device, data, min_score, passes, same_crop_iou)
        obj_ids = predictor.obj_ids
    else:
        predictor = Predictor.load(ckpts[0], detector, device, data, onnx, min_score, passes, same_crop_iou)
        obj_ids = [predictor.obj.obj_id]
    sequences = read_sequence_frames(data) if data is not None else {}
    obj_id = obj_ids[0]
    if data is not None:
        if camera is not None:
            raise PosenetError("--camera is taken from the dataset with --data; leave it out")
        frames = dataset_frames(data, split, obj_id) if len(obj_ids) == 1 else multi_object_frames(
            data, split, obj_ids)  # fmt: skip
        if sequences:
            order = {k: (s.sequence_id, s.frame) for k, s in sequences.items()}
            frames.sort(key=lambda f: order.get(f.key, (-1, 0)) if f.key is not None else (-1, 0))
        user, total, fps, stream = None, len(frames), 0.0, frames
        keys = [f.key for f in frames if f.key is not None]
    else:
        user = resolve_camera(str(camera), predictor.camera, presets)
        src = resolve_source(str(source))
        total, fps, stream = len(src), src.fps, read_frames(src)
        keys = [(0, i) for i in range(total)]
    stored, misses = _read_box_file(boxes, obj_id, keys) if boxes is not None else ({}, set())
    if fixed_box is None and boxes is None and detector is None and data is None:
        raise PosenetError("no box for the images: give --detector, --box x,y,w,h or --boxes FILE")

    def box_for(frame: Frame, index: int) -> Box | str | None:
        key = frame.key if frame.key is not None else (0, index)
        if fixed_box is not None:
            return fixed_box
        if boxes is not None:
            return MISS if key in misses else stored[key]
        if detector is None and frame.box is not None:  # --data without a detector: GT, as posenet eval
            return frame.box
        return None

    tracker = None
    if track or filtered:
        assert noise is not None
        if not sequences:
            frame_dt = frame_dt or (1.0 / fps if fps > 0 else None)
            if frame_dt is None:
                raise PosenetError("the filter needs each frame's time: give --dt SECONDS between frames "
                                   "(a video has its rate, a sequence dataset its times)")  # fmt: skip
        assert isinstance(predictor, Predictor)
        tracker = Tracker(predictor, noise, nav_config, seed_crops=track)
    return PredictInputs(predictor, stream, total, user, box_for, fps, tracker, sequences, frame_dt)


def _read_box_file(path: Path, obj_id: int, keys: list[tuple[int, int]]) -> tuple[dict, set]:
    """The box file's boxes and misses; every input must have one or the other."""
    stored, misses = read_boxes(path, obj_id), read_misses(path, obj_id)
    missing = [k for k in keys if k not in stored and k not in misses]
    if missing:
        raise PosenetError(
            f"box file {path} has no box for {len(missing)} input(s), e.g. (scene, image) {missing[0]}"
        )
    return stored, misses
