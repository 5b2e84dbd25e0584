"""The scene factors of the paper's robustness table: their groups, thresholds, the viewpoint cells
(an icosahedron's 20 faces) and the combination key.

One home for the vocabulary the sampler draws from, the annotator measures, the split planner keys
on, `scgen stats` counts and `scgen preview` prints.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from scgen.scenes.spec import SceneSpec

ILLUMINATION_LEVELS = ("weak", "normal", "strong")
SHADOW_LABELS = ("no", "yes")
OCCLUSION_GROUPS = ("none", "slight", "moderate", "heavy")
BACKGROUND_KINDS = ("clean", "complex", "earth", "cluttered")
DISTANCE_GROUPS = ("near", "middle", "far")
NOISE_GROUPS = ("none", "low", "medium", "high")  # sensor noise by mid-grey SNR; none: no sensor model
FLARE_LABELS = ("no", "yes")
FINISH_GROUPS = ("nominal", "varied", "swapped")  # the target's finish (scgen.scenes.finish)
FACTOR_GROUPS: dict[str, tuple[str, ...]] = {
    "illumination": ILLUMINATION_LEVELS,
    "shadow": SHADOW_LABELS,
    "occlusion": OCCLUSION_GROUPS,
    "background": BACKGROUND_KINDS,
    "distance": DISTANCE_GROUPS,
    "noise": NOISE_GROUPS,
    "flare": FLARE_LABELS,
    "finish": FINISH_GROUPS,
}

SHADOW_THRESHOLD = 0.05  # shadow label "yes" when >= 5 % of the lit, visible target is in cast shadow
OCCLUSION_LIMITS = (("none", 0.0), ("slight", 0.2), ("moderate", 0.4))  # r_occ upper bounds; above: heavy
NOISE_SNR_LIMITS = (("low", 30.0), ("medium", 15.0))  # mid-grey SNR lower bounds; below: high


def shadow_label(shadow_fraction: float) -> str:
    return SHADOW_LABELS[int(shadow_fraction >= SHADOW_THRESHOLD)]


def occlusion_group(r_occ: float) -> str:
    """The paper's groups: none (r_occ = 0), slight (<= 0.2), moderate (<= 0.4), heavy (> 0.4)."""
    for name, limit in OCCLUSION_LIMITS:
        if r_occ <= limit:
            return name
    return OCCLUSION_GROUPS[-1]


def noise_group(mid_grey_snr: float | None) -> str:
    """none (no sensor model), low (mid-grey SNR >= 30), medium (>= 15), high (< 15)."""
    if mid_grey_snr is None:
        return NOISE_GROUPS[0]
    for name, limit in NOISE_SNR_LIMITS:
        if mid_grey_snr >= limit:
            return name
    return NOISE_GROUPS[-1]


def distance_groups(
    distances: np.ndarray, lo: float | None = None, hi: float | None = None
) -> tuple[list[str], list[float]]:
    """near / middle / far by thirds of [lo, hi] of the camera-target distance |t| (m).

    lo/hi default to the range of `distances` (scgen stats: over a split); `scgen preview` passes the
    config's range. Returns the labels and the edges [lo, 1/3, 2/3, hi].
    """
    if len(distances) == 0:
        return [], []
    lo = float(distances.min()) if lo is None else lo
    hi = float(distances.max()) if hi is None else hi
    edges = [lo, lo + (hi - lo) / 3, lo + 2 * (hi - lo) / 3, hi]
    idx = np.clip(np.searchsorted(edges[1:3], distances, side="right"), 0, 2)
    return [DISTANCE_GROUPS[i] for i in idx], edges


def occluder_config(spec: SceneSpec) -> str:
    """The occluder part of the combination key: requested group and the occluders' shapes."""
    shapes = "+".join(sorted(p.shape for p in spec.occluders)) or "-"
    return f"{spec.requested_occlusion}:{shapes}"


def combination_key(cell: int, illumination: str, background: str, occluder_config: str) -> str:
    """The factor-combination key: viewpoint cell, illumination level, background, occluder config."""
    return f"v{cell:02d}|{illumination}|{background}|{occluder_config}"


def spec_key(spec: SceneSpec) -> str:
    """The factor-combination key of a sample, from its SceneSpec."""
    cell = viewpoint_cell(spec.target.R_mat, spec.target.t_vec)
    return combination_key(cell, spec.sun.level, spec.background.kind, occluder_config(spec))


def viewpoint_cells() -> np.ndarray:
    """The 20 face centres of a regular icosahedron: the documented viewpoint partition of S^2."""
    p = (1 + 5**0.5) / 2
    verts = np.array(
        [
            [-1, p, 0],
            [1, p, 0],
            [-1, -p, 0],
            [1, -p, 0],
            [0, -1, p],
            [0, 1, p],
            [0, -1, -p],
            [0, 1, -p],
            [p, 0, -1],
            [p, 0, 1],
            [-p, 0, -1],
            [-p, 0, 1],
        ],
        float,
    )
    verts /= np.linalg.norm(verts, axis=1, keepdims=True)
    faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ]
    centres = verts[np.array(faces)].mean(axis=1)
    return centres / np.linalg.norm(centres, axis=1, keepdims=True)


_CELLS = viewpoint_cells()


def view_direction(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Unit direction from the model towards the camera, in the model frame: -R^T t / |t|."""
    view = -np.asarray(R).T @ np.asarray(t)
    return view / np.linalg.norm(view)


def viewpoint_cell(R: np.ndarray, t: np.ndarray) -> int:
    """Index of the icosahedron face containing the camera's direction seen from the model frame."""
    return int(np.argmax(_CELLS @ view_direction(R, t)))
