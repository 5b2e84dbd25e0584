"""Drawing a predicted pose on the user's image, in the paper's qualitative style: the model's projected
silhouette edge, its axes at the predicted pose, and the box; a contact sheet of several."""

from __future__ import annotations

import re

import cv2
import numpy as np

from posenet.data.camera import Camera, project
from posenet.data.object_model import ObjectModel
from posenet.predict.predictor import Box, Pose

POSE_COLOUR = (60, 220, 60)  # BGR: the silhouette edge
BOX_COLOUR = (0, 200, 255)
AXIS_COLOURS = ((0, 0, 255), (0, 255, 0), (255, 0, 0))  # x red, y green, z blue
WARN_COLOUR = (0, 0, 255)
AXIS_LENGTH = 0.5  # of the object's diameter


def outline(uv: np.ndarray, faces: np.ndarray, size: tuple[int, int]) -> list[np.ndarray]:
    """Outer contours of a mesh whose vertices project to `uv` (N x 2 pixels): every triangle filled on an
    image of `size` (width, height), then traced."""
    canvas = np.zeros((size[1], size[0]), np.uint8)
    tris = np.round(np.clip(uv, -1e5, 1e5)[faces] * 8).astype(np.int32)  # 3 bits of sub-pixel precision
    cv2.fillPoly(canvas, list(tris), 255, shift=3)
    contours, _ = cv2.findContours(canvas, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return list(contours)


def thickness(image: np.ndarray) -> int:
    return max(1, round(max(image.shape[:2]) / 400))


def draw_pose(image: np.ndarray, pose: Pose, obj: ObjectModel, camera: Camera, label: str = "") -> np.ndarray:
    """A copy of `image` (BGR) with the pose drawn through `camera` (its lens too) and a label line."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    size, lw = (out.shape[1], out.shape[0]), thickness(out)
    if pose.box is not None:
        draw_box(out, pose.box, BOX_COLOUR)
    in_front = (
        pose.R is not None and pose.t is not None and np.all(obj.vertices @ pose.R.T[:, 2] + pose.t[2] > 0)
    )
    if in_front:  # a pose reaching behind the camera has no image to draw
        uv = project(obj.vertices, pose.R, pose.t, camera)
        cv2.drawContours(out, outline(uv, obj.faces, size), -1, POSE_COLOUR, lw, cv2.LINE_AA)
        ends = np.vstack([np.zeros(3), np.eye(3) * AXIS_LENGTH * obj.diameter])
        o, *tips = project(ends, pose.R, pose.t, camera)
        for tip, colour in zip(tips, AXIS_COLOURS, strict=True):
            cv2.line(out, _pt(o), _pt(tip), colour, lw + 1, cv2.LINE_AA)
    text = f"{label} score {pose.score:.2f} conf {pose.confidence:.2f}"
    if pose.flags:
        text += " " + ",".join(pose.flags)
    draw_label(out, text.strip(), WARN_COLOUR if pose.flags else (255, 255, 255))
    return out


def draw_box(image: np.ndarray, box: Box, colour: tuple[int, int, int]) -> None:
    """Draw [x, y, w, h] (pixels x .. x + w - 1) on `image` in place, its edges through the outer pixels'
    centres."""
    x, y, w, h = box
    corners = (round(x - 0.5), round(y - 0.5)), (round(x + w - 0.5), round(y + h - 0.5))
    cv2.rectangle(image, *corners, colour, thickness(image))


LABEL_MARGIN = 6  # pixels between a label and the image's left and right edges
LABEL_FONT = cv2.FONT_HERSHEY_SIMPLEX


def label_style(image: np.ndarray) -> tuple[int, float, int]:
    """(stroke width, font scale, line pitch in pixels) of a label on `image`: sized to the image, the
    scale 0.4 at the least."""
    scale = max(0.4, max(image.shape[:2]) / 1200)
    return thickness(image), scale, round(22 * scale / 0.5)


def draw_label(image: np.ndarray, text: str, colour: tuple[int, int, int]) -> None:
    """Write `text` at the top left of `image` in place (label_style), over a dark outline; a text wider
    than the image goes on over as many lines as it needs (label_lines)."""
    lw, scale, leading = label_style(image)
    for row, line in enumerate(label_lines(text, image.shape[1] - 2 * LABEL_MARGIN, scale, lw + 2)):
        for ink, width in (((0, 0, 0), lw + 2), (colour, lw)):
            origin = (LABEL_MARGIN, leading * (row + 1))
            cv2.putText(image, line, origin, LABEL_FONT, scale, ink, width, cv2.LINE_AA)


def label_lines(text: str, width: int, scale: float, stroke: int) -> list[str]:
    """`text` broken after spaces and commas into lines no wider than `width` pixels in the label's
    font (a single word wider than that keeps a line of its own)."""
    lines = [""]
    for word in re.findall(r"[^ ,]+[ ,]?|[ ,]", text):
        wider = lines[-1] + word
        if lines[-1] and cv2.getTextSize(wider.rstrip(), LABEL_FONT, scale, stroke)[0][0] > width:
            lines.append(word.lstrip())
        else:
            lines[-1] = wider
    return [line.rstrip() for line in lines]


def _pt(p: np.ndarray) -> tuple[int, int]:
    return int(round(float(np.clip(p[0], -1e5, 1e5)))), int(round(float(np.clip(p[1], -1e5, 1e5))))


def contact_sheet(images: list[np.ndarray], columns: int = 4, tile_width: int = 320) -> np.ndarray:
    """The images side by side, `columns` a row, each scaled to `tile_width` (height by its aspect)."""
    tiles = [
        cv2.resize(
            im, (tile_width, round(im.shape[0] * tile_width / im.shape[1])), interpolation=cv2.INTER_AREA
        )
        for im in images
    ]
    height = max(t.shape[0] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, height - t.shape[0], 0, 0, cv2.BORDER_CONSTANT, value=0) for t in tiles]
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % columns)
    rows = [np.hstack(tiles[i : i + columns]) for i in range(0, len(tiles), columns)]
    return np.vstack(rows)
