"""The labelled objects beside the target in a rendezvous sequence (config `[[objects]]` with
`[sequence]`): each on its own free orbit about the target and its own attitude motion.

Every instance drifts nowhere: its motion relative to the target's centre of mass is HCW's drift-free
ellipse about a point of V-bar (scgen.scenes.motion.orbit.hill_state with x_c = 0),

    x = A cos(nt + a),   y = y_c - 2 A sin(nt + a),   z = B sin(nt + b),

y_c at ± the entry's `separation_m`, A and B up to a quarter of |y_c| (so it never comes nearer the target
than |y_c| / 2), phases uniform: a client and its servicer station-keeping, or debris that shares the
orbit. Its attitude is drawn as the target's is (the sequence's `attitude_probs` and `rate_deg`, its own
inertia). An instance whose ellipse comes within reach of the target, of the chaser's path or of an
instance before it is drawn again (OBJECT_TRIES), the draw that keeps farthest kept if none clears.
Pure numpy, from the sequence's own `objects` stream.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from scgen.scenes.motion.orbit import hcw_state, hill_state
from scgen.scenes.motion.tumble import MassProperties, attitude_track, draw_attitude
from scgen.scenes.rng import choice

OBJECT_TRIES = 32
AMPLITUDE_SHARE = 0.25  # the ellipse's radial and cross-track amplitudes, at most this share of |y_c|


@dataclass(frozen=True)
class Companion:
    """What a sequence needs of one `[[objects]]` entry: its obj_id, its model's radius about the model
    origin (model metres), its mass properties (centre of mass, inertia) and the entry."""

    obj_id: int
    radius: float
    mass: MassProperties
    entry: dict[str, Any]


@dataclass(frozen=True)
class CompanionTrack:
    """One instance's path: obj_id, and its attitude R_LB (T, 3, 3) and centre of mass (LVLH, real metres,
    relative to the target's centre of mass) at each frame time."""

    obj_id: int
    R_lb: np.ndarray
    com: np.ndarray


def companion_tracks(
    rng: np.random.Generator, companions: Sequence[Companion], seq: dict[str, Any], n: float,
    times: np.ndarray, chaser: np.ndarray, scale: float, target_radius: float,
) -> list[CompanionTrack]:  # fmt: skip
    """Every instance of every entry, in entry order, for a sequence of mean motion n at `times`, the chaser
    at `chaser` (T x 3, LVLH, real metres); `scale` turns real metres into model metres (the radii's)."""
    balls = [(np.zeros_like(chaser), target_radius / scale), (chaser, target_radius / scale)]
    out = []
    for companion in companions:
        lo, hi = companion.entry["separation_m"]
        for _ in range(companion.entry["count"]):
            best: tuple[float, np.ndarray] | None = None
            reach = companion.radius / scale
            for _ in range(OBJECT_TRIES):
                y_c = rng.uniform(lo, hi) * (1.0 if rng.uniform() < 0.5 else -1.0)
                radial, cross = rng.uniform(0.0, AMPLITUDE_SHARE * abs(y_c), 2)
                phase, cross_phase = rng.uniform(0.0, 2.0 * math.pi, 2)
                r0, v0 = hill_state(n, 0.0, y_c, radial, cross, phase, cross_phase)
                com = hcw_state(r0, v0, n, times)[0]
                clearance = min(_closest(com, c) - (r + reach) for c, r in balls)
                if best is None or clearance > best[0]:
                    best = (clearance, com)
                if clearance > 0:
                    break
            assert best is not None
            mode = choice(rng, seq["attitude_probs"])
            motion = draw_attitude(mode, rng, companion.mass, tuple(seq["rate_deg"]))
            R_lb = attitude_track(motion, n, times, companion.mass).R_lb
            balls.append((best[1], reach))
            out.append(CompanionTrack(companion.obj_id, R_lb, best[1]))
    return out


def _closest(a: np.ndarray, b: np.ndarray) -> float:
    """The least distance between two paths at the same times (T x 3 each)."""
    return float(np.min(np.linalg.norm(a - b, axis=-1)))
