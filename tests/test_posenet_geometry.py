"""Pose geometry: rot6d, allocentric/egocentric, SITE, and the DZI crop against the dataset's own targets."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from posenet.config import smoke_config
from posenet.data import open_split
from posenet.data.crop import Roi, crop_affine, roi_from_box
from posenet.geometry import (
    allo_to_ego,
    ego_to_allo,
    mat_to_rot6d,
    project,
    ray_rotation,
    rot6d_to_mat,
    site_decode,
    site_encode,
)

# torch's float64 kernels (matmul, det) on unit-norm rotations: each entry a few products of O(1) terms, so
# good to ~10 eps = 2e-15; the 1e-12 bounds below leave 500x for another CPU's kernels.
# The figures hang on those kernels: `make test` reruns the module under a second kernel set
pytestmark = pytest.mark.numeric


def random_rotations(n: int, seed: int = 0) -> torch.Tensor:
    q = torch.randn(n, 4, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    w, x, y, z = torch.nn.functional.normalize(q, dim=-1).unbind(-1)
    return torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            torch.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            torch.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def random_translations(n: int, seed: int = 1) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    xy = (torch.rand(n, 2, generator=g) - 0.5) * 1.5
    z = 0.3 + 3 * torch.rand(n, 1, generator=g)
    return torch.cat([xy, z], -1).double()


# The float64 checks below (atol 1e-12): a few u64 (1.1e-16) per operation on unit-sized entries, a few
# tens of operations a rotation: ~1e-14 at most, where a wrong convention (order, sign, transpose) is O(1).


def test_rot6d_round_trip() -> None:
    R = random_rotations(500)
    assert torch.allclose(rot6d_to_mat(mat_to_rot6d(R)), R, atol=1e-12)


def test_rot6d_of_any_vector_is_a_rotation() -> None:
    R = rot6d_to_mat(torch.randn(500, 6, generator=torch.Generator().manual_seed(2)).double())
    eye = torch.eye(3, dtype=torch.float64).expand(500, 3, 3)
    assert torch.allclose(R.transpose(-1, -2) @ R, eye, atol=1e-12)
    assert torch.allclose(torch.linalg.det(R), torch.ones(500, dtype=torch.float64), atol=1e-12)


def test_ray_rotation_takes_optical_axis_to_the_ray() -> None:
    t = random_translations(500)
    Rq = ray_rotation(t)
    z = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    assert torch.allclose(Rq @ z, t / t.norm(dim=-1, keepdim=True), atol=1e-12)
    assert torch.allclose(torch.linalg.det(Rq), torch.ones(500, dtype=torch.float64), atol=1e-12)
    # on the axis v = 0, so the ray rotation is I + 0 + 0 exactly
    assert torch.equal(ray_rotation(torch.tensor([0.0, 0.0, 2.0])), torch.eye(3))


def test_allo_ego_round_trip_and_on_axis_identity() -> None:
    R, t = random_rotations(500), random_translations(500)
    assert torch.allclose(allo_to_ego(ego_to_allo(R, t), t), R, atol=1e-12)
    assert torch.allclose(ego_to_allo(allo_to_ego(R, t), t), R, atol=1e-12)
    on_axis = torch.tensor([[0.0, 0.0, 1.5]], dtype=torch.float64)
    assert torch.allclose(allo_to_ego(R[:1], on_axis), R[:1], atol=1e-12)


def test_allocentric_rotation_is_invariant_to_moving_along_the_view() -> None:
    """Swinging an on-axis object onto another ray (camera-centred turn, no roll): R_allo is unchanged."""
    R, t = random_rotations(100), torch.tensor([[0.0, 0.0, 2.0]], dtype=torch.float64).expand(100, 3)
    turn = ray_rotation(random_translations(100))
    moved = (turn @ t[..., None])[..., 0]
    assert torch.allclose(ego_to_allo(turn @ R, moved), ego_to_allo(R, t), atol=1e-12)


def test_site_round_trip_recovers_translation() -> None:
    n = 500
    g = torch.Generator().manual_seed(3)
    t = random_translations(n)
    K = torch.tensor([[600.0, 0, 319.5], [0, 610.0, 239.5], [0, 0, 1]], dtype=torch.float64).expand(n, 3, 3)
    centre = project(K, t) + 20 * torch.randn(n, 2, generator=g, dtype=torch.float64)
    box_wh = 30 + 200 * torch.rand(n, 2, generator=g, dtype=torch.float64)
    ratio = 64 / (1.5 * box_wh.amax(-1))
    site = site_encode(t, K, centre, box_wh, ratio)
    # a float64 round trip, ~10 roundings of depths up to 3.3 m: ~1e-14 m; 1e-5 m is far above rounding
    assert (site_decode(site, K, centre, box_wh, ratio) - t).norm(dim=-1).max() < 1e-5
    assert torch.allclose(site[:, 2], t[:, 2] / ratio)


def test_crop_affine_maps_the_square_onto_the_grid() -> None:
    roi = roi_from_box((100, 50, 40, 80), (640, 480), pad_scale=1.5)
    A = crop_affine(roi, 64)
    corners = np.array([[*(roi.center - roi.scale / 2), 1.0], [*(roi.center + roi.scale / 2), 1.0]])
    # float64 affine of integers and halves: exact or within a few u64 x 640, far inside allclose's defaults
    assert np.allclose(corners @ A.T, [[-0.5, -0.5], [63.5, 63.5]])
    assert math.isclose(roi.scale, 120.0)


def test_dzi_crop_puts_targets_where_the_geometry_says(dataset_dir: Path) -> None:
    """On real rendered samples with DZI jitter: the projected object centre lands where coord2d and SITE
    put it, and every visible xyz target pixel projects (with the GT pose) onto its own RoI pixel."""
    cfg = smoke_config()
    model_cfg = cfg.model_config()
    ds = open_split(dataset_dir, "train", cfg.data, model_cfg, train=True)
    r = model_cfg.output_res
    for idx in range(len(ds)):
        item = ds[(3, idx)]
        inst = ds.instances[idx]
        W, H = inst.image_size
        K, R, t = (item[k].double() for k in ("K", "R", "t"))
        centre = project(K, t)
        # SITE offset + crop centre = projected centre (float32 items: 2^-24 of ~300 px is 2e-5 px; 1e-3 px
        # covers the few roundings of the offset's product and sum)
        site = item["site"].double()
        assert torch.allclose(
            site[:2] * item["box_wh"].double() + item["crop_center"].double(), centre, atol=1e-3
        )
        # coord2d is an affine image of the grid: evaluate it at the projected centre's RoI position
        roi = Roi(
            item["crop_center"].double().numpy(), r / float(item["resize_ratio"]), item["box_wh"].numpy()
        )
        u, v = crop_affine(roi, r) @ np.array([*centre.numpy(), 1.0])
        c2d = item["roi_coord2d"].double()
        grid = np.arange(r)
        got_u = np.interp(u, grid, c2d[0, 0].numpy()) * W
        got_v = np.interp(v, grid, c2d[1, :, 0].numpy()) * H
        # float32 coord2d (u / W): 2^-24 x 640 = 4e-5 px a value, a linear interpolation of two: 1e-3 px
        assert abs(got_u - centre[0]) < 1e-3 and abs(got_v - centre[1]) < 1e-3
        # every visible xyz target pixel projects onto the image point its RoI pixel covers
        vis = item["roi_mask_visib"][0] > 0
        xyz = (item["roi_xyz"].double().permute(1, 2, 0)[vis] - 0.5) * torch.from_numpy(ds.obj.extent)
        px = project(K, xyz @ R.T + t)
        seen = torch.stack([c2d[0][vis] * W, c2d[1][vis] * H], -1)
        err = (px - seen).norm(dim=-1)
        # nearest-neighbour target sampling: within a full-resolution pixel of the RoI pixel centre
        assert err.median() < 0.75 and err.max() < 1.5, (idx, float(err.median()), float(err.max()))
