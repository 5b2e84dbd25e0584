"""What `posenet predict` reads: an image, a folder, a glob or a video, or a split of a labelled dataset.

Each input is a `Frame`: its name (the file, `video.mp4#000012` for a frame), the image (posenet.predict.
pixels.to_bgr8's) or the reason it could not be read (a bad input is recorded, and the batch goes on), a
note on how it was read where that was a guess, and, from a dataset, its camera (lens included), its
(scene_id, im_id) and ground-truth box.
"""

from __future__ import annotations

import glob
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from posenet.data.camera import Camera, make_camera
from posenet.data.layout import scan_split
from posenet.errors import PosenetError
from posenet.predict.pixels import to_bgr8
from scgen.io import read_image, why_unreadable

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v")
# what OpenCV decodes of an image file: any depth (16-bit kept for to_bgr8), grey or colour (alpha dropped),
# turned as its EXIF orientation says
READ_FLAGS = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR


@dataclass(frozen=True)
class Frame:
    name: str
    image: np.ndarray | None
    error: str | None = None
    camera: Camera | None = None  # a dataset's per-image camera
    key: tuple[int, int] | None = None  # a dataset's (scene_id, im_id)
    box: tuple[float, float, float, float] | None = None  # a dataset's ground-truth box (bbox_obj)
    note: str | None = None  # how the image was read, where that was a guess (to_bgr8)


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
    or a glob's images (a glob follows a folder's rules: images only); nothing to read is a one-line
    error."""
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
        return Source(images=_images(path.iterdir(), f"{path} holds no images"))
    if glob.has_magic(text):
        return Source(images=_images(map(Path, glob.glob(text)), f"no image matches {text}"))
    raise PosenetError(f"no such image, folder, glob or video: {text}")


def _images(paths: Iterable[Path], none: str) -> tuple[Path, ...]:
    """The image files (IMAGE_SUFFIXES) among `paths`, sorted; none is the one-line error `none`."""
    images = tuple(sorted(p for p in paths if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()))
    if not images:
        raise PosenetError(f"{none} ({', '.join(IMAGE_SUFFIXES)})")
    return images


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
        yield _read(Frame(str(path), None))


def _read(frame: Frame) -> Frame:
    """The frame with its file read and converted, or the reason it could not be."""
    path = Path(frame.name)
    image, note, error = read_image(path, READ_FLAGS), None, None
    if image is None:
        error = f"cannot read image: {why_unreadable(path)}"
    else:
        try:
            image, note = to_bgr8(image)
        except PosenetError as exc:
            image, error = None, str(exc)
    return replace(frame, image=image, error=error, note=note)


def dataset_frames(data: Path, split: str, obj_id: int) -> list[Frame]:
    """One Frame per image of the split showing `obj_id` (read lazily: image None until `load_frame`),
    with the image's camera (cam_K and a lens' cam_dist: the image is warped into the training camera as
    any other) and the instance's full-object box, as `posenet eval` crops it. An unreadable image is
    that frame's error, not the split's."""
    frames, seen = [], set()
    for inst in scan_split(data, split, obj_id, lens=True, check_images=False):
        if inst.px_count_visib <= 0 or inst.key in seen:
            continue
        seen.add(inst.key)
        camera = make_camera(inst.K, inst.dist, inst.image_size)
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
    return _read(frame)
