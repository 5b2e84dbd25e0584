"""`posenet predict`'s batch: every input through the Predictor, one JSON line each, overlays, and the
optional BOP19 results and SPEED+ submission files; an input that cannot be read, or cannot go through
its camera, is recorded and the batch goes on.

OUT/predictions.jsonl   one line per input: source, (scene_id, im_id), Pose.to_json(), obj_id, time_ms; or
                        error (several objects: a line per object posed, or one of obj_id null for none)
OUT/results.csv         --format bop: BOP19 results (scene_id,im_id,obj_id,score,R,t,time; t in mm; a row
                        per posed object, the image's time on each)
OUT/submission.csv      --format speedplus: filename,q0,q1,q2,q3,x,y,z per image (Kelvins SPEC style)
OUT/overlays/*.jpg      per image: silhouette edge, axes and box at the predicted pose (not with --no-vis)
OUT/overlay.mp4         a video input's overlays as a video
OUT/sequences/ID.mp4    a sequence dataset's overlays, a video per sequence in time order (SEQUENCE_FPS)
OUT/sheet.jpg           up to SHEET_TILES overlays spread over the inputs, side by side
"""

from __future__ import annotations

import itertools
import json
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from posenet.data.camera import Camera, CameraMismatch
from posenet.navigation.scene import sequence_frames
from posenet.predict.batch import BatchPredictor
from posenet.predict.objects import ObjectsPredictor
from posenet.predict.overlay import contact_sheet, draw_pose
from posenet.predict.predictor import NO_DETECTION, Box, Pose, Predictor, Prepared, Timings
from posenet.predict.sources import Frame, load_frame
from posenet.predict.track import Tracker, estimate_json
from scgen.io import SequenceFrame, atomic_write_bytes, atomic_write_text, bop

MISS = "miss"  # a box file's entry for an image where its detector found nothing
PREDICTIONS_FILE = "predictions.jsonl"
SHEET_TILES = 8
JPEG_QUALITY = 90
SEQUENCE_FPS = 10.0  # the frame rate of a sequence's overlay video, whatever the frames' spacing in time


@dataclass
class PredictRun:
    """What one batch produced: the JSON records, how many failed, the seconds it took."""

    records: list[dict[str, Any]] = field(default_factory=list)
    failed: int = 0
    seconds: float = 0.0
    files: list[Path] = field(default_factory=list)


def overlay_name(frame: Frame, index: int) -> str:
    if frame.key is not None:
        return f"{frame.key[0]:06d}_{frame.key[1]:06d}.jpg"
    return f"{index:06d}_{Path(frame.name.split('#')[0]).stem}.jpg"


