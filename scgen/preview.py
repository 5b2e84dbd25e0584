"""`scgen preview`: one contact-sheet PNG showing that every factor varies, and what the labels are.

Per sample: the RGB image; below it, zoomed on the target, the mask outlines (full: cyan, visible:
yellow) over the image, the visible mask (occluded part of the full mask in grey) and the xyz map
in colour; then the factor labels as the dataset records them (measured shadow and occlusion). Labelled
objects beside the target (`[[objects]]`) are outlined on the image, each visible mask in its object's
colour with its obj_id.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image
from tqdm import tqdm

from scgen.annotate import Annotation
from scgen.generator import Generator
from scgen.scenes.factors import distance_groups
from scgen.scenes.spec import SceneSpec

TILE_W = 320  # width of a sample's RGB tile in the sheet; the three label panels share it
COLUMNS = 4
CAPTION_H = 46
ZOOM_MARGIN = 1.3  # the zoomed panels show the full-mask box enlarged by this factor
FULL_COLOUR = (0, 220, 255)
VISIB_COLOUR = (255, 230, 0)
OBJECT_COLOURS = ((255, 90, 200), (120, 255, 90), (255, 150, 40), (150, 120, 255))  # by obj_id, cycling


def xyz_colours(xyz: np.ndarray, mask: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Model coordinates mapped to RGB over the model's bounding box; black off the mask."""
    rgb = np.clip((xyz - lo) / np.maximum(hi - lo, 1e-9), 0, 1) * 255
    return np.where(mask[..., None], rgb, 0).astype(np.uint8)


def outlines(rgb: np.ndarray, ann: Annotation) -> np.ndarray:
    """The image with the full-mask (cyan) and visible-mask (yellow) outlines."""
    out = rgb.copy()
    for mask, colour in ((ann.mask, FULL_COLOUR), (ann.mask_visib, VISIB_COLOUR)):
        contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(out, contours, -1, colour, 1)
    return out


def object_outlines(rgb: np.ndarray, objects: list[tuple[int, Annotation]]) -> np.ndarray:
    """The image with each labelled object's visible-mask outline in its obj_id's colour (OBJECT_COLOURS)
    and its obj_id beside it; `objects`: (obj_id, its labels) of every instance beside the target."""
    out = rgb.copy()
    for obj_id, ann in objects:
        colour = OBJECT_COLOURS[(obj_id - 2) % len(OBJECT_COLOURS)]
        contours, _ = cv2.findContours(
            ann.mask_visib.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE
        )
        cv2.drawContours(out, contours, -1, colour, 1)
        if ann.px_count_visib:
            x, y, _, _ = ann.bbox_visib
            cv2.putText(
                out, str(obj_id), (x, max(y - 2, 9)), cv2.FONT_HERSHEY_PLAIN, 0.8, colour, 1, cv2.LINE_AA
            )
    return out


def zoom(img: np.ndarray, bbox: list[int], size: tuple[int, int]) -> np.ndarray:
    """The region around bbox [x, y, w, h] (aspect of `size` = (w, h), zero-padded), resized to `size`."""
    x, y, w, h = bbox
    if w == 0 or h == 0:
        return np.zeros((size[1], size[0], 3), np.uint8)
    cx, cy = x + 0.5 * w, y + 0.5 * h
    half_w = 0.5 * ZOOM_MARGIN * max(w, h * size[0] / size[1]) + 2
    half_h = half_w * size[1] / size[0]
    x0, y0 = int(round(cx - half_w)), int(round(cy - half_h))
    x1, y1 = int(round(cx + half_w)), int(round(cy + half_h))
    pad = max(0, -x0, -y0, x1 - img.shape[1], y1 - img.shape[0])
    padded = np.pad(img, ((pad, pad), (pad, pad), (0, 0)))
    crop = padded[y0 + pad : y1 + pad, x0 + pad : x1 + pad]
    return cv2.resize(crop, size, interpolation=cv2.INTER_NEAREST)


def labels(spec: SceneSpec, ann: Annotation, distance_group: str, exposure_ev: float) -> list[str]:
    """Caption lines: the factor groups of the robustness table, with their measured values, and the
    exposure the camera used."""
    caster = "caster" if spec.shadow_caster else "no caster"
    return [
        f"#{spec.index} {spec.sun.level} (EV{exposure_ev:+.1f})  {spec.background.kind}"
        f"  {distance_group} {spec.distance_m:.2f} m",
        f"shadow {ann.shadow_label} {ann.shadow_fraction:.2f} ({caster})",
        f"occlusion {ann.occlusion_group} {ann.r_occ:.2f} (aim {spec.requested_occlusion})",
    ]


def display_rgb(image: np.ndarray) -> np.ndarray:
    """A recorded image as 8-bit RGB for the sheet: 16-bit codes to their top byte, one channel to grey."""
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    return np.repeat(image[..., None], 3, axis=2) if image.ndim == 2 else image


