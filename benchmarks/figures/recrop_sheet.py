"""Re-crop, seen: the first pass's crop box against the refined ones on held-out images.

    python benchmarks/figures/recrop_sheet.py --ckpt POSE/last.pt --data CORRIDOR_S8 --boxes BOXES.json \
        [--split test] [--n 8] [--passes 3] [--out docs/recrop_sheet.jpg]

For the first --n images of the split that have a box in --boxes (`posenet boxes`: perturbed ground
truth, or the detector's), the pose network runs --passes times as `posenet predict --passes` does
(posenet.Predictor: each pass after the first re-crops around the model's box at the pose before). Each
tile draws the full object's true box bbox_obj (white), the first pass's crop box (red) and the last
pass's (green), and gives both boxes' IoU with bbox_obj; the tiles go side by side in one sheet.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, positive, run_script

from posenet import Predictor
from posenet.data.boxes import read_boxes
from posenet.data.camera import make_camera
from posenet.data.io import read_bgr
from posenet.data.layout import Instance, scan_split
from posenet.errors import PosenetError
from posenet.predict.overlay import contact_sheet, draw_box, draw_label
from posenet.predict.recrop import box_iou
from scgen.io.atomic import atomic_write_bytes

TRUE, FIRST, LAST = (255, 255, 255), (0, 0, 255), (0, 200, 0)  # BGR


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--ckpt", type=Path, required=True, help="Pose network checkpoint.")
    ap.add_argument("--data", type=Path, required=True, help="Held-out dataset folder.")
    ap.add_argument("--boxes", type=Path, required=True, help="Box file (posenet boxes) of the split.")
    ap.add_argument("--split", default="test", help="Split of --data [%(default)s].")
    ap.add_argument("--n", type=positive, default=8, help="Images on the sheet [%(default)s].")
    ap.add_argument("--passes", type=positive, default=3, help="Pose network runs per image [%(default)s].")
    ap.add_argument("--out", type=Path, default=Path("docs/recrop_sheet.jpg"), help="Sheet [%(default)s].")
    return ap.parse_args()


def tile(predictor: Predictor, instance: Instance, box: tuple[float, ...]) -> np.ndarray:
    """The instance's image with its true box, the first crop box and the last, and their IoUs."""
    image = read_bgr(instance.rgb)
    pose = predictor(image, make_camera(instance.K, instance.dist), box)
    first, last = pose.crops[0], pose.crops[-1]
    for b, colour in ((instance.bbox_obj, TRUE), (first, FIRST), (last, LAST)):
        draw_box(image, b, colour)
    draw_label(
        image, f"IoU {box_iou(first, instance.bbox_obj):.2f} -> {box_iou(last, instance.bbox_obj):.2f}", TRUE
    )
    return image


def run(args: argparse.Namespace) -> None:
    predictor = Predictor.load(args.ckpt, passes=args.passes)
    boxes = read_boxes(args.boxes, predictor.obj.obj_id)
    chosen = [i for i in scan_split(args.data, args.split, predictor.obj.obj_id) if i.key in boxes]
    tiles = [tile(predictor, i, boxes[i.key]) for i in chosen[: args.n]]
    if not tiles:
        raise PosenetError(f"no image of {args.data} {args.split} has a box in {args.boxes}")
    _, jpg = cv2.imencode(".jpg", contact_sheet(tiles), [cv2.IMWRITE_JPEG_QUALITY, 90])
    atomic_write_bytes(args.out, jpg.tobytes())
    print(f"wrote {args.out}: {len(tiles)} images, {args.passes} passes")


if __name__ == "__main__":
    run_script(run, parse_args())
