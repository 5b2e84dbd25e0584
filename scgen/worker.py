"""What one worker does: keep a renderer alive, and turn sample tasks into samples on disk.

Used by every executor (local processes, Ray actors), so a sample is rendered, annotated and
written the same way whatever runs it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from scgen.annotate import annotate
from scgen.dataset import Layout
from scgen.model import load_target
from scgen.render.base import create_backend
from scgen.scenes.spec import SceneSpec
from scgen.writer import WriteOptions, write_sample


@dataclass(frozen=True)
class WorkerSettings:
    """Picklable settings every worker needs to build its renderer and write samples."""

    out: Path
    backend: str
    quality: str
    device: str
    model_path: Path | None
    keep_scale: bool
    write: WriteOptions
    threads: int | None = None  # renderer threads per worker; None = all cores


@dataclass(frozen=True)
class Task:
    index: int
    split: str
    spec: dict


@dataclass(frozen=True)
class Done:
    index: int
    render_s: float
    other_s: float


class SampleWorker:
    """One renderer scene, built once, updated per sample."""

    def __init__(self, settings: WorkerSettings) -> None:
        self.settings = settings
        model = load_target(settings.model_path, keep_scale=settings.keep_scale)
        self.backend = create_backend(
            settings.backend,
            model,
            quality=settings.quality,
            device=settings.device,
            threads=settings.threads,
        )
        self.layout = Layout(settings.out)

    def run(self, task: Task) -> Done:
        spec = SceneSpec.from_dict(task.spec)
        t0 = time.perf_counter()
        buffers = self.backend.render(spec)
        t1 = time.perf_counter()
        write_sample(self.layout, spec, buffers, annotate(spec, buffers), task.split, self.settings.write)
        return Done(task.index, t1 - t0, time.perf_counter() - t1)

    def close(self) -> None:
        self.backend.close()
