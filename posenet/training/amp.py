"""Mixed precision for pose training: the mode a run trains in, its autocast and fp16's gradient scaler.

`optim.amp` is `auto`, `off`, `bf16` or `fp16`. `auto` (the paper preset) is bf16 on a CUDA GPU that
supports it and float32 elsewhere; the CPU preset says `off`. Autocast covers the forward pass and the
losses; pose decoding and the point-matching loss run in float32 (`posenet.training.losses.pose_losses`). fp16
scales the loss with torch's GradScaler, so small gradients do not flush to zero.
"""

from __future__ import annotations

import contextlib

import torch

DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}


def resolve_amp(mode: str, device: torch.device) -> str:
    """The precision `mode` trains in on `device`: `auto` is bf16 on a CUDA GPU with bf16, else off."""
    if mode != "auto":
        return mode
    return "bf16" if device.type == "cuda" and torch.cuda.is_bf16_supported() else "off"


class Precision:
    """A run's resolved precision (off, bf16 or fp16) on one device type, and its gradient scaler."""

    def __init__(self, mode: str, device: torch.device) -> None:
        self.mode = resolve_amp(mode, device)
        self.device_type = device.type
        self.scaler = torch.amp.GradScaler(device.type, enabled=self.mode == "fp16")

    @property
    def label(self) -> str:
        """float32, bf16 or fp16."""
        return "float32" if self.mode == "off" else self.mode

    def loss_scale(self) -> float:
        """fp16's current loss scale (1 where the scaler is off). GradScaler halves it exactly when it
        skips an optimizer step (its scaled gradients overflowed), so a fall tells a skipped step."""
        return self.scaler.get_scale() if self.scaler.is_enabled() else 1.0

    def autocast(self) -> contextlib.AbstractContextManager:
        """Autocast to the run's dtype (a no-op in float32)."""
        if self.mode == "off":
            return contextlib.nullcontext()
        return torch.autocast(self.device_type, dtype=DTYPES[self.mode])


def full_precision(device: torch.device) -> contextlib.AbstractContextManager:
    """Autocast switched off on `device`: what must stay float32 inside an autocast region."""
    return torch.autocast(device.type, enabled=False)
