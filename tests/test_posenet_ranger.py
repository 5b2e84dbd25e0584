"""posenet's fused Ranger against timm's Lookahead(RAdam), the optimizer posenet trained with before."""

from __future__ import annotations

import copy

import torch
from timm.optim import create_optimizer_v2, param_groups_weight_decay
from torch import nn

from posenet.training.ranger import BETAS, Ranger

LR, WD, EPS = 1e-3, 0.05, 1e-8  # the smoke config's lr, the default decay and Adam epsilon
# what posenet.training.train.make_optimizer built up to 3a10b4b: timm's Lookahead(RAdam)
TIMM_RANGER = {"opt": "lookahead_radam", "lr": LR, "weight_decay": WD, "betas": BETAS, "eps": EPS,
               "decoupled_weight_decay": True, "filter_bias_and_bn": True}  # fmt: skip
STEPS = 100
# Both run the same arithmetic in another order: RAdam's update of one weight takes at most 10 float32
# roundings in either (sqrt, +eps, two divisions, three products, the add; the Lookahead pull 2 more),
# each off by at most eps/2 of its result. The update is lr-sized and each result is bounded by the
# weight it lands on plus lr, so one step can move the two apart by <= 12 * eps * (|w| + lr), and 100
# steps by 100 times that when the difference does not feed back faster than it adds (gradients of
# weights this close differ by as little; the run below shows it does not).
ROUNDINGS = 12


def small_net() -> nn.Module:
    """Convolutions, a norm and a linear head: conv/FC weights (decayed) and 1-d weights and biases
    (timm's no-decay group), as in posenet's networks."""
    return nn.Sequential(
        # no bias before BatchNorm: its gradient would be rounding noise alone, which Adam scales to
        # lr-sized steps of random sign, so two exact optimizers would part by lr a step (seen: 4e-4)
        nn.Conv2d(3, 8, 3, padding=1, bias=False),
        nn.BatchNorm2d(8),
        nn.ReLU(),
        nn.Conv2d(8, 8, 3, stride=2, padding=1),
        nn.GroupNorm(2, 8),
        nn.ReLU(),
        nn.Flatten(),
        nn.Linear(8 * 8 * 8, 4),
    )


def timm_ranger(model: nn.Module) -> torch.optim.Optimizer:
    """What posenet.training.train.make_optimizer built up to 3a10b4b."""
    return create_optimizer_v2(model, **TIMM_RANGER)


def train(model: nn.Module, optimizer: torch.optim.Optimizer, steps: int, seed: int = 1) -> None:
    """`steps` steps on a fixed regression task, the lr warmed up over the first 20 (a LambdaLR, as in
    training), so both optimizers see the same data and schedule."""
    gen = torch.Generator().manual_seed(seed)
    x, y = torch.rand(16, 3, 16, 16, generator=gen), torch.rand(16, 4, generator=gen)
    sched = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda it: min(1.0, (it + 1) / 20))
    for _ in range(steps):
        optimizer.zero_grad(set_to_none=True)
        nn.functional.mse_loss(model(x), y).backward()
        optimizer.step()
        sched.step()


def twins() -> tuple[nn.Module, nn.Module]:
    torch.manual_seed(0)
    a = small_net()
    b = small_net()
    b.load_state_dict(a.state_dict())
    return a, b


def assert_close(a: nn.Module, b: nn.Module, steps: int) -> None:
    eps = torch.finfo(torch.float32).eps
    for (name, p), q in zip(a.named_parameters(), b.parameters(), strict=True):
        bound = steps * ROUNDINGS * eps * (p.detach().abs() + LR)
        diff = (p - q).detach().abs()
        assert (diff <= bound).all(), (name, float(diff.max()))


def test_ranger_equals_timms_over_100_steps() -> None:
    ref, new = twins()
    start = [p.detach().clone() for p in ref.parameters()]
    train(ref, timm_ranger(ref), STEPS)
    train(new, Ranger(param_groups_weight_decay(new, WD), lr=LR, weight_decay=WD, eps=EPS), STEPS)
    assert_close(ref, new, STEPS)
    moved = min(float((p.detach() - s).abs().max()) for p, s in zip(ref.parameters(), start, strict=True))
    assert moved > 100 * LR * EPS  # every tensor trained: the comparison is not of untouched weights


def test_ranger_resumes_timms_state() -> None:
    """A checkpoint written with timm's optimizer (its state dict) continues here as it would there."""
    ref, new = twins()
    opt = timm_ranger(ref)
    train(ref, opt, 7)  # past one Lookahead pull: the slow weights are in the state
    new.load_state_dict(ref.state_dict())
    ranger = Ranger(param_groups_weight_decay(new, WD), lr=LR, weight_decay=WD, eps=EPS)
    ranger.load_state_dict(copy.deepcopy(opt.state_dict()))  # as read from a checkpoint: no shared tensors
    assert ranger.param_groups[0]["lookahead_step"] == 7
    train(ref, opt, 20, seed=2)
    train(new, ranger, 20, seed=2)
    assert_close(ref, new, 20)
