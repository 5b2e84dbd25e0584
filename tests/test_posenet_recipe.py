"""GDR-Net's recipe details as options: the head's norm, Ranger's gradient centralisation, weight decay
on norms and biases."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from posenet.config import OptimConfig
from posenet.errors import PosenetError
from posenet.models import create_model
from posenet.training.train import centralize_gradients, make_optimizer

SMALL = {"head_channels": 32, "pnp_channels": 32, "fc_dims": (64, 32)}


def test_head_norm_is_groupnorm_by_default_and_gdrnet_batchnorm_on_request() -> None:
    for norm, kind in (("gn", nn.GroupNorm), ("bn", nn.BatchNorm2d)):
        model = create_model("gdrnet", "smoke", head_norm=norm, **SMALL)
        head = {type(m) for m in model.geo_head.decoder.modules()}
        assert kind in head and ({nn.GroupNorm, nn.BatchNorm2d} - {kind}).isdisjoint(head)
        assert any(isinstance(m, nn.GroupNorm) for m in model.pnp.modules())  # Patch-PnP keeps GN
        assert model.config_dict()["head_norm"] == norm
    assert create_model("gdrnet", "smoke", **SMALL).config.head_norm == "gn"
    with pytest.raises(PosenetError, match="head_norm"):
        create_model("gdrnet", "smoke", head_norm="ln")


def test_gradient_centralisation_centres_conv_and_fc_gradients_only() -> None:
    torch.manual_seed(0)
    model = create_model("gdrnet", "smoke", **SMALL)
    optimizer, _ = make_optimizer(model, OptimConfig(), total_iters=10)
    out = model(torch.rand(2, 3, 128, 128), torch.rand(2, 2, 32, 32))
    (out["rot6d"].square().sum() + out["xyz"].mean()).backward()
    before = {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
    centralize_gradients(optimizer)
    for name, p in model.named_parameters():
        if name not in before:
            continue
        if p.dim() > 1:
            mean = p.grad.mean(dim=tuple(range(1, p.dim())))
            # Centred exactly, the mean is 0. In float32 (u = 2^-24) each of the two means over a fan-in
            # of n (the centring's and this check's) sums in torch's cascade (pairwise) order, within
            # (log2 n + 1) u max|g| of exact, and the subtraction rounds each entry by u |g - mean| <=
            # 2 u max|g|, so the residual mean is within (2 (log2 n + 1) + 2) u max|g|.
            fan_in = p[0].numel()
            bound = (2 * (math.ceil(math.log2(fan_in)) + 1) + 2) * 2.0**-24 * before[name].abs().max()
            assert mean.abs().max() <= bound, name
        else:
            assert torch.equal(p.grad, before[name]), name


@pytest.mark.parametrize("decay_all", [False, True])
def test_norms_and_biases_decay_only_when_asked(decay_all: bool) -> None:
    model = create_model("gdrnet", "smoke", **SMALL)
    optimizer, _ = make_optimizer(model, OptimConfig(decay_norms_biases=decay_all), total_iters=10)
    decayed = {id(p) for g in optimizer.param_groups if g["weight_decay"] > 0 for p in g["params"]}
    one_d = [p for p in model.parameters() if p.dim() <= 1]
    assert all(id(p) in decayed for p in model.parameters() if p.dim() > 1)
    assert all((id(p) in decayed) == decay_all for p in one_d)
