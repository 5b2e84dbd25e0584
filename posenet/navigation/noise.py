"""The measurement noise of a pose network, calibrated on a labelled split: the covariance a filter gives
each frame's pose, from the network's own confidence (posenet.predict.confidence).

Per band of confidence (the calibration images split at its quantiles, `BANDS` bands of equal count):

- the rotation error, the rotation vector of R_pred R_true^T in camera axes (rad), whose covariance the
  filter takes as R_pred's (posenet.navigation.filter.Measurement);
- the translation error t_pred - t_true in camera axes divided by the true depth z: the network sees a
  target's image, so its errors grow with range (lateral ~ z, depth ~ z); at a frame the covariance is
  z_pred^2 times the band's.

Each covariance is robust: a turned pose (the near-symmetric target's 180 deg twins) or a lost box is an
outlier the filter's gate is there to reject, not noise to average in. So the covariance is the trimmed
one (`robust_covariance`): iterated over the errors whose squared Mahalanobis distance lies inside the
chi-square (3 dof) quantile `TRIM_PROB`, then scaled by the variance a Gaussian keeps inside that
ellipsoid (chi2_5(q) / chi2_3(q) mass ratio), so a Gaussian's covariance comes back unchanged. The share
of errors trimmed is kept beside it: the outlier rate a user should expect.

**The persistent part.** A network's error on a frame is not independent of its error on the next: a
sequence of similar views shares most of it (a bias of the view, not of the frame), so no number of
frames averages it away. Along labelled sequences (`with_persistence`), the errors of each sequence,
whitened by their band's covariance, give their autocorrelation against the time between frames, fitted
by rho exp(-dt / tau) (`persistence`): rho is the share of each part's variance that persists, tau
how long it lasts. The filter carries that share as a bias state (posenet.navigation.filter.
MeasurementBias: rho times the split's overall covariance, with time constant tau) and takes the rest,
(1 - rho) times the band's covariance, as each frame's white noise. Without labelled sequences there is
nothing to measure it with: rho = 0, and the filter treats the errors as white (and so grows overconfident
on a long sequence of one view).

A pose under the model's `min_confidence` is no measurement (`measurement` gives None): none was
calibrated on. Written as JSON beside the checkpoint (`noise_path`): posenet predict --filter / --track
and posenet eval read it.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import curve_fit
from scipy.stats import chi2

from posenet.errors import PosenetError
from posenet.navigation.filter import Measurement, MeasurementBias

BANDS = 4  # confidence bands of equal count
TRIM_PROB = 0.997  # errors beyond this chi-square (3 dof) quantile are outliers to the covariance
TRIM_ITERATIONS = 20
MIN_PER_BAND = 20  # fewer calibration images than BANDS x this: one band
MAX_LAG = 20  # frames: the autocorrelation is fitted over lags 1 .. MAX_LAG
PARTS = ("rot", "t")
NOISE_SUFFIX = ".noise.json"
FORMAT = "posenet measurement noise v1"


def noise_path(ckpt: Path) -> Path:
    """Where a checkpoint's calibrated noise lives: beside it, `last.pt` -> `last.noise.json`."""
    return Path(ckpt).with_name(Path(ckpt).stem + NOISE_SUFFIX)


def require_noise(ckpt: Path) -> Path:
    """The checkpoint's calibrated noise file, or one line saying how to make it."""
    path = noise_path(ckpt)
    if not path.is_file():
        raise PosenetError(
            f"{ckpt} has no calibrated measurement noise ({path.name} beside it), which the navigation "
            f"filter needs: run posenet calibrate --data DATASET --ckpt {ckpt}"
        )
    return path


def robust_covariance(x: np.ndarray, prob: float = TRIM_PROB) -> tuple[np.ndarray, float]:
    """The trimmed covariance about zero of errors x (N, 3) and the share of them trimmed: iterate the
    covariance of the errors inside the `prob` chi-square ellipsoid of the one before, scaled by
    P(chi2_3 <= q) / P(chi2_5 <= q) (q the ellipsoid's quantile), the consistency factor of a Gaussian
    truncated there. About zero, not the mean: a network's bias is error the filter must be told of."""
    x = np.asarray(x, np.float64)
    q = float(chi2.ppf(prob, 3))
    factor = prob / float(chi2.cdf(q, 5))
    cov = x.T @ x / len(x)
    inside = np.ones(len(x), bool)
    for _ in range(TRIM_ITERATIONS):
        d2 = np.einsum("ni,ij,nj->n", x, np.linalg.pinv(cov), x)
        now = d2 <= q
        if now.sum() < 4:
            break
        cov = factor * x[now].T @ x[now] / now.sum()
        if np.array_equal(now, inside):
            break
        inside = now
    return 0.5 * (cov + cov.T), float(1.0 - inside.mean())


