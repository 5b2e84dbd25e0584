"""Ranger (RAdam + Lookahead) as one fused Adam pass over the weights.

RAdam's rectified update is Adam's with the learning rate times the rectification r_t and epsilon over
sqrt(c2), where c1 = 1 - beta1^t and c2 = 1 - beta2^t:

    lr r_t / c1 * m * sqrt(c2) / (sqrt(v) + eps)  =  (lr r_t) / c1 * m / (sqrt(v) / sqrt(c2) + eps / sqrt(c2))

so torch's fused Adam kernel (`fused=True`: one pass over weights, gradients and both moments, on a CPU
or a GPU) computes it. timm's Lookahead(RAdam), which training used up to 3a10b4b, steps RAdam one
parameter at a time on a CPU and pulls each weight toward its slow copy in a Python loop; torch's foreach
RAdam, used after it, makes ten passes over the weights. The arithmetic is timm's, so the weights agree
to float rounding (tests/test_posenet_ranger.py), and the state dict is timm's too (the moments and step
of RAdam and Adam share their names; each parameter's `lookahead_slow_buff` and the groups'
`lookahead_*` entries), so a checkpoint written with timm's optimizer resumes here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import torch

BETAS = (0.95, 0.999)  # GDRNPP's Ranger
LOOKAHEAD_ALPHA = 0.5  # GDRNPP's and timm's Lookahead: halfway back to the slow weights ...
LOOKAHEAD_K = 6  # ... every 6 steps
FUSED_ADAM = {"fused": True, "foreach": None, "capturable": False, "amsgrad": False, "maximize": False}


def rectification(step: int, beta2: float) -> float:
    """RAdam's variance rectification r_t at step `step` (from 1), or 0 while the variance of the
    adaptive learning rate is intractable (rho_t <= 5: the first steps take plain momentum steps)."""
    rho_inf = 2 / (1 - beta2) - 1
    rho_t = rho_inf - 2 * step * beta2**step / (1 - beta2**step)
    if rho_t <= 5:
        return 0.0
    return math.sqrt((rho_t - 4) * (rho_t - 2) * rho_inf / ((rho_inf - 4) * (rho_inf - 2) * rho_t))


class Ranger(torch.optim.Adam):
    """RAdam with decoupled weight decay (p -= lr * wd * p, as Ranger decays), then every `k` steps
    Lookahead: slow += alpha * (fast - slow), fast = slow.

    The step count t that RAdam's rectification and bias corrections use is the group's (Lookahead's
    `lookahead_step` + 1): every parameter of a group steps together, as in posenet's training, so the
    host knows t without reading a device tensor."""

    def __init__(
        self,
        params: Iterable[torch.Tensor] | Iterable[dict[str, Any]],
        lr: float,
        weight_decay: float,
        eps: float,
        betas: tuple[float, float] = BETAS,
        alpha: float = LOOKAHEAD_ALPHA,
        k: int = LOOKAHEAD_K,
    ) -> None:
        super().__init__(params, lr=lr, betas=betas, eps=eps, weight_decay=weight_decay, fused=True)
        # the decay, the momentum steps and Lookahead run outside the kernel, so GradScaler must unscale
        # and skip whole steps itself rather than hand the kernel its scale
        self._step_supports_amp_scaling = False
        for group in self.param_groups:
            group.setdefault("lookahead_alpha", alpha)
            group.setdefault("lookahead_k", k)
            group.setdefault("lookahead_step", 0)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Also on load_state_dict: a state dict of timm's optimizer (RAdam's groups) runs fused here,
        with each step count on its parameter's device as the fused kernel reads it."""
        super().__setstate__(state)
        for group in self.param_groups:
            group.update(FUSED_ADAM)
            for p in group["params"]:
                if "step" in self.state.get(p, {}):
                    self.state[p]["step"] = self.state[p]["step"].to(p.device, torch.float32)

    @torch.no_grad()
    def step(self, closure: Any = None) -> Any:  # noqa: ANN401 (torch's signature)
        """One RAdam step of every group, then Lookahead where a group's k-th step falls."""
        loss = None
        if closure is not None:  # the gradients first, as torch's optimizers take them
            with torch.enable_grad():
                loss = closure()
        # per group: its parameters with a gradient, its rectification, and the lr, eps and weight decay
        # it was given, which the kernel's call replaces for a moment
        plan = []
        for group in self.param_groups:
            lr, eps, weight_decay, beta2 = group["lr"], group["eps"], group["weight_decay"], group["betas"][1]
            params = [p for p in group["params"] if p.grad is not None]
            t = group["lookahead_step"] + 1
            rect = rectification(t, beta2)
            if weight_decay and params:
                torch._foreach_mul_(params, 1 - lr * weight_decay)
            plan.append((group, params, rect, (lr, eps, weight_decay)))
            group.update(lr=lr * rect, eps=eps / math.sqrt(1 - beta2**t), weight_decay=0.0)
        try:
            super().step()  # the moments, and the rectified update (lr 0 before rectification)
        finally:
            for group, _, _, (lr, eps, weight_decay) in plan:
                group.update(lr=lr, eps=eps, weight_decay=weight_decay)
        for group, params, rect, _ in plan:
            group["lookahead_step"] += 1
            t = group["lookahead_step"]
            if params and rect == 0:
                # RAdam's unrectified step: p -= lr / c1 * m
                moments = [self.state[p]["exp_avg"] for p in params]
                torch._foreach_add_(params, moments, alpha=-group["lr"] / (1 - group["betas"][0] ** t))
            if params and t % group["lookahead_k"] == 0:
                self._lookahead(group, params)
        return loss

    def _lookahead(self, group: dict[str, Any], fast: list[torch.Tensor]) -> None:
        """Pull the group's weights `fast` (those with a gradient) halfway (alpha) back to their slow
        copies, which then take their place; the slow copy starts as the weights at the first pull, as in
        timm."""
        for p in fast:
            if "lookahead_slow_buff" not in self.state[p]:
                self.state[p]["lookahead_slow_buff"] = p.detach().clone()
        slow = [self.state[p]["lookahead_slow_buff"] for p in fast]
        # timm's slow.add_(fast - slow, alpha=alpha), the same two roundings
        torch._foreach_add_(slow, torch._foreach_sub(fast, slow), alpha=group["lookahead_alpha"])
        torch._foreach_copy_(fast, slow)
