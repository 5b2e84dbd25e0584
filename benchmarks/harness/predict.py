"""predict as `posenet predict` runs it, timed by stage: shared by predict_speed.py and throughput.py."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import cv2
import torch

from posenet.predict.batch import BatchPredictor
from posenet.predict.predictor import STAGES, Predictor
from posenet.predict.sources import resolve_source

SHOWN = [s for s in STAGES if s != "drawing"]  # the stages a benchmark reports (nothing is drawn)


def images_of(folder: Path, n: int) -> list[Path]:
    """The first `n` images of `folder`, as `posenet predict FOLDER` finds them (its one-line error for
    none)."""
    return list(resolve_source(str(folder)).images[:n])


def measure(
    predictor: Predictor, paths: list[Path], camera: Any, batched: BatchPredictor | None
) -> tuple[dict[str, Any], list[Any]]:
    """One mode over `paths` after a warm-up: ms per image by stage, end-to-end images/s, the poses."""
    size = batched.size if batched else 1
    warm = [cv2.imread(str(p)) for p in paths[:size]]
    (batched or one_at_a_time(predictor))(warm, camera)
    sync = torch.cuda.synchronize if predictor.device.type == "cuda" else (lambda: None)
    sync()
    predictor.timings.ms.clear()
    poses: list[Any] = []
    tic = time.perf_counter()
    if batched is None:
        for path in paths:
            t0 = time.perf_counter()
            image = cv2.imread(str(path))
            predictor.timings.add("decode", time.perf_counter() - t0)
            poses.append(predictor(image, camera))
    else:  # the next batch is decoded in the pool while this one runs, as posenet predict --batch does
        chunks = [paths[i : i + size] for i in range(0, len(paths), size)]
        read = lambda chunk: list(batched.pool.map(lambda p: cv2.imread(str(p)), chunk))  # noqa: E731
        with ThreadPoolExecutor(1) as ahead:
            nxt = ahead.submit(read, chunks[0])
            for k in range(len(chunks)):
                images = nxt.result()
                if k + 1 < len(chunks):
                    nxt = ahead.submit(read, chunks[k + 1])
                poses += batched(images, camera)
    sync()
    wall = time.perf_counter() - tic
    if batched is not None:  # decoding alone, in the pool: its own rate
        t0 = time.perf_counter()
        list(batched.pool.map(lambda p: cv2.imread(str(p)), paths))
        seconds = time.perf_counter() - t0
        predictor.timings.ms["decode"] = [1000.0 * seconds / len(paths)] * len(paths)
    ms = predictor.timings.per_image_ms(len(paths))
    rates = {s: round(1000.0 / ms[s], 1) for s in SHOWN if ms.get(s)}
    return {"ms": {s: round(v, 3) for s, v in ms.items()}, "images_per_s": rates,
            "end_to_end": round(len(paths) / wall, 1)}, poses  # fmt: skip


def one_at_a_time(predictor: Predictor) -> Any:
    """predict without --batch: one image after another."""
    return lambda images, camera: [predictor(im, camera) for im in images]
