"""The one conversion of whatever image predict is given (a file the CLI read, an array a Python caller
passes) into what the network's crop reads: H x W x 3 uint8 in OpenCV's BGR order."""

from __future__ import annotations

import numpy as np

from posenet.errors import PosenetError

TWELVE_BIT_MAX = 4095  # machine-vision and space cameras' common depth, stored in 16-bit files


def to_bgr8(image: np.ndarray) -> tuple[np.ndarray, str | None]:
    """`image` as H x W x 3 uint8 BGR, and a note where how it was read is a guess (else None).

    Grey (H x W, H x W x 1) is repeated into 3 channels and a 4th channel (alpha) dropped. uint8 is kept;
    uint16 is divided by 257 (65535 -> 255), except where no value passes 4095: that is 12-bit data in a
    16-bit file, which read as 16-bit would be near black (1/16 of its range), so it is scaled by 255 / 4095
    and noted; float must lie in [0, 1] and is scaled by 255. Anything else is one PosenetError."""
    image = np.asarray(image)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[2] not in (1, 3, 4) or image.shape[0] == 0 or image.shape[1] == 0:
        raise PosenetError(f"an image is H x W (grey) or H x W x 1, 3 or 4 (BGR[A]), got {image.shape}")
    image = image[..., :3] if image.shape[2] == 4 else image
    note = None
    if image.dtype == np.uint16:
        top = int(image.max())
        full = TWELVE_BIT_MAX if top <= TWELVE_BIT_MAX else np.iinfo(np.uint16).max
        if full == TWELVE_BIT_MAX:
            note = f"a 16-bit image whose values reach only {top}: read as 12-bit data (4095 is white)"
        image = np.round(image.astype(np.float32) * (255.0 / full)).astype(np.uint8)
    elif image.dtype.kind == "f":
        low, high = float(np.min(image)), float(np.max(image))
        if not (low >= 0.0 and high <= 1.0):  # NaN fails both
            raise PosenetError(f"a float image must lie in [0, 1], got values from {low:g} to {high:g}")
        image = np.round(image * 255.0).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise PosenetError(f"an image is uint8, uint16 or float in [0, 1], got {image.dtype}")
    if image.shape[2] == 1:
        image = np.repeat(image, 3, axis=2)
    return np.ascontiguousarray(image), note
