"""RGB file formats side by side on the same images: bytes per image and what JPEG loses.

Usage: python benchmarks/probes/image_format.py [--n 24] [--seed 0] [--resolution 640x480] [--backend mitsuba]
       [--camera default] [--qualities 85 90 95]

Renders samples 0..N-1 in memory as `scgen render` would (default camera: sensor noise, PSF, drawn
exposure) and encodes each recorded image as `--rgb-format png` writes it and as JPEG at each quality
(the writer's own encoder, scgen.dataset.writer.encode_rgb), plus JPEG at the quality the camera draws per
image (`camera.output.jpeg_quality`: what `--rgb-format jpg` writes). Prints, per format, the bytes per
image (mean and median), what 50,000 images weigh, and the PSNR of the decoded JPEG against the lossless
image over the whole frame and over the target's visible pixels.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import parser, run_script

from scgen import Generator
from scgen.dataset.writer import drawn_jpeg_quality, encode_rgb

FULL_COUNT = 50_000


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def decode(data: bytes) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    return bgr[..., ::-1] if bgr.ndim == 3 else bgr


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--resolution", default="640x480")
    ap.add_argument("--backend", default="mitsuba")
    ap.add_argument("--camera", default="default")
    ap.add_argument("--qualities", type=int, nargs="+", default=[85, 90, 95])
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    resolution = tuple(int(v) for v in args.resolution.split("x"))
    formats = ["png", *(f"jpg q{q}" for q in args.qualities), "jpg as drawn"]
    sizes: dict[str, list[int]] = {f: [] for f in formats}
    frame: dict[str, list[float]] = {f: [] for f in formats[1:]}
    target: dict[str, list[float]] = {f: [] for f in formats[1:]}
    with Generator.load(
        seed=args.seed, resolution=resolution, backend=args.backend, camera=args.camera
    ) as gen:
        for i in range(args.n):
            sample = gen.sample(i)
            rgb, visib = sample.buffers.rgb, sample.annotation.mask_visib
            sizes["png"].append(len(encode_rgb(rgb, "png")))
            qualities = {f"jpg q{q}": q for q in args.qualities} | {
                "jpg as drawn": drawn_jpeg_quality(sample.spec)
            }
            for name, q in qualities.items():
                data = encode_rgb(rgb, "jpg", q)
                back = decode(data)
                sizes[name].append(len(data))
                frame[name].append(psnr(back, rgb))
                if visib.any():
                    target[name].append(psnr(back[visib], rgb[visib]))
    print(f"{args.n} images, seed {args.seed}, {args.resolution}, {args.backend}, camera {args.camera}")
    columns = ("KB mean", "KB median", "GB / 50k", "PSNR frame", "PSNR target")
    print(f"{'format':<14}" + "".join(f"{c:>12}" for c in columns))
    for name in formats:
        kb = np.asarray(sizes[name]) / 1000
        row = [kb.mean(), np.median(kb), kb.mean() * FULL_COUNT / 1e6]
        if name in frame:
            row += [np.median(frame[name]), np.median(target[name])]
        print(f"{name:<14}" + "".join(f"{v:>12.1f}" for v in row))
    print("PSNR: median over images, dB against the lossless image (8-bit)")


if __name__ == "__main__":
    run_script(run, parse_args())
