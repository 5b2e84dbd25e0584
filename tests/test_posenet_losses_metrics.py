"""Loss terms and pose metrics on hand-made tensors with known answers."""

from __future__ import annotations

import math

import pytest
import torch
from scipy.spatial import cKDTree

from posenet.config import LossConfig
from posenet.evaluation.metrics import (
    ESA_THETA_Q_DEG,
    TURNED_DEG,
    add_error,
    adds_error,
    esa_score,
    rotation_error_deg,
    sample_errors,
    summarise,
)
from posenet.geometry import ego_to_allo, mask_probability, mat_to_rot6d, site_encode
from posenet.training.losses import (
    PmObject,
    coord_loss,
    mask_loss,
    pm_loss,
    pose_losses,
    region_loss,
)


def rot_z(deg: float) -> torch.Tensor:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


def perfect_batch(b: int = 2, r: int = 8, regions: int = 4) -> tuple[dict, dict]:
    """A batch of targets and the network output that reproduces them exactly."""
    g = torch.Generator().manual_seed(0)
    visible = (torch.rand(b, 1, r, r, generator=g) > 0.5).float()
    labels = torch.randint(1, regions + 1, (b, r, r), generator=g) * visible[:, 0].long()
    R = torch.stack([rot_z(30.0), rot_z(-50.0)]).float()
    t = torch.tensor([[0.1, -0.05, 1.0], [-0.2, 0.1, 2.0]])
    K = torch.tensor([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]]).expand(b, 3, 3)
    roi = {
        "K": K,
        "crop_center": torch.tensor([[200.0, 90.0], [60.0, 150.0]]),
        "box_wh": torch.full((b, 2), 40.0),
    }
    roi["resize_ratio"] = torch.full((b,), r / 60.0)
    site = site_encode(t, K, roi["crop_center"], roi["box_wh"], roi["resize_ratio"])
    xyz = torch.rand(b, 3, r, r, generator=g) * visible
    batch = {
        **roi,
        "roi_xyz": xyz,
        "roi_mask_visib": visible,
        "roi_region": labels,
        "R": R,
        "t": t,
        "site": site,
    }
    out = {
        "xyz": xyz.clone(),
        "mask": (visible * 2 - 1) * 50,
        "region": torch.nn.functional.one_hot(labels, regions + 1).permute(0, 3, 1, 2).float() * 50,
        "rot6d": mat_to_rot6d(ego_to_allo(R, t)),
        "site": site.clone(),
    }
    return batch, out


def test_perfect_prediction_has_zero_loss() -> None:
    batch, out = perfect_batch()
    pts = torch.rand(100, 3) - 0.5
    total, terms = pose_losses(out, batch, PmObject(pts, torch.eye(4)[None]), LossConfig())
    assert set(terms) == {"coord", "mask", "region", "pm", "cent", "z"}
    # Each term is 0 in exact arithmetic. coord, cent and z subtract a clone: exactly 0. The mask (BCE) and
    # region (cross-entropy) logits are +-50: softplus(-50) = e^-50 per pixel, and log(1 + regions e^-50),
    # plus the rounding of the 50s that cancel (2 u x 50). pm: R goes to 6D and back in float32 (allocentric
    # and back, ~2 x 6 u an entry, Gram-Schmidt ~10 u: under 32 u), so a coordinate of R p with |p_j| <= 1/2
    # moves by at most 3 x 32 u / 2 = 48 u, and pm is 3 x its mean: 144 u.
    u = 2**-24
    bounds = {"coord": 0.0, "cent": 0.0, "z": 0.0, "pm": 144 * u}
    bounds |= {"mask": math.exp(-50) + 100 * u, "region": 4 * math.exp(-50) + 100 * u}
    for name, value in terms.items():
        assert float(value) <= bounds[name], name
    cfg = LossConfig()
    assert float(total) <= sum(getattr(cfg, name) * b for name, b in bounds.items()) * (1 + 8 * u)


def test_total_is_the_weighted_sum_with_the_paper_weights() -> None:
    batch, out = perfect_batch()
    out = {k: v + 0.1 for k, v in out.items()}
    cfg = LossConfig()
    assert (cfg.coord, cfg.mask, cfg.region, cfg.pm, cfg.cent, cfg.z) == (1.0, 1.0, 1.1, 1.0, 1.0, 1.0)
    total, terms = pose_losses(out, batch, PmObject(torch.rand(50, 3), torch.eye(4)[None]), cfg)
    expected = sum(getattr(cfg, k) * v for k, v in terms.items())
    assert torch.isclose(total, expected, rtol=6 * 2**-24, atol=0)  # float32 sums of 6 terms: 6 u at most
    assert all(float(v) > 0 for k, v in terms.items() if k != "region")