@dataclass(frozen=True)
class NoiseModel:
    """Per confidence band (lower edges ascending; a confidence falls in the last band whose edge it
    reaches): the rotation error covariance (rad^2) and the translation error covariance per unit depth
    (camera axes), each band's outlier share, and how it was made; over all bands, each part's
    covariance, the share of it that persists along a sequence (`persistent`, per part) and for how long
    (`tau_s`, seconds); `min_confidence`, under which a pose is no measurement."""

    edges: list[float]
    cov_rot: list[list[list[float]]]
    cov_t_rel: list[list[list[float]]]
    outliers: list[float]
    images: int
    source: dict[str, Any]
    overall: dict[str, list[list[float]]]
    persistent: dict[str, float]
    tau_s: dict[str, float]
    min_confidence: float  # a pose under it is no measurement (none was calibrated on)

    def band(self, confidence: float) -> int:
        return max(0, int(np.searchsorted(self.edges, confidence, side="right")) - 1)

    def covariances(self, confidence: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rotation, translation) covariances in camera axes of the white part of a pose's error, the
        pose with `confidence` at `t`: (1 - persistent) times its band's."""
        b = self.band(confidence)
        z = max(float(t[2]), 1e-9)
        white = {part: 1.0 - self.persistent[part] for part in PARTS}
        return white["rot"] * np.asarray(self.cov_rot[b]), white["t"] * z * z * np.asarray(self.cov_t_rel[b])

    def bias(self) -> MeasurementBias | None:
        """The persistent part as the filter's bias model; None where nothing persists."""
        if not any(self.persistent[part] > 0 for part in PARTS):
            return None
        rho, tau = self.persistent, self.tau_s
        cov = {part: rho[part] * np.asarray(self.overall[part]) for part in PARTS}
        return MeasurementBias(cov["rot"], cov["t"], tau["rot"], tau["t"])

    def table(self) -> str:
        """One line per band: its confidence range, the 1-sigma of each error and the outlier share."""
        header = "confidence  rotation 1-sigma x,y,z (deg)  translation 1-sigma x,y,z (% of depth)  outliers"
        lines = [f"{self.images} calibration images; a pose under confidence {self.min_confidence:g} is no "
                 "measurement (none was calibrated on)", header]  # fmt: skip
        for b, lo in enumerate(self.edges):
            hi = self.edges[b + 1] if b + 1 < len(self.edges) else 1.0
            rot = np.degrees(np.sqrt(np.diag(self.cov_rot[b])))
            rel = 100 * np.sqrt(np.diag(self.cov_t_rel[b]))
            lines.append(f"{lo:.2f}-{hi:.2f}   {rot[0]:6.2f} {rot[1]:6.2f} {rot[2]:6.2f}"
                         f"             {rel[0]:6.3f} {rel[1]:6.3f} {rel[2]:6.3f}"
                         f"                         {100 * self.outliers[b]:.1f} %")  # fmt: skip
        rho, tau = self.persistent, self.tau_s
        lines.append(
            f"persistent along a sequence: rotation {100 * rho['rot']:.0f} % for {tau['rot']:.0f} s, "
            f"translation {100 * rho['t']:.0f} % for {tau['t']:.0f} s"
            + ("" if self.source.get("sequences") else " (a split of independent frames: none measured)")
        )
        return "\n".join(lines)

    def to_json(self) -> str:
        return json.dumps({"format": FORMAT, **asdict(self)}, indent=1) + "\n"

    @staticmethod
    def load(path: Path) -> NoiseModel:
        """A calibration file, or one line saying why it cannot be read."""
        try:
            raw = json.loads(Path(path).read_text())
            if raw.get("format") != FORMAT:
                raise ValueError(f"format {raw.get('format')!r}, not {FORMAT!r}")
            model = NoiseModel(**{k: raw[k] for k in NoiseModel.__dataclass_fields__})
            for cov in (*model.cov_rot, *model.cov_t_rel, *model.overall.values()):
                if np.shape(cov) != (3, 3) or not np.all(np.linalg.eigvalsh(np.asarray(cov)) > 0):
                    raise ValueError("a covariance is not a positive-definite 3x3 matrix")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise PosenetError(f"{path} is not a measurement-noise file of posenet calibrate: {exc}") from exc
        return model


@dataclass(frozen=True)
class Errors:
    """Calibration images' poses against the truth: confidences (N,), rotation errors (N, 3: rotation
    vectors of R_pred R_true^T, camera axes, rad) and translation errors per unit of true depth (N, 3)."""

    confidence: np.ndarray
    rot: np.ndarray
    t_rel: np.ndarray

    def part(self, name: str) -> np.ndarray:
        return self.rot if name == "rot" else self.t_rel