def sample_tile(rgb: np.ndarray, ann: Annotation, xyz_rgb: np.ndarray, caption: list[str]) -> np.ndarray:
    """One sample's block: RGB on top, zoomed outlines | visible mask | xyz below, caption at the bottom."""
    h, w = rgb.shape[:2]
    big = cv2.resize(rgb, (TILE_W, round(TILE_W * h / w)), interpolation=cv2.INTER_AREA)
    size = (TILE_W // 3, round(TILE_W // 3 * h / w))
    visib = np.where(ann.mask_visib, 255, np.where(ann.mask, 90, 0)).astype(np.uint8)
    panels = [outlines(rgb, ann), np.repeat(visib[..., None], 3, axis=2), xyz_rgb]
    small = np.hstack([zoom(p, ann.bbox_obj, size) for p in panels])
    small = np.pad(small, ((0, 0), (0, TILE_W - small.shape[1]), (0, 0)))
    text = np.zeros((CAPTION_H, TILE_W, 3), np.uint8)
    for k, line in enumerate(caption):
        cv2.putText(text, line, (3, 12 + 14 * k), cv2.FONT_HERSHEY_PLAIN, 0.75, (235, 235, 235), 1,
                    cv2.LINE_AA)  # fmt: skip
    return np.vstack([big, small, text])


def contact_sheet(tiles: list[np.ndarray], columns: int = COLUMNS, gap: int = 4) -> np.ndarray:
    """Tiles (equal size) in a grid with grey gaps."""
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // columns)
    sheet = np.full((rows * (h + gap) + gap, columns * (w + gap) + gap, 3), 60, np.uint8)
    for k, tile in enumerate(tiles):
        r, c = divmod(k, columns)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        sheet[y : y + h, x : x + w] = tile
    return sheet


def save_png(sheet: np.ndarray, path: Path) -> None:
    """Palette PNG (256 adaptive colours): a 16-sample sheet stays well under a megabyte."""
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(sheet).quantize(256, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)


def build_preview(generator: Generator, n: int, progress: bool = False) -> np.ndarray:
    """Sample, render and annotate samples 0..n-1 exactly as `scgen render` does; return the sheet (with
    `progress`, a bar per sample: ~1 s each at 320x240)."""
    from scgen.scenes.config.scene import distance_range_m

    lo, hi = generator.model.mesh.bounds
    d_lo, d_hi = distance_range_m(generator.cfg, generator.model.diameter)
    tiles = []
    with generator:
        for i in tqdm(range(n), desc="preview", unit="sample", dynamic_ncols=True, disable=not progress):
            sample = generator.sample(i)
            spec, ann = sample.spec, sample.annotation
            (group,), _ = distance_groups(np.array([spec.distance_m]), d_lo, d_hi)
            record = sample.buffers.camera
            caption = labels(spec, ann, group, record.exposure_ev if record else spec.camera.exposure_ev)
            xyz_rgb = xyz_colours(ann.xyz, ann.mask_visib, lo, hi)
            rgb = display_rgb(sample.buffers.rgb)
            if spec.objects:
                rgb = object_outlines(
                    rgb, [(o.obj_id, a) for o, a in zip(spec.objects, sample.objects, strict=True)]
                )
            tiles.append(sample_tile(rgb, ann, xyz_rgb, caption))
    return contact_sheet(tiles)


AXIS_COLOURS = ((255, 70, 70), (70, 230, 70), (90, 150, 255))  # the model's x, y, z axes: red, green, blue


def draw_axes(rgb: np.ndarray, spec: SceneSpec, length: float) -> np.ndarray:
    """The image with the model frame's axes (from its origin, `length` metres long) as the pose puts them,
    projected through the camera; an axis reaching behind the camera is left out."""
    out = rgb.copy()
    R, t = spec.target.R_mat, spec.target.t_vec
    points = np.vstack([t, length * R.T + t])  # rows: the origin, then the x, y, z axes' ends
    if np.any(points[:, 2] <= 1e-6):
        return out
    uv = spec.camera.project(points)
    origin = tuple(int(round(c)) for c in uv[0])
    for end, colour in zip(uv[1:], AXIS_COLOURS, strict=True):
        cv2.line(out, origin, tuple(int(round(c)) for c in end), colour, 1, cv2.LINE_AA)
    return out


def sequence_frame(rgb: np.ndarray, spec: SceneSpec, ann: Annotation, diameter: float) -> np.ndarray:
    """One frame of a sequence preview: the image with the mask outlines and the model's axes, a caption."""
    image = draw_axes(outlines(rgb, ann), spec, 0.5 * diameter)
    f = spec.sequence
    assert f is not None
    eclipse = ", ECLIPSE" if f.eclipse else ""
    lines = [f"seq {f.sequence} frame {f.frame}  t {f.time_s:.1f} s  range {f.range_m:.1f} m",
             f"{f.profile}, {f.attitude}, {spec.background.kind}{eclipse}"]  # fmt: skip
    text = np.zeros((CAPTION_H - 14, image.shape[1], 3), np.uint8)
    for k, line in enumerate(lines):
        cv2.putText(text, line, (3, 12 + 14 * k), cv2.FONT_HERSHEY_PLAIN, 0.75, (235, 235, 235), 1,
                    cv2.LINE_AA)  # fmt: skip
    return np.vstack([image, text])


def build_sequence_preview(generator: Generator, sequence: int) -> list[np.ndarray]:
    """Render and annotate every frame of sequence `sequence` exactly as `scgen render` does; return the
    frames with the target's outline (full: cyan, visible: yellow) and axes (x red, y green, z blue)."""
    frames = []
    with generator:
        for spec in generator.sequence(sequence):
            sample = generator.render(spec)
            frames.append(sequence_frame(display_rgb(sample.buffers.rgb), spec, sample.annotation,
                                         generator.model.diameter))  # fmt: skip
    return frames


def save_gif(frames: list[np.ndarray], path: Path, frame_ms: int = 200) -> None:
    """An animated GIF, looping, each frame shown `frame_ms` (one adaptive 256-colour palette per frame)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(f).quantize(256, method=Image.Quantize.MEDIANCUT) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=frame_ms, loop=0, optimize=True)
