"""The target's finish per sample: each material class of its parts jittered, sometimes swapped.

Drawn from the sample's own "finish" stream, so no other factor's draws move. For every class of
scgen.scenes.materials (sorted by name, used by the target or not: the draws do not depend on the model), in a
fixed number of draws whatever the outcome: with probability swap_prob the
class becomes another one (uniform), then the base colour, roughness, metallic and crinkle strength are
drawn within scgen.scenes.materials.FINISH_RANGES of the resulting class, scaled by `jitter`. The result maps
each original class to {material, base, roughness, metallic, detail}; nominal mode gives {}, and so does
varied mode for a `nominal_prob` share of the samples (one more draw, after all the others).
Only shading changes: the geometry, and so every label, is the same.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from scgen.scenes.factors import FINISH_GROUPS
from scgen.scenes.materials import FINISH_RANGES, MATERIALS, Material

FINISH_MODES = ("nominal", "varied")


def sample_finish(rng: np.random.Generator, cfg: dict[str, Any]) -> dict[str, dict]:
    """The finish of every material class for one sample ({} in nominal mode)."""
    if cfg["mode"] == "nominal":
        return {}
    names = sorted(MATERIALS)
    s = float(cfg["jitter"])
    out = {}
    for cls in names:
        swap, pick, bright, roughness, metallic, detail = rng.uniform(size=6)
        tint = rng.uniform(-1.0, 1.0, 3)
        others = [n for n in names if n != cls]
        material = others[int(pick * len(others))] if swap < cfg["swap_prob"] else cls
        nominal, r = MATERIALS[material], FINISH_RANGES[material]
        gain = _jitter(1.0, r.brightness, bright, s, log=True)
        base = np.clip(np.asarray(nominal.base) * gain * (1 + s * r.tint * tint), 0.0, 1.0)
        out[cls] = {
            "material": material,
            "base": [float(b) for b in base],
            "roughness": _jitter(nominal.roughness, r.roughness, roughness, s),
            "metallic": _jitter(nominal.metallic, r.metallic, metallic, s),
            "detail": _jitter(1.0, r.detail, detail, s, log=True),
        }
    return {} if rng.uniform() < cfg["nominal_prob"] else out


def _jitter(nominal: float, bounds: tuple[float, float], u: float, s: float, log: bool = False) -> float:
    """The point at fraction u of [lo, hi] (of a log scale with `log`), moved from `nominal` by s of the
    way: s = 0 keeps the nominal value, s = 1 takes the drawn one."""
    lo, hi = bounds
    if log:
        return float(nominal * np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))) ** s)
    return float(nominal + s * (lo + u * (hi - lo) - nominal))


def finish_group(finish: dict[str, dict]) -> str:
    """The metadata group: nominal, varied, or swapped (at least one class became another)."""
    if not finish:
        return FINISH_GROUPS[0]
    return FINISH_GROUPS[2] if any(f["material"] != cls for cls, f in finish.items()) else FINISH_GROUPS[1]


def finished(finish: dict[str, dict], cls: str) -> Material:
    """The material a part of class `cls` is rendered with under a sample's finish."""
    f = finish.get(cls)
    if f is None:
        return MATERIALS[cls]
    return replace(MATERIALS[f["material"]], base=tuple(f["base"]), roughness=f["roughness"],
                   metallic=f["metallic"], crinkle=f["detail"])  # fmt: skip
