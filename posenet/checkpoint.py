"""Checkpoint files: what a run saves each epoch, and the checks that refuse a mismatched one."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import torch

from posenet.errors import PosenetError
from posenet.models import ModelConfig, PoseNet, create_model
from scgen.io import atomic_write_bytes

REQUIRED = ("model", "model_config", "config", "step")


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """Write atomically: a reader (or a crash) never sees half a checkpoint."""
    buf = io.BytesIO()
    torch.save(state, buf)
    atomic_write_bytes(path, buf.getvalue())


KINDS = {"pose": "posenet train's", "detector": "posenet train-detector's"}


def checkpoint_kind(state: dict[str, Any]) -> str:
    """'detector' (an FCOS run: its model_config names an arch) or 'pose'."""
    return "detector" if "arch" in state["model_config"] else "pose"


def load_checkpoint(path: Path, kind: str | None = None) -> dict[str, Any]:
    """A posenet checkpoint on the CPU (of `kind`, pose or detector, when given); anything else is a
    one-line error naming the file."""
    if not Path(path).is_file():
        raise PosenetError(f"checkpoint not found: {path}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for foreign or corrupt files
        raise PosenetError(f"{path} is not a readable checkpoint: {str(exc).splitlines()[0]}") from exc
    if not isinstance(state, dict) or any(k not in state for k in REQUIRED):
        raise PosenetError(f"{path} is not a posenet checkpoint (needs {', '.join(REQUIRED)})")
    if kind is not None and checkpoint_kind(state) != kind:
        found = checkpoint_kind(state)
        raise PosenetError(
            f"{path} is a {found} checkpoint ({KINDS[found]}), not a {kind} one ({KINDS[kind]})"
        )
    return state


def check_model_config(state: dict[str, Any], expected: dict[str, Any], path: Path) -> None:
    """Refuse a checkpoint written for another network configuration, naming the differing fields. A field
    the checkpoint predates (e.g. `head_norm`) stands for its default, which is what rebuilds it."""
    found = {**ModelConfig().to_dict(), **state["model_config"]}
    if found != expected:
        diff = sorted(k for k in set(found) | set(expected) if found.get(k) != expected.get(k))
        detail = ", ".join(f"{k}: {found.get(k)!r} != {expected.get(k)!r}" for k in diff[:4])
        raise PosenetError(f"checkpoint {path} is from another configuration ({detail})")


def load_model(ckpt: Path, device: torch.device) -> tuple[PoseNet, dict[str, Any]]:
    """The network of a checkpoint, in eval mode on `device`, and the checkpoint itself."""
    state = load_checkpoint(ckpt, kind="pose")
    return model_from_state(state, ckpt, device), state


def model_from_state(state: dict[str, Any], ckpt: Path, device: torch.device) -> PoseNet:
    """The network of an already loaded pose checkpoint `state` (read from `ckpt`), in eval mode."""
    model = create_model(**state["model_config"])
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as exc:
        raise PosenetError(f"checkpoint {ckpt} does not match its own model configuration") from exc
    return model.to(device).eval()
