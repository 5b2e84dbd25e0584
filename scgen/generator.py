"""The library entry point: the scenes and samples `scgen render` makes, one at a time, in memory.

    from scgen import Generator
    with Generator.load(seed=0, resolution=(320, 240), backend="mitsuba") as gen:
        sample = gen.sample(7)  # sample 7 of seed 0: SceneSpec, renderer Buffers, Annotation

The render workers, `scgen preview`, the benchmarks and the tests all go through this class, so a
sample is sampled, rendered and annotated the same way everywhere.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scgen.annotate import Annotation, annotate, annotate_objects
from scgen.io.bop import TARGET_OBJ_ID
from scgen.io.buffers import Buffers
from scgen.scenes import SceneSpec, TargetShape, load_config, sample_scene
from scgen.scenes.config.objects import object_models
from scgen.scenes.model import TargetModel, load_target
from scgen.scenes.motion.companions import Companion
from scgen.scenes.motion.sequence import is_sequence, sample_sequence
from scgen.scenes.motion.tumble import MassProperties, mass_properties
from scgen.scenes.sampler import ObjectDraw


@dataclass(frozen=True)
class Sample:
    """One sample before it is written: what was asked for, what the renderer saw, the labels (the
    target's, then each of spec.objects')."""

    spec: SceneSpec
    buffers: Buffers
    annotation: Annotation
    objects: tuple[Annotation, ...] = ()

    @property
    def annotations(self) -> tuple[Annotation, ...]:
        """Every labelled instance's labels, in scene_gt order."""
        return (self.annotation, *self.objects)


class Generator:
    """Scenes of one target under one sampling config and seed; renders them on first `sample`.

    The renderer (`backend`: blender or mitsuba) is built once, on first use, and kept until `close`.
    """

    def __init__(
        self, model: TargetModel, cfg: dict[str, Any], seed: int = 0, backend: str = "blender",
        quality: str = "default", device: str = "auto", threads: int | None = None,
    ) -> None:  # fmt: skip
        self.model, self.cfg, self.seed = model, cfg, seed
        self.shape = TargetShape.from_mesh(model.mesh, model.diameter)
        self.render_settings = {"backend": backend, "quality": quality, "device": device, "threads": threads}
        self.model_source: tuple[Path | None, bool] | None = None  # (file, keep_scale) when loaded from one
        self._backend: Any = None
        self._mass: MassProperties | None = None  # the target's inertia, for a sequence's attitude
        self._sequence: tuple[int, list[SceneSpec]] | None = None

    @classmethod
    def load(
        cls, model: str | Path | None = None, config: str | Path | None = None, seed: int = 0,
        resolution: tuple[int, int] | None = None, keep_scale: bool = False,
        overrides: dict[str, Any] | None = None, camera: str | None = None, **render: Any,
    ) -> Generator:  # fmt: skip
        """From files, as `scgen render` reads them: a mesh (None: the bundled spacecraft) and a config.

        `camera` names a camera preset (scgen.scenes.config.camera); `render` takes the renderer
        settings: backend, quality, device, threads.
        """
        cfg = load_config(config, overrides, resolution, camera)
        generator = cls(load_target(model, keep_scale=keep_scale), cfg, seed, **render)
        generator.model_source = (None if model is None else Path(model), keep_scale)
        return generator

    def scene(self, index: int) -> SceneSpec:
        """The SceneSpec of sample `index`: pure and cheap, no renderer involved. With a `[sequence]`
        table, sample index s * frames + k is frame k of sequence s."""
        if is_sequence(self.cfg):
            sequence, frame = divmod(index, self.cfg["sequence"]["frames"])
            return self.sequence(sequence)[frame]
        return sample_scene(self.seed, index, self.cfg, self.shape, self.object_draws)

    @functools.cached_property
    def _object_keys(self) -> list[str]:
        """The models by obj_id - 1: the target's, then each `[[objects]]` model not named before
        (scgen.scenes.config.objects.object_models)."""
        source = self.model_source[0] if self.model_source else None
        return object_models(self.cfg, str(source) if source else self.model.name)

    @functools.cached_property
    def models(self) -> dict[int, TargetModel]:
        """The dataset's objects by BOP obj_id: the target, then each `[[objects]]` model (`_object_keys`),
        loaded with the target's keep_scale."""
        keep_scale = self.model_source[1] if self.model_source else False
        others = {k: load_target(m, keep_scale=keep_scale) for k, m in enumerate(self._object_keys[1:], 2)}
        return {TARGET_OBJ_ID: self.model, **others}

    @functools.cached_property
    def object_draws(self) -> tuple[ObjectDraw, ...]:
        """What the sampler places of each `[[objects]]` entry (none without the table)."""
        entries = self.cfg.get("objects", ())
        ids = [self._object_keys.index(e["model"]) + 1 for e in entries]
        shapes = {k: TargetShape.from_mesh(self.models[k].mesh, self.models[k].diameter) for k in set(ids)}
        return tuple(ObjectDraw(k, shapes[k], e) for k, e in zip(ids, entries, strict=True))

    @functools.cached_property
    def companions(self) -> tuple[Companion, ...]:
        """What a sequence moves of each `[[objects]]` entry (none without the table)."""
        ids = {d.obj_id for d in self.object_draws}
        masses = {k: mass_properties([mesh for _, mesh in self.models[k].parts]) for k in ids}
        return tuple(
            Companion(d.obj_id, d.shape.radius, masses[d.obj_id], d.entry) for d in self.object_draws
        )

    @property
    def frames(self) -> int:
        """Samples per sequence: the `[sequence]` table's frames, 1 without one."""
        return self.cfg["sequence"]["frames"] if is_sequence(self.cfg) else 1

    def sequence(self, sequence: int) -> list[SceneSpec]:
        """The SceneSpecs of every frame of sequence `sequence` (the last one asked is kept: a whole
        sequence is computed at once, the tumble integrated over its span)."""
        if self._sequence is None or self._sequence[0] != sequence:
            if self._mass is None:
                self._mass = mass_properties([mesh for _, mesh in self.model.parts])
            specs = sample_sequence(self.seed, sequence, self.cfg, self.shape, self._mass, self.companions)
            self._sequence = (sequence, specs)
        return self._sequence[1]

    def render(self, spec: SceneSpec) -> Sample:
        """Render and annotate one SceneSpec."""
        if self._backend is None:
            from scgen.render.base import create_backend

            r = self.render_settings
            self._backend = create_backend(r["backend"], self.model, r["quality"], r["device"], r["threads"],
                                           self.models)  # fmt: skip
        buffers = self._backend.render(spec)
        return Sample(spec, buffers, annotate(spec, buffers), annotate_objects(spec, buffers))

    def sample(self, index: int) -> Sample:
        """Sample `index` of the seed, rendered and annotated exactly as `scgen render` writes it."""
        return self.render(self.scene(index))

    def close(self) -> None:
        """Release the renderer (a later `sample` builds a new one)."""
        if self._backend is not None:
            self._backend.close()
            self._backend = None

    def __enter__(self) -> Generator:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled without its renderer, and as its model file when it has one (not the meshes): a
        render worker receives a few hundred bytes and loads the model itself."""
        model = self.model_source or self.model
        return _rebuild, (model, self.cfg, self.seed, self.render_settings)


def _rebuild(model: TargetModel | tuple[Path | None, bool], cfg: dict[str, Any], seed: int,
             render_settings: dict[str, Any]) -> Generator:  # fmt: skip
    source = model if isinstance(model, tuple) else None
    generator = Generator(load_target(*source) if source else model, cfg, seed, **render_settings)
    generator.model_source = source
    return generator
