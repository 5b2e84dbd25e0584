"""Draw docs/camera_presets.jpg: one scene through the ideal, default and speedplus cameras, and the
default camera once more with the sun in view (ghosts, veiling glare and bloom over the target).

    python benchmarks/figures/camera_figure.py [--backend blender] [--seed 3] [--index 0]
        [--out docs/camera_presets.jpg]

The scene (pose, distance, sun, background, props) is sample INDEX of SEED under the default camera;
each panel keeps it and swaps only the camera (intrinsics, lens, and that camera's own draws).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import ROOT, parser, run_script

from scgen import Generator
from scgen.scenes import load_config
from scgen.scenes.config.camera import CameraSettings
from scgen.scenes.imaging import sample_imaging
from scgen.scenes.rng import factor_rng
from scgen.scenes.spec import CameraSpec, SunSpec

PANEL_WIDTH = 480


def _as_camera(spec, preset: str, width: int):
    """The spec seen by another preset's camera at `width` pixels (its own per-image draws)."""
    cfg = load_config(camera=preset)
    height = round(width * cfg["camera"]["height"] / cfg["camera"]["width"])
    cfg = load_config(camera=preset, resolution=(width, height))
    rng = factor_rng(spec.seed, spec.index, "camera")
    camera = CameraSpec.from_config(cfg["camera"])
    return replace(spec, camera=camera, imaging=sample_imaging(rng, CameraSettings.from_table(cfg["camera"])))


def _sun_in_view(spec):
    """The same scene lit from behind the target, the sun just beside it in the frame."""
    t = np.asarray(spec.target.t)
    K = spec.camera.K_mat
    u, v, _ = K @ (t / t[2])
    offset = 0.28 * spec.camera.width * np.sign(spec.camera.width / 2 - u or 1.0)
    ray = np.linalg.solve(K, [u + offset, v - 0.15 * spec.camera.height, 1.0])
    direction = tuple(float(x) for x in ray / np.linalg.norm(ray))
    return replace(spec, sun=SunSpec(direction, spec.sun.level, spec.sun.irradiance))


def _central(spec) -> bool:
    """The target's centre within the middle fifth of the frame, no occluder, in the nearer half."""
    u, v, _ = spec.camera.K_mat @ (np.asarray(spec.target.t) / spec.target.t[2])
    near = abs(u / spec.camera.width - 0.5) < 0.1 and abs(v / spec.camera.height - 0.5) < 0.1
    return near and not spec.occluders and spec.background.kind in ("earth", "complex")


def _panel(image: np.ndarray, label: str) -> np.ndarray:
    bgr = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image[..., ::-1]
    bgr = cv2.resize(bgr, (PANEL_WIDTH, round(PANEL_WIDTH * bgr.shape[0] / bgr.shape[1])),
                     interpolation=cv2.INTER_AREA)  # fmt: skip
    bgr = cv2.copyMakeBorder(bgr, 0, 360 - bgr.shape[0], 0, 0, cv2.BORDER_CONSTANT, value=(40, 40, 40))
    cv2.putText(bgr, label, (8, 352), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return bgr


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--backend", default="blender", help="[blender]")
    ap.add_argument("--seed", type=int, default=3, help="[3]")
    ap.add_argument(
        "--index", type=int, default=None, help="Default: the first sample with the target central."
    )
    ap.add_argument(
        "--out", type=Path, default=ROOT / "docs" / "camera_presets.jpg", help="[docs/camera_presets.jpg]"
    )
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    index, out = args.index, args.out
    with Generator.load(seed=args.seed, backend=args.backend, camera="ideal") as gen:
        index = next(i for i in range(1000) if _central(gen.scene(i))) if index is None else index
        base = gen.scene(index)
        views = [
            ("ideal", _as_camera(base, "ideal", 640)),
            ("default", _as_camera(base, "default", 640)),
            ("speedplus (mono, K + lens, 640x400)", _as_camera(base, "speedplus", 640)),
            ("default, sun in view", _sun_in_view(_as_camera(base, "default", 640))),
        ]
        panels = []
        for label, spec in views:
            sample = gen.render(spec)
            record = sample.buffers.camera
            note = f"{label}: EV {record.exposure_ev:+.2f}" + (", flare" if record.flare else "")
            panels.append(_panel(sample.buffers.rgb, note))
    grid = np.vstack([np.hstack(panels[:2]), np.hstack(panels[2:])])
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), grid, [cv2.IMWRITE_JPEG_QUALITY, 92])
    print(f"wrote {out}")


if __name__ == "__main__":
    run_script(run, parse_args())
