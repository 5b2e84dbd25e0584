"""The navigation filter's settings, torch- and scipy-free: the command lines show their defaults in
--help without loading the filter."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NavConfig:
    """The filter's tunable settings (docs/navigation.md); lengths in diameters of the target so that one
    default fits any model scale."""

    accel_noise: float = 2e-3  # sqrt of the unmodelled acceleration's PSD, diameters / s^1.5
    angular_accel_noise: float = 2e-4  # sqrt of the unmodelled angular acceleration's PSD, rad / s^1.5
    velocity_prior: float = 0.05  # 1-sigma of the velocity at the start, diameters / s
    rate_prior_deg: float = 2.0  # 1-sigma of the angular velocity at the start, deg / s
    gate_prob: float = 0.997  # chi-square gate on each part's innovation (3 dof)
    reinit_after: int = 5  # rejections of a part in a row that restart it (from two agreeing measurements)
