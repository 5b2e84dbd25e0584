"""scgen's machine cache: arrays made once are read back as the same bits, under a key of what made them,
and a cache that cannot be used costs the making, never a wrong array or an error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scgen.io.machine_cache import ARRAYS_KEPT, CACHE_ENV, cached_arrays
from scgen.render.sky.moon_surface import _make_moon_maps, moon_maps


class Maker:
    """make() for cached_arrays that counts its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self) -> tuple[np.ndarray, ...]:
        self.calls += 1
        rng = np.random.default_rng(3)
        return rng.normal(size=(5, 7)).astype(np.float32), rng.integers(0, 255, (4, 4, 4), np.uint8)


def _same(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> bool:
    pairs = zip(a, b, strict=True) if len(a) == len(b) else ()
    return len(a) == len(b) and all(x.dtype == y.dtype and np.array_equal(x, y) for x, y in pairs)


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_arrays_are_made_once_and_read_back_as_the_same_bits(cache: Path, tmp_path: Path):
    code = tmp_path / "maker.py"
    code.write_text("version 1")
    make = Maker()
    first = cached_arrays("thing", [code], [], make)
    again = cached_arrays("thing", [code], [], make)
    assert make.calls == 1 and _same(first, again) and _same(first, Maker()())
    assert len(list(cache.glob("thing-*.npz"))) == 1


def test_a_changed_input_makes_a_new_entry_and_old_ones_go(cache: Path, tmp_path: Path):
    code, data = tmp_path / "maker.py", tmp_path / "map.bin"
    data.write_bytes(b"1")
    make = Maker()
    for k in range(ARRAYS_KEPT + 2):  # each version of the code is a new entry
        code.write_text(f"version {k}")
        cached_arrays("thing", [code], [data], make)
    assert make.calls == ARRAYS_KEPT + 2
    data.write_bytes(b"22")  # a data file read by the maker: its size and time are in the key
    cached_arrays("thing", [code], [data], make)
    assert make.calls == ARRAYS_KEPT + 3
    assert len(list(cache.glob("thing-*.npz"))) == ARRAYS_KEPT


def test_a_damaged_or_unwritable_cache_costs_the_making_only(
    cache: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    code = tmp_path / "maker.py"
    code.write_text("v")
    make = Maker()
    cached_arrays("thing", [code], [], make)
    (entry,) = cache.glob("thing-*.npz")
    entry.write_bytes(entry.read_bytes()[:100])  # a truncated file (a disk error): made again, rewritten
    assert _same(cached_arrays("thing", [code], [], make), Maker()()) and make.calls == 2
    assert _same(cached_arrays("thing", [code], [], make), Maker()()) and make.calls == 2
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the folder would go")
    monkeypatch.setenv(CACHE_ENV, str(blocked))
    other = Maker()
    for _ in range(2):
        assert _same(cached_arrays("thing", [code], [], other), Maker()())
    assert other.calls == 2 and blocked.read_text() == "a file where the folder would go"


def test_the_moon_maps_from_the_cache_are_the_made_ones():
    """The real user: the Moon's maps (tests/conftest.py points the cache at this run's own folder)."""
    moon_maps.cache_clear()
    kept = moon_maps()
    moon_maps.cache_clear()
    assert _same(moon_maps(), kept) and _same(kept, _make_moon_maps())