def run_predict(
    predictor: Predictor | ObjectsPredictor,
    frames: Iterable[Frame],
    total: int,
    out: Path,
    camera: Camera | None,
    box_for: Callable[[Frame, int], Box | str | None],
    vis: bool = True,
    formats: tuple[str, ...] = (),
    video_fps: float = 0.0,
    progress: Callable[[int], None] | None = None,
    warn: Callable[[str], None] = print,
    tracker: Tracker | None = None,
    sequence_of: Callable[[Frame], SequenceFrame | None] = lambda frame: None,
    batched: BatchPredictor | None = None,
    frame_dt: float | None = None,
) -> PredictRun:
    """Predict every frame (a dataset frame brings its camera, else `camera`), writing into `out` (made
    by the caller). `box_for(frame, index)` gives a frame's box, None for the detector's, MISS for none.
    With a `tracker`, each frame goes through the navigation filter (posenet.predict.track) at its time (its
    sequence's, from `sequence_of`: a frame's sequence, frame number and time, None outside a sequence
    dataset; else its index times `frame_dt`), restarted where a new sequence begins; each record then
    names its box_source and holds the filter's answer (`filter`) and, once its sequence has ended, the
    smoother's (`smoothed`). With `batched` (not with a tracker), frames are loaded in its thread pool and
    predicted `batched.size` at a time (_batches); with neither, each frame alone, its loading, warp and
    detection a frame ahead in another thread (_prepared). An ObjectsPredictor (several objects; no tracker,
    no batch, no box but its detector's) gives each frame one record per object it poses."""
    run, tic = PredictRun(), time.perf_counter()
    sheet_every = max(1, total // SHEET_TILES)
    sheet: list[np.ndarray] = []
    writer: cv2.VideoWriter | None = None
    videos = SequenceVideos(out / "sequences")
    if vis and not video_fps:
        (out / "overlays").mkdir(exist_ok=True)
    noted: set[str] = set()
    several = isinstance(predictor, ObjectsPredictor)
    if several:
        predictor.warn = warn
    if batched is not None:
        stream: Iterator[Any] = _batches(frames, batched, camera, box_for)
    elif tracker is None and not several:
        stream = _prepared(frames, predictor, camera, box_for)
    else:
        stream = iter(frames)
    sequence: int | None = None  # the sequence of the frame before
    tracked: list[dict[str, Any]] = []  # the records of the current track, for its smoother
    for index in itertools.count():
        before = {s: len(v) for s, v in predictor.timings.ms.items()}
        t0 = time.perf_counter()  # a file or video frame is decoded by the stream, a dataset's by load_frame
        item = next(stream, None)
        if item is None:
            break
        ready, shares = None, None  # with `batched`: the frame's pose and its share of its batch's ms
        if batched is not None:
            frame, ready, shares = item
        elif tracker is None and not several:
            frame, ready, ahead = item  # prepared a frame ahead: its stages' times come with it
            predictor.timings.merge(ahead)
        else:
            frame = load_frame(item)
            predictor.timings.add("decode", time.perf_counter() - t0)
        base: dict[str, Any] = {"source": frame.name, "index": index}
        if frame.key is not None:
            base |= {"scene_id": frame.key[0], "im_id": frame.key[1]}
        seq = sequence_of(frame)
        if seq is not None:
            base |= {"sequence_id": seq.sequence_id, "frame": seq.frame, "time_s": seq.time_s}
            if tracker is not None and seq.sequence_id != sequence:
                _attach_smoothed(tracked, tracker)
                tracker.reset(seq)
            sequence = seq.sequence_id
        elif tracker is not None:
            base["time_s"] = index * (frame_dt or 0.0)
        cam, error = _camera_for(frame, camera)
        if error is not None:
            run.failed += 1
            run.records.append({**base, "error": error})
            warn(f"Warning: {frame.name}: {error}")
        else:
            assert frame.image is not None and cam is not None
            if frame.note is not None and frame.note not in noted:
                noted.add(frame.note)
                warn(f"Warning: {frame.name}: {frame.note} (so is every such input after it, unmentioned)")
            box = box_for(frame, index)
            if isinstance(predictor, ObjectsPredictor):
                poses = _object_poses(predictor, frame.image, cam)
            elif box == MISS:
                pose = NO_DETECTION
            elif isinstance(ready, Prepared):
                pose = predictor.finish(ready)
            elif ready is not None:
                pose = ready
            elif tracker is not None:
                frames = sequence_frames(seq)
                step = tracker(frame.image, cam, base["time_s"], frames, box)  # type: ignore[arg-type]
                pose = step.pose if step.pose is not None else NO_DETECTION
                base |= {"box_source": step.source, **step.to_json()}
            else:
                pose = predictor(frame.image, cam, box)  # type: ignore[arg-type]
            if not several:
                poses = [(predictor.obj.obj_id, pose)]
            if vis:
                t1 = time.perf_counter()
                drawn = _draw_poses(frame.image, poses, _objects(predictor), cam)
                if video_fps:
                    if writer is None:
                        writer = _video_writer(out / "overlay.mp4", video_fps, drawn.shape[1::-1])
                    writer.write(drawn)
                else:
                    ok, jpg = cv2.imencode(".jpg", drawn, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
                    atomic_write_bytes(out / "overlays" / overlay_name(frame, index), jpg.tobytes())
                    if seq is not None:
                        videos.write(seq.sequence_id, drawn)
                if index % sheet_every == 0 and len(sheet) < SHEET_TILES:
                    sheet.append(drawn)
                predictor.timings.add("drawing", time.perf_counter() - t1)
            spent = {s: v[before.get(s, 0) :] for s, v in predictor.timings.ms.items()}
            time_ms = {
                s: round(sum(v), 3) for s, v in spent.items() if v and (shares is None or s == "drawing")
            }
            time_ms = (shares or {}) | time_ms
            run.records += [{**base, **p.to_json(), "obj_id": k, "time_ms": time_ms} for k, p in poses]
            if tracker is not None:
                tracked.append(run.records[-1])
        if progress is not None:
            progress(1)
    if tracker is not None:
        _attach_smoothed(tracked, tracker)
    if writer is not None:
        writer.release()
        run.files.append(out / "overlay.mp4")
    run.files += videos.close()
    run.seconds = time.perf_counter() - tic
    _write_outputs(run, out, formats, sheet)
    return run


def _object_poses(
    predictor: ObjectsPredictor, image: np.ndarray, camera: Camera
) -> list[tuple[int | None, Pose]]:
    """Each object's (obj_id, pose) in a frame; a frame without any: one NO_DETECTION of no object."""
    found = predictor(image, camera)
    return [(p.obj_id, p.pose) for p in found] if found else [(None, NO_DETECTION)]


def _objects(predictor: Predictor | ObjectsPredictor) -> dict[int, Any]:
    """The object model of each obj_id the predictor poses."""
    if isinstance(predictor, ObjectsPredictor):
        return predictor.objects()
    return {predictor.obj.obj_id: predictor.obj}


def _draw_poses(
    image: np.ndarray, poses: list[tuple[int | None, Pose]], objects: dict, cam: Camera
) -> np.ndarray:
    """The frame with each pose drawn over it (draw_pose); a pose of no object, the frame as draw_pose
    draws a miss."""
    drawn = image
    for obj_id, pose in poses:
        drawn = draw_pose(drawn, pose, objects.get(obj_id, next(iter(objects.values()))), cam)
    return drawn


def _attach_smoothed(records: list[dict[str, Any]], tracker: Tracker) -> None:
    """Give the records of the track just ended (each frame that went through the filter) the
    smoother's estimate, and start a new list."""
    for record, estimate in zip(records, tracker.smoothed(), strict=True):
        record["smoothed"] = None if estimate is None else estimate_json(estimate)
    records.clear()


def _prepared(
    frames: Iterable[Frame],
    predictor: Predictor,
    camera: Camera | None,
    box_for: Callable[[Frame, int], Box | str | None],
) -> Iterator[tuple[Frame, Prepared | Pose | None, Timings]]:
    """The frames, each loaded, warped into the training camera and boxed (Predictor.prepare) in a helper
    thread a frame ahead, so that the next frame's detector runs while the pose network runs on this one:
    each frame is still predicted alone and as by Predictor.__call__. With each its prepared image (None
    where it has no camera or its box is MISS) and the times its preparation took."""
    stream = iter(frames)

    def prepare(index: int) -> tuple[Frame, Prepared | Pose | None, Timings] | None:
        timings, tic = Timings(), time.perf_counter()
        item = next(stream, None)
        if item is None:
            return None
        frame = load_frame(item)
        timings.add("decode", time.perf_counter() - tic)
        cam, error = _camera_for(frame, camera)
        box = box_for(frame, index) if error is None else MISS
        if box == MISS:
            return frame, None, timings
        return frame, predictor.prepare(frame.image, cam, box, timings), timings  # type: ignore[arg-type]

    with ThreadPoolExecutor(1) as ahead:
        coming = ahead.submit(prepare, 0)
        for index in itertools.count(1):
            done = coming.result()
            if done is None:
                return
            coming = ahead.submit(prepare, index)
            yield done


def _batches(
    frames: Iterable[Frame],
    batched: BatchPredictor,
    camera: Camera | None,
    box_for: Callable[[Frame, int], Box | str | None],
) -> Iterator[tuple[Frame, Pose | None, dict[str, float]]]:
    """The frames loaded in `batched`'s pool, the next batch while one is predicted, and predicted
    `batched.size` at a time: each with its pose (None where it has no camera or its box is MISS) and its
    share of its batch's milliseconds by stage (decode: the wait for the batch)."""
    stream, timings = iter(frames), batched.predictor.timings

    def load() -> list[Frame]:
        return list(batched.pool.map(load_frame, itertools.islice(stream, batched.size)))

    index = 0
    with ThreadPoolExecutor(1) as ahead:
        coming = ahead.submit(load)
        while True:
            tic = time.perf_counter()
            chunk = coming.result()
            if not chunk:
                return
            coming = ahead.submit(load)
            before = {s: len(v) for s, v in timings.ms.items()}
            for _ in chunk:
                timings.add("decode", (time.perf_counter() - tic) / len(chunk))
            wanted = []
            for i, frame in enumerate(chunk):
                cam, error = _camera_for(frame, camera)
                box = box_for(frame, index + i) if error is None else MISS
                if box != MISS:
                    wanted.append((i, cam, box))
            poses: list[Pose | None] = [None] * len(chunk)
            images = [chunk[i].image for i, _, _ in wanted]
            found = batched(images, [c for _, c, _ in wanted], [b for _, _, b in wanted])  # type: ignore[misc]
            for (i, _, _), pose in zip(wanted, found, strict=True):
                poses[i] = pose
            spent = {s: sum(v[before.get(s, 0) :]) / len(chunk) for s, v in timings.ms.items()}
            shares = {s: round(v, 3) for s, v in spent.items() if v}
            for frame, pose in zip(chunk, poses, strict=True):
                yield frame, pose, shares
            index += len(chunk)


def _camera_for(frame: Frame, camera: Camera | None) -> tuple[Camera | None, str | None]:
    """The frame's camera (a dataset's own, else the run's) fitted to its image, or why there is none:
    the image could not be read, or cannot go through that camera (CameraMismatch)."""
    if frame.image is None:
        return None, frame.error
    cam = frame.camera or camera
    assert cam is not None
    try:
        return cam.for_image(frame.image.shape[1::-1]), None
    except CameraMismatch as exc:
        return None, str(exc)


def _video_writer(path: Path, fps: float, size: tuple[int, int]) -> cv2.VideoWriter:
    return cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)


class SequenceVideos:
    """The overlays of a sequence dataset as one video per sequence, FOLDER/SEQUENCE_ID.mp4, in the order
    the frames come (predict_inputs gives them in time order, sequence by sequence). Each video is
    written under a partial name and renamed when its sequence ends: a stopped run leaves no video that
    looks whole."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.sequence: int | None = None
        self.writer: cv2.VideoWriter | None = None
        self.done: list[Path] = []

    def write(self, sequence_id: int, image: np.ndarray) -> None:
        """Append `image` to its sequence's video, ending the one before at a new sequence."""
        if sequence_id != self.sequence:
            self._end()
            self.folder.mkdir(exist_ok=True)
            self.sequence = sequence_id
            self.writer = _video_writer(self._partial(), SEQUENCE_FPS, image.shape[1::-1])
        assert self.writer is not None
        self.writer.write(image)

    def close(self) -> list[Path]:
        """End the last video; every finished video's path."""
        self._end()
        return self.done

    def _partial(self) -> Path:
        return self.folder / f"{self.sequence:06d}.partial.mp4"

    def _end(self) -> None:
        if self.writer is None:
            return
        self.writer.release()
        self.done.append(self._partial().replace(self.folder / f"{self.sequence:06d}.mp4"))
        self.writer = None


def _write_outputs(run: PredictRun, out: Path, formats: tuple[str, ...], sheet: list[np.ndarray]) -> None:
    lines = "".join(json.dumps(r) + "\n" for r in run.records)
    atomic_write_text(out / PREDICTIONS_FILE, lines)
    run.files.insert(0, out / PREDICTIONS_FILE)
    posed = [r for r in run.records if r.get("R") is not None]
    if "bop" in formats:
        atomic_write_text(out / "results.csv", bop.results_csv([_bop_record(r) for r in posed]))
        run.files.append(out / "results.csv")
    if "speedplus" in formats:
        rows = [
            ",".join([submission_name(r["source"]), *map(repr, r["quaternion"]), *map(repr, r["t"])])
            for r in posed
        ]
        atomic_write_text(out / "submission.csv", "".join(row + "\n" for row in rows))
        run.files.append(out / "submission.csv")
    if sheet:
        ok, jpg = cv2.imencode(".jpg", contact_sheet(sheet), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        atomic_write_bytes(out / "sheet.jpg", jpg.tobytes())
        run.files.append(out / "sheet.jpg")


def submission_name(source: str) -> str:
    """An image's file name (SPEED+ labels name images without folders); a video frame keeps its name."""
    return source if "#" in source else Path(source).name


def _bop_record(r: dict[str, Any]) -> dict[str, Any]:
    """A prediction as scgen.io.bop.results_csv reads a record: a dataset image keeps its ids; any other
    input is scene 0, its image id its place in the input order."""
    ids = {"scene_id": r.get("scene_id", 0), "im_id": r.get("im_id", r["index"]), "obj_id": r["obj_id"]}
    seconds = sum(r["time_ms"].values()) / 1000.0
    return {**ids, "R": r["R"], "t": r["t"], "score": r["confidence"], "time_s": seconds}