def calibrate(errors: Errors, source: dict[str, Any], min_confidence: float = 0.0) -> NoiseModel:
    """A NoiseModel, nothing persistent yet (`with_persistence`), from the errors of calibration images:
    those at or above `min_confidence`, the poses the filter will take, independent views of the
    network's domain (their spread is the model's)."""
    confidence = np.asarray(errors.confidence, np.float64)
    n = len(confidence)
    if n < 4:
        raise PosenetError(f"calibration needs at least 4 posed images, got {n}")
    bands = BANDS if n >= BANDS * MIN_PER_BAND else 1
    edges, covs, outliers = [], {"rot": [], "t": []}, []
    for b, idx in enumerate(confidence_bands(confidence, bands)):
        edges.append(0.0 if b == 0 else float(confidence[idx[0]]))
        shares = []
        for part in PARTS:
            cov, out = robust_covariance(errors.part(part)[idx])
            covs[part].append(cov)
            shares.append(out)
        outliers.append(max(shares))
    overall = {part: robust_covariance(errors.part(part))[0].tolist() for part in PARTS}
    none = {part: 0.0 for part in PARTS}
    return NoiseModel(edges, [c.tolist() for c in covs["rot"]], [c.tolist() for c in covs["t"]], outliers, n,
                      {**source, "sequences": 0}, overall, none, dict(none), min_confidence)  # fmt: skip


def with_persistence(
    model: NoiseModel, errors: Errors, sequences: list[tuple[np.ndarray, np.ndarray]], source: dict[str, Any]
) -> NoiseModel:
    """`model` with the persistent part measured along labelled sequences: `errors` of their frames and
    each sequence's (indices into them, times) in time order. Each error is whitened by its confidence
    band's covariance (the model's), then `persistence` fits how much of it lasts, and how long."""
    persistent, tau = {}, {}
    for part in PARTS:
        bands = model.cov_rot if part == "rot" else model.cov_t_rel
        whitening = np.stack([np.linalg.inv(np.linalg.cholesky(np.asarray(c))) for c in bands])
        band_of = [model.band(c) for c in errors.confidence]
        u = np.einsum("nij,nj->ni", whitening[band_of], errors.part(part))
        persistent[part], tau[part] = persistence([(u[idx], times) for idx, times in sequences])
    return replace(model, persistent=persistent, tau_s=tau,
                   source={**model.source, "sequences": len(sequences), "persistence": source})  # fmt: skip


def confidence_bands(confidence: np.ndarray, bands: int) -> list[np.ndarray]:
    """The images' indices split into `bands` bands of about equal count by confidence, ascending; the
    images of a band that tie the highest confidence of the band before go to that one (many images share
    one confidence, 0 on a dark frame), so that a confidence belongs to one band."""
    order = np.argsort(confidence, kind="stable")
    out: list[np.ndarray] = []
    for idx in np.array_split(order, bands):
        if out:
            tied = confidence[idx] <= confidence[out[-1][-1]]
            out[-1], idx = np.concatenate([out[-1], idx[tied]]), idx[~tied]
        if len(idx):
            out.append(idx)
    return out


def persistence(series: list[tuple[np.ndarray, np.ndarray]], max_lag: int = MAX_LAG) -> tuple[float, float]:
    """(rho, tau): the share of whitened errors' variance that persists along sequences, and for how long
    (s). `series`: per sequence its whitened errors (n, 3) and their times (n,) in order. The mean of
    u_k . u_k+l over pairs of inliers (both inside the TRIM_PROB ellipsoid), divided by the mean of
    |u|^2, is fitted against the pairs' mean time apart by rho exp(-dt / tau), lags 1 .. max_lag (least
    squares, rho in [0, 1])."""
    gate = float(chi2.ppf(TRIM_PROB, 3))
    zero, lags = [], {}
    for u, times in series:
        ok = np.sum(u * u, axis=1) <= gate
        zero.append(np.sum(u[ok] * u[ok], axis=1))
        for lag in range(1, min(max_lag, len(u) - 1) + 1):
            keep = ok[:-lag] & ok[lag:]
            products = np.sum(u[:-lag][keep] * u[lag:][keep], axis=1)
            apart = (times[lag:] - times[:-lag])[keep]
            lags.setdefault(lag, []).append((products, apart))
    c0 = float(np.mean(np.concatenate(zero))) if zero else 0.0
    points = []
    for pairs in lags.values():
        products, apart = (np.concatenate(x) for x in zip(*pairs, strict=True))
        if len(products):
            points.append((float(np.mean(apart)), float(np.mean(products)) / c0))
    if len(points) < 2 or c0 <= 0:
        return 0.0, 0.0
    dt, r = (np.array(x) for x in zip(*points, strict=True))
    if r.max() <= 0:
        return 0.0, 0.0
    (rho, tau), _ = curve_fit(lambda x, rho, tau: rho * np.exp(-x / tau), dt, r,
                              p0=(min(max(r[0], 1e-3), 1.0), dt.max()),
                              bounds=([0.0, dt.min() / 10], [1.0, 1e3 * dt.max()]))  # fmt: skip
    return float(rho), float(tau)


def measurement(R: np.ndarray, t: np.ndarray, confidence: float, noise: NoiseModel) -> Measurement | None:
    """A pose (camera from model, t in metres) with its confidence's calibrated covariance; None under the
    model's min_confidence (the network's own low-confidence flag: a dark frame's guess is no measurement)."""
    if confidence < noise.min_confidence:
        return None
    cov_rot, cov_t = noise.covariances(confidence, t)
    return Measurement(np.asarray(R, np.float64), np.asarray(t, np.float64), cov_rot, cov_t)