def test_coord_loss_counts_visible_pixels_only() -> None:
    target = torch.zeros(1, 3, 2, 2)
    pred = torch.zeros(1, 3, 2, 2)
    pred[0, :, 0, 0] = 0.3  # visible: error 3 x 0.3
    pred[0, :, 1, 1] = 9.0  # not visible: ignored
    visible = torch.tensor([[[[1.0, 1.0], [0.0, 0.0]]]])
    # float32: 0.3 rounds by u, the sum of three by 2 u more, the halving is exact: 8 u holds it
    assert math.isclose(float(coord_loss(pred, target, visible)), 0.9 / 2, rel_tol=8 * 2**-24)


def test_mask_loss_kinds() -> None:
    target = torch.tensor([[[[1.0, 0.0]]]])
    logits = torch.tensor([[[[0.0, 0.0]]]])
    u = 2**-24  # float32: softplus(0) = log 2 to a few u, the mean of two exact; small integers are exact
    assert math.isclose(float(mask_loss(logits, target, "bce")), math.log(2), rel_tol=8 * u)
    raw = torch.tensor([[[[2.0, -1.0]]]])  # GDR-Net's L1 takes the raw channel, not its sigmoid
    assert float(mask_loss(raw, target, "l1")) == (1.0 + 1.0) / 2
    assert mask_probability(raw, "l1").tolist() == [[[[1.0, 0.0]]]]
    sigmoid = [1 / (1 + math.exp(-2.0)), 1 / (1 + math.exp(1.0))]
    # float32 sigmoid: exp to an ulp or two (its error shrinks by e / (1 + e) in the quotient), the sum and
    # the quotient a u each, against float64's: within 4 u
    assert mask_probability(raw, "bce").flatten().tolist() == pytest.approx(sigmoid, rel=4 * u)


def test_region_loss_is_uniform_cross_entropy_at_zero_logits() -> None:
    labels = torch.tensor([[[1, 2], [0, 3]]])
    visible = (labels > 0).float()[:, None]
    # float32: log of the sum of five exact e^0 (a u or so), three equal terms summed and divided by 3 (3 u)
    assert math.isclose(
        float(region_loss(torch.zeros(1, 5, 2, 2), labels, visible)), math.log(5), rel_tol=8 * 2**-24
    )


def test_pm_loss_of_a_known_rotation() -> None:
    pts = torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64)
    # R_pred p = (0, 1, 0), R_gt p = (1, 0, 0): per-point L1 = 2, "3 x mean over xyz" = 2
    assert math.isclose(float(pm_loss(rot_z(90), torch.eye(3, dtype=torch.float64), pts)), 2.0)


def test_pose_errors_of_known_perturbations() -> None:
    """float64 throughout: a few u64 (1e-16) an operation, times arccos's 1 / sin(angle) for an angle (2.4 at
    25 deg), so 1e-9 holds with room while a wrong formula misses by O(1)."""
    pts = torch.rand(500, 3, dtype=torch.float64) - 0.5
    R, t = torch.eye(3, dtype=torch.float64)[None], torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64)
    shift = torch.tensor([[0.03, 0.0, 0.04]], dtype=torch.float64)
    assert math.isclose(float(add_error(R, t + shift, R, t, pts)), 0.05, rel_tol=1e-9)
    assert math.isclose(float(rotation_error_deg(rot_z(25)[None], R)), 25.0, rel_tol=1e-9)
    turned = rot_z(10)[None]
    assert float(adds_error(turned, t, R, t, pts)) <= float(add_error(turned, t, R, t, pts))
    # a distance through |a|^2 + |b|^2 - 2 a.b cancels to ~8 u64 |a|^2 (|a| = |p + t| < 2.5): its root 7e-8
    assert float(adds_error(R, t, R, t, pts)) == pytest.approx(0.0, abs=1e-7)


def test_esa_score_terms_and_thresholds() -> None:
    R, t = torch.eye(3, dtype=torch.float64)[None], torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64)
    # 10 deg and 0.1 m at 2 m: score = rad(10) + 0.05 (float64: arccos's 1 / sin(10 deg) = 5.8 times a few
    # u64, far inside 1e-9)
    got = esa_score(rot_z(10)[None], t + torch.tensor([[0.1, 0.0, 0.0]], dtype=torch.float64), R, t)
    assert math.isclose(float(got), math.radians(10) + 0.05, rel_tol=1e-9)
    tiny = esa_score(rot_z(ESA_THETA_Q_DEG / 2)[None], t + 1e-3, R, t)
    assert float(tiny) == 0.0


