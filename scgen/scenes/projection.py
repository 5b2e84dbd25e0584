"""Which pixels a posed mesh can cover: the box the labels cast rays over (`scgen annotate`, and the
labelled objects beside the target in a render)."""

from __future__ import annotations

import numpy as np

from scgen.scenes.geometry import project
from scgen.scenes.spec import CameraSpec

Box = tuple[int, int, int, int]  # x, y, w, h in pixels


def projection_box(vertices: np.ndarray, R: np.ndarray, t: np.ndarray, camera: CameraSpec) -> Box | None:
    """The pixels whose centres the posed mesh can cover: its projected vertices' extent (one pixel spare),
    within the image grown by one image size on each side (bop_toolkit's canvas for the full projection);
    that whole canvas when part of the mesh is behind the camera. None when empty.
    """
    W, H = camera.width, camera.height
    lo, hi = np.array([-W, -H]), np.array([2 * W - 1, 2 * H - 1])
    X = vertices @ R.T + t
    if (X[:, 2] > 0).all():
        uv = project(camera.K_mat, X)
        lo = np.maximum(lo, np.floor(uv.min(axis=0)).astype(int) - 1)
        hi = np.minimum(hi, np.ceil(uv.max(axis=0)).astype(int) + 1)
    if (hi < lo).any():
        return None
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
