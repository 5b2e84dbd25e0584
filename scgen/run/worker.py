"""What one worker does: keep a renderer alive, and turn sample tasks into samples on disk.

Used by every executor (local processes, Ray actors), so a sample is rendered, annotated and
written the same way whatever runs it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from scgen.dataset.layout import Layout
from scgen.dataset.writer import WriteOptions, write_sample
from scgen.generator import Generator
from scgen.scenes.spec import SceneSpec


@dataclass(frozen=True)
class WorkerSettings:
    """Picklable: the job's generator (model, config, renderer settings) and where and how to write."""

    generator: Generator
    out: Path
    write: WriteOptions


@dataclass(frozen=True)
class Task:
    index: int
    split: str
    spec: dict


@dataclass(frozen=True)
class Done:
    index: int
    render_s: float  # render and annotate
    other_s: float  # encode and write


class SampleWorker:
    """One renderer, built on the first task and reused for every later one."""

    def __init__(self, settings: WorkerSettings) -> None:
        self.settings = settings
        self.layout = Layout(settings.out)

    def run(self, task: Task) -> Done:
        spec = SceneSpec.from_dict(task.spec)
        t0 = time.perf_counter()
        sample = self.settings.generator.render(spec)
        t1 = time.perf_counter()
        write_sample(self.layout, spec, sample.buffers, sample.annotation, task.split, self.settings.write,
                     sample.objects)  # fmt: skip
        return Done(task.index, t1 - t0, time.perf_counter() - t1)

    def close(self) -> None:
        self.settings.generator.close()
