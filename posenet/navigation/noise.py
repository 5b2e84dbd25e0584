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

Written as JSON beside the checkpoint (`noise_path`): posenet predict --track and posenet eval read it.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from posenet.errors import PosenetError
from posenet.navigation.filter import Measurement

BANDS = 4  # confidence bands of equal count
TRIM_PROB = 0.997  # errors beyond this chi-square (3 dof) quantile are outliers to the covariance
TRIM_ITERATIONS = 20
MIN_PER_BAND = 20  # fewer calibration images than BANDS x this: one band
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
    (camera axes), each band's outlier share, and how it was made."""

    edges: list[float]
    cov_rot: list[list[list[float]]]
    cov_t_rel: list[list[list[float]]]
    outliers: list[float]
    images: int
    source: dict[str, Any]

    def band(self, confidence: float) -> int:
        return max(0, int(np.searchsorted(self.edges, confidence, side="right")) - 1)

    def covariances(self, confidence: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rotation, translation) covariances in camera axes of a pose with `confidence` at `t`."""
        b = self.band(confidence)
        z = max(float(t[2]), 1e-9)
        return np.asarray(self.cov_rot[b]), z * z * np.asarray(self.cov_t_rel[b])

    def table(self) -> str:
        """One line per band: its confidence range, the 1-sigma of each error and the outlier share."""
        lines = ["confidence  rotation 1-sigma x,y,z (deg)  translation 1-sigma x,y,z (% of depth)  outliers"]
        for b, lo in enumerate(self.edges):
            hi = self.edges[b + 1] if b + 1 < len(self.edges) else 1.0
            rot = np.degrees(np.sqrt(np.diag(self.cov_rot[b])))
            rel = 100 * np.sqrt(np.diag(self.cov_t_rel[b]))
            lines.append(f"{lo:.2f}-{hi:.2f}   {rot[0]:6.2f} {rot[1]:6.2f} {rot[2]:6.2f}"
                         f"             {rel[0]:6.3f} {rel[1]:6.3f} {rel[2]:6.3f}"
                         f"                         {100 * self.outliers[b]:.1f} %")  # fmt: skip
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
            model = NoiseModel(
                **{k: raw[k] for k in ("edges", "cov_rot", "cov_t_rel", "outliers", "images", "source")}
            )
            for cov in (*model.cov_rot, *model.cov_t_rel):
                if np.shape(cov) != (3, 3) or not np.all(np.linalg.eigvalsh(np.asarray(cov)) > 0):
                    raise ValueError("a covariance is not a positive-definite 3x3 matrix")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise PosenetError(f"{path} is not a measurement-noise file of posenet calibrate: {exc}") from exc
        return model


def calibrate(
    confidence: np.ndarray,
    rot_error: np.ndarray,
    t_error: np.ndarray,
    depth: np.ndarray,
    source: dict[str, Any],
) -> NoiseModel:
    """A NoiseModel from calibration images: their confidences (N,), rotation errors (N, 3: rotation
    vectors of R_pred R_true^T, rad), translation errors (N, 3: t_pred - t_true, m) and true depths (N,)."""
    confidence = np.asarray(confidence, np.float64)
    n = len(confidence)
    if n < 4:
        raise PosenetError(f"calibration needs at least 4 posed images, got {n}")
    bands = BANDS if n >= BANDS * MIN_PER_BAND else 1
    order = np.argsort(confidence, kind="stable")
    parts = np.array_split(order, bands)
    edges, cov_rot, cov_t, outliers = [], [], [], []
    rel = np.asarray(t_error, np.float64) / np.asarray(depth, np.float64)[:, None]
    for b, idx in enumerate(parts):
        edges.append(0.0 if b == 0 else float(confidence[idx[0]]))
        c_rot, out_rot = robust_covariance(np.asarray(rot_error)[idx])
        c_t, out_t = robust_covariance(rel[idx])
        cov_rot.append(c_rot.tolist())
        cov_t.append(c_t.tolist())
        outliers.append(max(out_rot, out_t))
    return NoiseModel(edges, cov_rot, cov_t, outliers, n, source)


def measurement(R: np.ndarray, t: np.ndarray, confidence: float, noise: NoiseModel) -> Measurement:
    """A pose (camera from model, t in metres) with its confidence's calibrated covariance."""
    cov_rot, cov_t = noise.covariances(confidence, t)
    return Measurement(np.asarray(R, np.float64), np.asarray(t, np.float64), cov_rot, cov_t)
