"""xyz maps as OpenEXR: X, Y, Z channels (half float by default), ZIP-compressed, metres."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR


def encode_xyz_exr(xyz: np.ndarray, dtype: str = "float16") -> bytes:
    """EXR file bytes holding an H x W x 3 model-coordinate crop as channels X, Y, Z."""
    arr = np.ascontiguousarray(xyz.astype(np.float16 if dtype == "float16" else np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {name: np.ascontiguousarray(arr[..., k]) for k, name in enumerate("XYZ")}
    fd, tmp = tempfile.mkstemp(suffix=".exr")
    os.close(fd)
    try:
        with OpenEXR.File(header, channels) as f:
            f.write(tmp)
        return Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)


def read_xyz_exr(path: str | Path) -> np.ndarray:
    """H x W x 3 float32 model coordinates from an xyz EXR."""
    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        return np.stack([np.asarray(ch[c].pixels, np.float32) for c in "XYZ"], axis=-1)
