"""Shared fixtures: small real datasets rendered with the Mitsuba backend (fast on CPU)."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from shared_dirs import shared_dir

from scgen.io.machine_cache import CACHE_ENV
from scgen.run.runner import RenderJob, run_render
from scgen.scenes.model import TargetModel, load_target

SMALL = (320, 240)
# albumentations asks PyPI for a newer version on import (2 s timeout): tests stay off the network
os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")
# what scgen learns of the machine (the libLLVM that renders, the sky's derived maps) stays in this run
# (not the user's cache) and goes with it
os.environ[CACHE_ENV] = tempfile.mkdtemp(prefix="scgen-test-cache-")
atexit.register(shutil.rmtree, os.environ[CACHE_ENV], ignore_errors=True)
# The modules that take minutes (2026-11-28, 2 cores: the learning test ~9.5 min, the detector's ~3,
# packaging's ~2.5, scale-out's ~2), run first: `make test` spreads whole modules over pytest-xdist
# workers in collection order, and one started last would run alone at the end.
LONGEST_FIRST = (
    "test_posenet_learning.py",
    "test_posenet_detector.py",
    "test_packaging.py",
    "test_scale_out.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """LONGEST_FIRST's modules first, in its order; the rest as collected."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def render_dataset(out: Path, n: int, seed: int = 0, **kwargs) -> Path:
    """Render n samples at 320x240 with Mitsuba, the way `scgen render` does."""
    job = RenderJob(out=out, n=n, seed=seed, backend="mitsuba", quality="draft", resolution=SMALL, **kwargs)
    run_render(job, progress=False)
    return out


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """12 samples of seed 0: shared, read-only for the tests that use it."""
    return shared_dir(tmp_path_factory, "small", lambda out: render_dataset(out, n=12))


@pytest.fixture(scope="session")
def dataset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The posenet tests' dataset (posenet_helpers.posenet_dataset: 24 images of seed 0), read-only; a
    module that needs another one defines its own `dataset_dir`."""
    from posenet_helpers import posenet_dataset

    return posenet_dataset(tmp_path_factory)


@pytest.fixture(scope="session")
def pose_ckpt(dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-step GDR-Net checkpoint on `dataset_dir` (posenet_helpers.tiny_pose_checkpoint), read-only."""
    from posenet_helpers import tiny_pose_checkpoint

    return tiny_pose_checkpoint(dataset_dir, tmp_path_factory)


@pytest.fixture(scope="session")
def spacecraft() -> TargetModel:
    """The bundled spacecraft (read-only)."""
    return load_target()


# sequence_dataset's [sequence] table: a 20 m spacecraft, so that at 64x48 every frame shows the target
SEQUENCE = {"frames": 4, "dt_s": 3.0, "spacecraft_diameter_m": 20.0}


@pytest.fixture(scope="session")
def sequence_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """3 rendezvous sequences of SEQUENCE's 4 frames (seed 0, Mitsuba, 64x48, draft): 2 in train, 1 in test.
    Shared, read-only for the tests that use it."""

    def build(out: Path) -> None:
        job = RenderJob(out=out, n=3, seed=0, backend="mitsuba", quality="draft", resolution=(64, 48),
                        overrides={"sequence": SEQUENCE}, split_by="random",
                        ratios=(0.67, 0.0, 0.33))  # fmt: skip
        run_render(job, progress=False)

    return shared_dir(tmp_path_factory, "sequences", build)
