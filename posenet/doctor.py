"""What this machine has for posenet: the packages every command needs (the console's guard), those a
given config needs (`check_config_packages`), and whether the default training can get its backbone's
weights (`train_weights`, posenet's line in `scgen doctor`).

The weights check is registered with the doctor as an entry point (pyproject.toml, group `scgen.doctor`),
so that scgen reads it without importing posenet; it returns (verdict, detail, fix), verdict `ok` or
`warn`. Nothing here imports torch or timm before finding them installed.
"""

from __future__ import annotations

import importlib.util
import os
import socket
import threading
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlparse

from posenet.errors import PosenetError

if TYPE_CHECKING:
    from posenet.config import TrainConfig

TRAINING_MODULES = ("torch", "torchvision", "timm", "tensorboard")  # what every posenet command imports
INSTALL_HINT = "pip install 'scgen[train]'"
# One TCP connect to the weights' host, at most this long: it says online or not without a request, where
# timm's own download retries for ~50 s offline before its error.
PROBE_S = 3.0
OFFLINE_FIX = (
    "posenet train --config smoke (its EfficientNet-Lite0 ImageNet weights ship in a package: the weights "
    "line), or set model.pretrained to a local weights file, or run once online to cache them"
)


def missing_training_modules() -> list[str]:
    """The training stack's top-level modules that cannot be found here (none are imported)."""
    return [m for m in TRAINING_MODULES if importlib.util.find_spec(m) is None]


def check_config_packages(cfg: TrainConfig) -> None:
    """Raise PosenetError naming the package and the config key when `cfg` selects something whose
    package is not installed here: every data.augment chain but the paper's is albumentations'
    (posenet.data.photometric, imported by the dataset only for those)."""
    augment = cfg.data.augment
    if augment != "paper" and importlib.util.find_spec("albumentations") is None:
        raise PosenetError(f"data.augment: {augment} needs albumentations, not installed here: "
                           f"{INSTALL_HINT} (or data.augment: paper, which needs none)")  # fmt: skip


def train_weights() -> tuple[str, str, str]:
    """Whether the default `posenet train` (no --config: the paper preset) can get its backbone's initial
    weights here: cached, packaged, a local file, or online. Downloads nothing (see PROBE_S)."""
    if any(importlib.util.find_spec(name) is None for name in ("torch", "timm")):
        return "warn", "not checked: posenet needs torch and timm", INSTALL_HINT
    from posenet.config import TrainConfig
    from posenet.models.backbone import shipped_weights_file, timm_weights
    from posenet.models.config import IMAGENET, PACKAGE

    cfg = TrainConfig()
    model = cfg.model_config()
    default = f"posenet train's default ({cfg.preset} preset, {cfg.variant}: {model.backbone})"
    if model.pretrained is None:
        return "ok", f"{default} starts from random init: nothing to fetch", ""
    try:
        if model.pretrained == IMAGENET:
            weights = timm_weights(model.backbone)
            path, where = weights.cached, "timm's ImageNet weights"
        elif model.pretrained == PACKAGE:
            path, where = shipped_weights_file(model.backbone), "its packaged ImageNet weights"
        else:
            path, where = Path(model.pretrained), "its weights file"
    except PosenetError as exc:
        return "warn", f"{default}: {exc}", OFFLINE_FIX
    if path is not None and path.is_file():
        return "ok", f"{default}: {where} at {path}", ""
    if model.pretrained != IMAGENET:
        return "warn", f"{default}: {where} missing ({path})", OFFLINE_FIX
    address = urlparse(weights.source)
    host, port = address.hostname or "", address.port or (80 if address.scheme == "http" else 443)
    offline = _unreachable(host, port)
    if offline is None:
        return "ok", f"{default}: {where} not cached; {host} is reachable: the first run downloads them", ""
    return "warn", f"{default} cannot start: {where} are not cached and {host} {offline}", OFFLINE_FIX


def _unreachable(host: str, port: int) -> str | None:
    """Why `host` cannot be reached (HF_HUB_OFFLINE, no address, no connection within PROBE_S), or None.

    One TCP connect, no request, in a thread given up after PROBE_S (a name lookup ignores socket
    timeouts)."""
    if os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on"):
        return "is ruled out: HF_HUB_OFFLINE is set"
    found: list[str | None] = [f"gave no connection within {PROBE_S:g} s"]

    def connect() -> None:
        try:
            socket.create_connection((host, port), timeout=PROBE_S).close()
            found[0] = None
        except OSError as exc:
            found[0] = f"is unreachable ({type(exc).__name__}: offline?)"

    probe = threading.Thread(target=connect, daemon=True)
    probe.start()
    probe.join(PROBE_S)
    return found[0]
