"""What `posenet predict` reads: an image, a folder, a glob or a video, or a split of a labelled dataset.

Each input is a `Frame`: its name (the file, `video.mp4#000012` for a frame), the image or the reason it
could not be read (a bad input is recorded, and the batch goes on), and, from a dataset, its camera, its
(scene_id, im_id) and ground-truth box.
"""

from __future__ import annotations

import glob
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from posenet.data.camera import Camera, make_camera
from posenet.data.layout import scan_split
from posenet.errors import PosenetError
from scgen.io import read_image, why_unreadable

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v")


@dataclass(frozen=True)
class Frame:
    name: str
    image: np.ndarray | None
    error: str | None = None
    camera: Camera | None = None  # a dataset's per-image camera
    key: tuple[int, int] | None = None  # a dataset's (scene_id, im_id)
    box: tuple[float, float, float, float] | None = None  # a dataset's ground-truth box (bbox_obj)


@dataclass(frozen=True)
class Source:
    """Resolved inputs: image files, or one video."""

    images: tuple[Path, ...] = ()
    video: Path | None = None

    def __len__(self) -> int:
        if self.video is None:
            return len(self.images)
        cap = cv2.VideoCapture(str(self.video))
        try:
            return max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), 0)
        finally:
            cap.release()

    @property
    def fps(self) -> float:
        """The video's frame rate (25 where the container does not say)."""
        if self.video is None:
            return 0.0
        cap = cv2.VideoCapture(str(self.video))
        try:
            return float(cap.get(cv2.CAP_PROP_FPS)) or 25.0
        finally:
            cap.release()


def resolve_source(text: str) -> Source:
    """The inputs SOURCE names: a video file, an image file, a folder's images (sorted, not recursive)
    or a glob's images; nothing to read is a one-line error."""
    path = Path(text)
    if path.is_file():
        if path.suffix.lower() in VIDEO_SUFFIXES:
            cap = cv2.VideoCapture(str(path))
            ok = cap.isOpened()
            cap.release()
            if not ok:
                raise PosenetError(f"cannot open video {path}")
            return Source(video=path)
        return Source(images=(path,))
    if path.is_dir():
        images = tuple(sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES))
        if not images:
            raise PosenetError(f"{path} holds no images ({', '.join(IMAGE_SUFFIXES)})")
        return Source(images=images)
    if glob.has_magic(text):
        images = tuple(sorted(Path(p) for p in glob.glob(text) if Path(p).is_file()))
        if not images:
            raise PosenetError(f"no file matches {text}")
        return Source(images=images)
    raise PosenetError(f"no such image, folder, glob or video: {text}")


def read_frames(source: Source) -> Iterator[Frame]:
    """The source's images in order; an unreadable one as a Frame with its error."""
    if source.video is not None:
        cap = cv2.VideoCapture(str(source.video))
        try:
            index = 0
            while True:
                ok, image = cap.read()
                if not ok:
                    break
                yield Frame(f"{source.video.name}#{index:06d}", image)
                index += 1
        finally:
            cap.release()
        return
    for path in source.images:
        image = read_image(path, cv2.IMREAD_COLOR)
        yield Frame(
            str(path), image, None if image is not None else f"cannot read image: {why_unreadable(path)}"
        )


def dataset_frames(data: Path, split: str, obj_id: int) -> list[Frame]:
    """One Frame per image of the split showing `obj_id` (read lazily: image None until `load_frame`),
    with the image's camera (cam_K, cam_dist) and the instance's full-object box, as `posenet eval`
    crops it."""
    frames, seen = [], set()
    for inst in scan_split(data, split, obj_id):
        if inst.px_count_visib <= 0 or inst.key in seen:
            continue
        seen.add(inst.key)
        camera = make_camera(inst.K, None, inst.image_size)
        frames.append(
            Frame(str(inst.rgb), None, None, camera, inst.key, tuple(float(v) for v in inst.bbox_obj))
        )
    if not frames:
        raise PosenetError(f"split '{split}' of {data} shows object {obj_id} in no image")
    return frames


def load_frame(frame: Frame) -> Frame:
    """A lazily listed dataset Frame with its image read (or its error)."""
    if frame.image is not None or frame.error is not None:
        return frame
    image = read_image(Path(frame.name), cv2.IMREAD_COLOR)
    error = None if image is not None else f"cannot read image: {why_unreadable(Path(frame.name))}"
    return Frame(frame.name, image, error, frame.camera, frame.key, frame.box)
