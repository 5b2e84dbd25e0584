"""The training step's forward pass and losses, eager or compiled (`optim.compile`).

Both return (loss, values): the scalar loss to back-propagate and the detached float32 (total, *terms)
that the log reads. Compiled, the function goes through `torch.compile`; on CUDA with
mode="reduce-overhead", which records forward and losses (and, through AOTAutograd, their backward) as
CUDA graphs and replays them, so a step launches a few graphs where eager mode launches every kernel
from Python (issue 63: the GPU idles between launches at the paper's batch). Shapes must stay fixed:
EpochSampler drops an incomplete batch, so every training batch has one shape and the graphs are
recorded once. A replay writes its outputs into the same memory, so the values are copied out.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from posenet.config import LossConfig
from posenet.training.amp import Precision
from posenet.training.losses import LOSS_TERMS, PmObject, pose_losses

Losses = Callable[[dict[str, torch.Tensor]], tuple[torch.Tensor, torch.Tensor]]


def eager_losses(model: torch.nn.Module, pm: PmObject, cfg: LossConfig, precision: Precision) -> Losses:
    """The forward pass and the losses of a batch under `precision`'s autocast, as Python runs them."""

    def losses(batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        with precision.autocast():
            out = model(batch["roi_img"], batch["roi_coord2d"])
            loss, terms = pose_losses(out, batch, pm, cfg)
        return loss, torch.stack([loss.detach(), *(terms[k].detach() for k in LOSS_TERMS)]).float()

    return losses


def compiled_losses(
    model: torch.nn.Module,
    pm: PmObject,
    cfg: LossConfig,
    precision: Precision,
    device: torch.device,
) -> Losses:
    """`eager_losses` through torch.compile: CUDA graphs on a CUDA `device` (mode reduce-overhead),
    inductor's fused kernels elsewhere."""
    cuda = device.type == "cuda"
    compiled = torch.compile(
        eager_losses(model, pm, cfg, precision), mode="reduce-overhead" if cuda else None
    )

    def losses(batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        if cuda:
            torch.compiler.cudagraph_mark_step_begin()  # the previous step's outputs are no longer read
        loss, values = compiled(batch)
        return loss, values.clone()  # the next replay overwrites the graph's outputs

    return losses
