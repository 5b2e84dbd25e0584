"""Ranger (RAdam + Lookahead) on torch's multi-tensor kernels.

timm's Lookahead(RAdam), which training used before, steps RAdam one parameter at a time on a CPU and
pulls each weight toward its slow copy in a Python loop: ~10 % of a CPU smoke step and a string of tiny
kernel launches on a GPU. Here RAdam runs its foreach path (one `torch._foreach_*` call per operation
over a group's whole parameter list) and the Lookahead update is two foreach calls per group. The
arithmetic is timm's, so the weights agree to float rounding (tests/test_posenet_ranger.py), and the
state dict is timm's too (RAdam's, with each parameter's `lookahead_slow_buff` and the groups'
`lookahead_*` entries), so a checkpoint written with timm's optimizer resumes here.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch

BETAS = (0.95, 0.999)  # GDRNPP's Ranger
LOOKAHEAD_ALPHA = 0.5  # GDRNPP's and timm's Lookahead: halfway back to the slow weights ...
LOOKAHEAD_K = 6  # ... every 6 steps


class Ranger(torch.optim.RAdam):
    """RAdam with decoupled weight decay (p -= lr * wd * p, as Ranger decays), then every `k` steps
    Lookahead: slow += alpha * (fast - slow), fast = slow. `capturable` keeps RAdam's step count on the
    device, so its update can be recorded in a CUDA graph; Lookahead's every-k branch stays on the host."""

    def __init__(
        self,
        params: Iterable[torch.Tensor] | Iterable[dict[str, Any]],
        lr: float,
        weight_decay: float,
        eps: float,
        betas: tuple[float, float] = BETAS,
        alpha: float = LOOKAHEAD_ALPHA,
        k: int = LOOKAHEAD_K,
        capturable: bool = False,
    ) -> None:
        super().__init__(
            params,
            lr=lr,
            betas=betas,
            eps=eps,
            weight_decay=weight_decay,
            decoupled_weight_decay=True,
            foreach=True,
            capturable=capturable,
        )
        for group in self.param_groups:
            group.setdefault("lookahead_alpha", alpha)
            group.setdefault("lookahead_k", k)
            group.setdefault("lookahead_step", 0)

    @torch.no_grad()
    def step(self, closure: Any = None) -> Any:  # noqa: ANN401 (torch's signature)
        loss = super().step(closure)
        for group in self.param_groups:
            group["lookahead_step"] += 1
            if group["lookahead_step"] % group["lookahead_k"] == 0:
                self._lookahead(group)
        return loss

    def _lookahead(self, group: dict[str, Any]) -> None:
        """Pull the group's weights halfway (alpha) back to their slow copies, which then take their place;
        the slow copy starts as the weights at the first pull, as in timm."""
        fast = [p for p in group["params"] if p.grad is not None]
        if not fast:
            return
        for p in fast:
            if "lookahead_slow_buff" not in self.state[p]:
                self.state[p]["lookahead_slow_buff"] = p.detach().clone()
        slow = [self.state[p]["lookahead_slow_buff"] for p in fast]
        # timm's slow.add_(fast - slow, alpha=alpha), the same two roundings
        torch._foreach_add_(slow, torch._foreach_sub(fast, slow), alpha=group["lookahead_alpha"])
        torch._foreach_copy_(fast, slow)
