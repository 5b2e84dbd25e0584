"""AFR / PGSA building blocks: shapes, identity at γ = 0, median pooling robustness, feature response."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F
from float_bounds import forward_rel

from posenet.evaluation.featviz import feature_response
from posenet.models.afr import AFR, GGCA, MECS, channel_descriptors
from posenet.models.pnp import PGSA


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)


def test_single_outlier_moves_median_least() -> None:
    x = torch.randn(1, 4, 16, 16)
    spiked = x.clone()
    spiked[0, :, 3, 5] = 100.0  # one reflection-like outlier per channel
    before, after = channel_descriptors(x), channel_descriptors(spiked)
    mean_shift, max_shift, median_shift = ((a - b).abs() for a, b in zip(after, before, strict=True))
    assert (median_shift < mean_shift).all()
    assert (median_shift < max_shift).all()
    assert (median_shift < 0.05).all()


@pytest.mark.parametrize(
    "module",
    [
        GGCA(64, groups=8, reduction=4),
        MECS(64, reduction=4, kernels=(7, 11, 21)),
        AFR(64, ggca=True, mecs=True, groups=8, reduction=4, kernels=(7, 11, 21)),
        AFR(64, ggca=True, mecs=False, groups=8, reduction=4, kernels=(7, 11, 21)),
        AFR(64, ggca=False, mecs=True, groups=8, reduction=4, kernels=(7, 11, 21)),
    ],
)
def test_afr_parts_keep_shape(module: torch.nn.Module) -> None:
    x = torch.randn(2, 64, 24, 20)  # non-square on purpose: the H and W axes must not be mixed up
    assert module(x).shape == x.shape


def test_ggca_gates_rows_and_columns() -> None:
    ggca = GGCA(16, groups=2, reduction=4).eval()
    x = torch.zeros(1, 16, 8, 6)
    x[0, :8, 2, :] = 1.0  # one bright row in group 0
    y = ggca(x)
    assert y[0, :, :2].abs().max() == 0 and y[0, 8:].abs().max() == 0  # zero stays zero (multiplicative)
    assert (y[0, :8, 2] > 0).all() and (y[0, :8, 2] < 1).all()  # sigmoid gates in (0, 1)


def test_gamma_zero_is_identity_and_gamma_moves_output() -> None:
    afr = AFR(64, ggca=True, mecs=True, groups=8, reduction=4, kernels=(7, 11, 21))
    pgsa = PGSA(32, num_tokens=16, heads=4)
    x, z = torch.randn(2, 64, 16, 16), torch.randn(2, 32, 4, 4)
    assert torch.equal(afr(x), x) and torch.equal(pgsa(z), z)
    with torch.no_grad():
        afr.gamma.fill_(1.0)
        pgsa.gamma.fill_(1.0)
    # gamma = 1 adds the branches: allclose's 1e-5 |x| + 1e-8 is ~170 u32 above the sum's float32 rounding, so
    # only a branch that contributes passes (the seeded default-initialised ones add entries of O(0.1))
    assert not torch.allclose(afr(x), x) and not torch.allclose(pgsa(z), z)


def test_pgsa_mixes_tokens() -> None:
    pgsa = PGSA(32, num_tokens=16, heads=4)
    with torch.no_grad():
        pgsa.gamma.fill_(1.0)
    z = torch.randn(1, 32, 4, 4)
    poked = z.clone()
    poked[0, :, 0, 0] += 1.0
    changed = (pgsa(poked) - pgsa(z)).abs().amax(1)[0]
    assert changed[3, 3] > 0  # a far token sees the change: global attention, not local conv


def test_feature_response_is_per_image_min_max_of_l2_norm() -> None:
    f = torch.zeros(2, 3, 4, 4)
    f[0, 0, 1, 1] = 3.0
    f[0, 1, 1, 1] = 4.0  # norm 5 at (1, 1)
    f[0, 2, 2, 2] = 1.0
    f[1] = 7.0  # constant image: no contrast
    r = feature_response(f)
    assert r.shape == (2, 4, 4)
    assert r[0, 1, 1] == 1.0 and r[0, 0, 0] == 0.0 and r[0, 2, 2] == pytest.approx(0.2)
    assert torch.equal(r[1], torch.zeros(4, 4))
    up = feature_response(f, size=16)
    assert up.shape == (2, 16, 16) and up.min() >= 0 and up.max() <= 1


def test_mecs_is_its_equations() -> None:
    """Paper eqs. mecs_channel to mecs_output, written out with the module's own weights."""
    c, kernels = 16, (7, 11, 21)
    mecs = MECS(c, reduction=4, kernels=kernels).eval()
    x = torch.randn(2, c, 12, 10)
    conv_in, lin1, lin2 = mecs.proj_in[0], mecs.channel_attention.mlp[0], mecs.channel_attention.mlp[2]
    X = F.gelu(F.conv2d(x, conv_in.weight, conv_in.bias))

    def psi(d: torch.Tensor) -> torch.Tensor:
        return F.linear(F.relu(F.linear(d, lin1.weight, lin1.bias)), lin2.weight, lin2.bias)

    pooled = (X.mean((2, 3)), X.amax((2, 3)), X.flatten(2).median(2).values)
    A_c = sum(psi(d) for d in pooled)[:, :, None, None]  # no sigmoid: Σ_ρ ψ(ρ(X))
    X_c = A_c * X
    B = F.conv2d(X_c, mecs.base.weight, mecs.base.bias, padding=2, groups=c)
    S = 0
    for k, (dw_1k, dw_k1) in zip(kernels, mecs.strips, strict=True):
        s_k = F.conv2d(B, dw_1k.weight, dw_1k.bias, padding=(0, k // 2), groups=c)
        S = S + F.conv2d(s_k, dw_k1.weight, dw_k1.bias, padding=(k // 2, 0), groups=c)
    F_mecs = torch.sigmoid(F.conv2d(S, mecs.spatial.weight, mecs.spatial.bias)) * X_c
    with torch.no_grad():  # the module groups its sums apart (float_bounds: rel of the output's scale)
        bound = forward_rel(mecs) * float(F_mecs.abs().max())
        assert torch.allclose(mecs(x), F_mecs, rtol=0, atol=bound)
