"""ImageNet weights for the backbones: the package-shipped EfficientNet-Lite0, and the download path."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import matplotlib
import numpy as np
import pytest
import timm
import torch

from posenet.config import load_config
from posenet.errors import PosenetError
from posenet.models import create_model
from posenet.models.backbone import checked_weights, shipped_weights_file

MILITARY_UNIFORM = 652  # ImageNet class of Grace Hopper's portrait (matplotlib's sample photo)


def photo(size: int) -> torch.Tensor:
    """matplotlib's sample portrait of Grace Hopper in uniform, centre square, RGB in [0, 1]."""
    bgr = cv2.imread(str(Path(matplotlib.get_data_path()) / "sample_data" / "grace_hopper.jpg"))
    h, w = bgr.shape[:2]
    s = min(h, w)
    square = bgr[(h - s) // 2 : (h - s) // 2 + s, (w - s) // 2 : (w - s) // 2 + s, ::-1]
    rgb = cv2.resize(square, (size, size), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
    return torch.from_numpy(rgb.transpose(2, 0, 1).copy())[None]


def test_package_weights_are_imagenet_lite0_under_timm_names() -> None:
    """The shipped EfficientNet-PyTorch keys, renamed by position, make timm's Lite0 see the uniform:
    a wrong rename (two same-shaped tensors swapped, a BN's stats moved) would not."""
    torch.set_num_threads(1)
    net = timm.create_model("tf_efficientnet_lite0", pretrained=False).eval()
    shipped = shipped_weights_file("tf_efficientnet_lite0")
    net.load_state_dict(checked_weights("tf_efficientnet_lite0", shipped))
    with torch.no_grad():
        probs = net((photo(224) - 0.5) / 0.5).softmax(1)[0]
    assert int(probs.argmax()) == MILITARY_UNIFORM
    assert probs[MILITARY_UNIFORM] > 0.2  # 1000 classes: chance is 0.001


def test_cpu_preset_trains_from_the_package_weights() -> None:
    cfg = load_config("smoke")
    model = create_model(cfg.variant, cfg.preset, **cfg.model)
    shipped = torch.load(shipped_weights_file(cfg.model_config().backbone))
    assert torch.equal(model.backbone.body.conv_stem.weight, shipped["_conv_stem.weight"])
    assert load_config("paper").model["pretrained"] == "imagenet"  # the paper's: timm's own weights


def test_package_weights_of_another_shape_are_refused(tmp_path: Path) -> None:
    with pytest.raises(PosenetError, match="do not match the backbone's shapes"):
        checked_weights("efficientnet_lite1", shipped_weights_file("efficientnet_lite0"))
    with pytest.raises(PosenetError, match="no package ships ImageNet weights for backbone 'resnet34'"):
        create_model("gdrnet", pretrained="package")


def test_imagenet_offline_is_one_line_naming_the_alternatives(tmp_path: Path) -> None:
    """timm's download, with the hub told it is offline (as on a machine without internet)."""
    code = "from posenet.models import create_model; create_model('gdrnet', 'smoke', pretrained='imagenet')"
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path), "TORCH_HOME": str(tmp_path)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert "cannot get timm's ImageNet weights for tf_efficientnet_lite0" in last
    assert "local weights file" in last and "'package'" in last