def test_summary_keys_and_recalls() -> None:
    R = torch.eye(3, dtype=torch.float64).expand(4, 3, 3)
    t = torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64).expand(4, 3)
    offsets = torch.tensor([[0.0, 0, 0], [0.01, 0, 0], [0.019, 0, 0], [0.05, 0, 0]], dtype=torch.float64)
    pts = torch.rand(100, 3, dtype=torch.float64) - 0.5
    errs = sample_errors(R, t + offsets, R, t, pts, pts, torch.eye(4, dtype=torch.float64)[None])
    s = summarise({k: v.tolist() for k, v in errs.items()}, diameter=0.2, symmetric=False)
    assert {"re_deg", "te_m", "add_0.02m", "add_0.1d", "adds_0.1d", "esa"} <= set(s)
    assert s["add_0.02m"] == 0.75 and s["add_0.1d"] == 0.75
    # float64: each te the norm of a one-entry offset (2 - 2 is 0 exactly), a u64 or so, and a mean of four
    # summed in another order: a few u64, inside isclose's 1e-9, where a wrong mean (over 3) is 33 %
    assert math.isclose(s["te_m"], (0.01 + 0.019 + 0.05) / 4)


def test_medians_and_turned_share_skip_missed_instances() -> None:
    R = torch.eye(3, dtype=torch.float64)
    t = torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64)
    pts = torch.rand(100, 3, dtype=torch.float64) - 0.5
    sym = torch.eye(4, dtype=torch.float64)[None]
    angles = [5.0, 30.0, TURNED_DEG + 1.0, 179.0, 100.0]  # median 100, two beyond TURNED_DEG
    rows = [sample_errors(rot_z(a)[None], t + 0.1 * t, R[None], t, pts, pts, sym) for a in angles]
    errors = {k: [float(r[k]) for r in rows] + [math.inf] for k in rows[0]}  # and one missed detection
    s = summarise(errors, diameter=0.2, symmetric=False)
    assert s["re_deg_median"] == pytest.approx(100.0) and s["turned"] == pytest.approx(2 / 5)
    assert s["te_m_median"] == pytest.approx(0.2) and s["tz_rel_median"] == pytest.approx(0.1)
    assert s["n"] == 6


def test_add_splits_into_its_rotation_and_translation_causes() -> None:
    pts = torch.rand(200, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64) - 0.5
    R, t = rot_z(20.0)[None], torch.tensor([[0.1, -0.2, 2.0]], dtype=torch.float64)
    sym = torch.eye(4, dtype=torch.float64)[None]
    # a translation error alone: every point moves by it, so ADD = te and the rotation's share is 0 (float64:
    # the norms of the same vector through other sums, a few u64: 1e-12 holds)
    shifted = sample_errors(R, t + torch.tensor([[0.03, 0.0, 0.4]], dtype=torch.float64), R, t, pts, pts, sym)
    assert float(shifted["add_rot_m"]) == 0.0
    assert math.isclose(float(shifted["add_m"]), float(shifted["te_m"]), rel_tol=1e-12)
    assert math.isclose(float(shifted["tz_rel"]), 0.4 / 2.0, rel_tol=1e-12)
    # a rotation error alone: the rotation's share is the whole ADD, translation and depth errors 0
    turned = sample_errors(rot_z(80.0)[None], t, R, t, pts, pts, sym)
    assert float(turned["te_m"]) == 0.0 and float(turned["tz_rel"]) == 0.0
    assert math.isclose(float(turned["add_rot_m"]), float(turned["add_m"]), rel_tol=1e-12)
    assert float(turned["add_m"]) > 0.15  # beyond 0.1 of the diameter 1 below
    s = summarise({k: shifted[k].tolist() + turned[k].tolist() for k in shifted}, 1.0, False)
    assert s["add_rot_0.1d"] == 0.5 and s["te_0.1d"] == 0.5 and s["add_0.1d"] == 0.0


def test_adds_runs_from_each_gt_point_to_the_nearest_estimated_point_as_bop_adi() -> None:
    """bop_toolkit's pose_error.adi: a KD-tree over the estimated points, queried with the GT points. The
    same float64 distances summed in another order: a few u64 relative, inside 1e-12."""
    g = torch.Generator().manual_seed(3)
    pts = torch.rand(300, 3, generator=g, dtype=torch.float64) - 0.5
    pts[:, 0] *= 4  # elongated, so that the two directions of the nearest-point mean differ
    R_gt, t_gt = torch.eye(3, dtype=torch.float64), torch.tensor([0.0, 0.0, 3.0], dtype=torch.float64)
    R_est, t_est = rot_z(35.0), torch.tensor([0.1, 0.0, 3.2], dtype=torch.float64)
    est, gt = pts @ R_est.T + t_est, pts @ R_gt.T + t_gt
    bop_adi = cKDTree(est.numpy()).query(gt.numpy(), k=1)[0].mean()
    reverse = cKDTree(gt.numpy()).query(est.numpy(), k=1)[0].mean()
    assert abs(bop_adi - reverse) > 0.01 * bop_adi
    assert float(adds_error(R_est, t_est, R_gt, t_gt, pts)) == pytest.approx(bop_adi, rel=1e-12)
    assert float(adds_error(R_est, t_est, R_gt, t_gt, pts, max_block=1000)) == pytest.approx(
        bop_adi, rel=1e-12
    )
