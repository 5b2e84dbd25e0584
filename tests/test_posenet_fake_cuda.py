"""Every CUDA path of posenet checked without a GPU: the networks run on a *fake* CUDA device.

Under torch's FakeTensorMode the weights are moved to a fake `cuda` device and every op only computes
shapes, dtypes and devices. A tensor that a module, a loss or the pose maths creates on the CPU and then
mixes with a CUDA tensor raises FakeTensorDeviceMismatchError here, as it would fail on a GPU. Autograd's
backward needs a real CUDA context, so the checks cover forward passes, losses, pose decoding and the
metrics; the detector's box selection and its loss matching have data-dependent shapes, which fake
tensors cannot follow, so it is checked up to its decoded boxes for every anchor.
"""

from __future__ import annotations

import pytest
import torch
from timm.optim import param_groups_weight_decay
from torch import nn
from torch._subclasses.fake_tensor import FakeTensorDeviceMismatchError, FakeTensorMode

from posenet.config import LossConfig
from posenet.detection.detector import build_detector, cpu_config, detector_config_from_dict
from posenet.detection.segmenter import mask_losses
from posenet.evaluation.metrics import sample_errors
from posenet.geometry import decode_pose
from posenet.models import PRESETS, VARIANTS, create_model
from posenet.training.losses import PmObject, pose_losses
from posenet.training.ranger import LOOKAHEAD_K, Ranger

CUDA = torch.device("cuda", 0)


def to_fake_cuda(model: nn.Module, mode: FakeTensorMode) -> nn.Module:
    """The model's parameters and buffers as fake CUDA tensors; tensors kept as plain attributes (as
    torchvision's anchors, which the model moves itself) become fake tensors on their own device."""
    for module in model.modules():
        for name, p in module._parameters.items():
            if p is not None:
                module._parameters[name] = nn.Parameter(mode.from_tensor(p).to(CUDA), p.requires_grad)
        for name, b in module._buffers.items():
            if b is not None:
                module._buffers[name] = mode.from_tensor(b).to(CUDA)
        for name, value in list(vars(module).items()):
            if isinstance(value, torch.Tensor):
                setattr(module, name, mode.from_tensor(value))
            elif isinstance(value, list) and value and all(isinstance(v, torch.Tensor) for v in value):
                setattr(module, name, [mode.from_tensor(v) for v in value])
    return model


def fake_batch(b: int, res: int, regions: int) -> dict[str, torch.Tensor]:
    """A training batch's targets and RoI geometry on the (fake) CUDA device."""
    R = torch.linalg.qr(torch.randn(b, 3, 3, device=CUDA)).Q
    return {
        "roi_xyz": torch.rand(b, 3, res, res, device=CUDA),
        "roi_mask_visib": torch.rand(b, 1, res, res, device=CUDA).round(),
        "roi_region": torch.randint(0, regions + 1, (b, res, res), device=CUDA),
        "R": R,
        "t": torch.rand(b, 3, device=CUDA) + torch.tensor([0.0, 0.0, 2.0], device=CUDA),
        "K": torch.eye(3, device=CUDA).expand(b, 3, 3),
        "crop_center": torch.rand(b, 2, device=CUDA) * 100,
        "box_wh": torch.rand(b, 2, device=CUDA) * 50 + 10,
        "resize_ratio": torch.rand(b, device=CUDA),
        "site": torch.rand(b, 3, device=CUDA),
    }


def test_a_cpu_tensor_mixed_into_fake_cuda_fails() -> None:
    """The premise: on the fake device, a CPU tensor meeting a CUDA one is an error, as on a GPU."""
    with FakeTensorMode(), pytest.raises(FakeTensorDeviceMismatchError):
        torch.ones(2, 2, device=CUDA) + torch.ones(2, 2)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_pose_network_losses_decoding_and_metrics_stay_on_cuda(variant: str, preset: str) -> None:
    torch.manual_seed(0)
    model = create_model(variant, preset).train()
    c = model.config
    mode = FakeTensorMode()
    with mode:
        to_fake_cuda(model, mode)
        batch = fake_batch(2, c.output_res, c.num_regions)
        out = model(
            torch.rand(2, 3, c.input_res, c.input_res, device=CUDA),
            torch.rand(2, 2, *[c.output_res] * 2, device=CUDA),
        )
        symmetries = torch.eye(4, device=CUDA).repeat(3, 1, 1)  # K = 3: the symmetric PM path too
        pm = PmObject(torch.rand(100, 3, device=CUDA), symmetries)
        losses = [pose_losses(out, batch, pm, LossConfig(mask_type=kind)) for kind in ("bce", "l1")]
        R, t = decode_pose(out, batch)
        errors = sample_errors(R, t, batch["R"], batch["t"], pm.points, pm.points, symmetries)
    assert all(v.device == CUDA for v in out.values())
    for total, terms in losses:
        assert total.device == CUDA and all(v.device == CUDA for v in terms.values())
    assert R.device == t.device == CUDA and R.shape == (2, 3, 3)
    assert all(e.device == CUDA and e.shape == (2,) for e in errors.values())


@pytest.mark.parametrize("preset", ["cpu", "paper"])
def test_detector_network_anchors_and_box_decoding_stay_on_cuda(preset: str) -> None:
    cfg = cpu_config() if preset == "cpu" else detector_config_from_dict({"preset": "paper"})
    model = build_detector(cfg.model_dict(), None).eval()
    mode = FakeTensorMode()
    with mode:
        to_fake_cuda(model, mode)
        images, _ = model.transform([torch.rand(3, 240, 320, device=CUDA)])
        features = list(model.backbone(images.tensors).values())
        head = model.head(features)
        anchors = model.anchor_generator(images, features)
        boxes = model.box_coder.decode(head["bbox_regression"][0], anchors[0])
        scores = head["cls_logits"][0].sigmoid() * head["bbox_ctrness"][0].sigmoid()
    assert images.tensors.device == CUDA and all(f.device == CUDA for f in features)
    assert anchors[0].device == boxes.device == scores.device == CUDA
    assert boxes.shape == (len(anchors[0]), 4)


def test_mask_detector_logits_and_losses_stay_on_cuda() -> None:
    """The mask detector: its per-pixel logits, at the input's size, and its losses."""
    cfg = detector_config_from_dict({"preset": "cpu", "arch": "mask-timm"})
    model = build_detector(cfg.model_dict(), None).train()
    mode = FakeTensorMode()
    with mode:
        to_fake_cuda(model, mode)
        logits = model.logits(torch.rand(2, 3, 240, 320, device=CUDA))
        losses = mask_losses(logits, torch.zeros(2, 1, 240, 320, device=CUDA))
    assert logits.device == CUDA and logits.shape == (2, 1, 240, 320)
    assert all(v.device == CUDA for v in losses.values())


def test_the_fused_ranger_steps_on_cuda() -> None:
    """Ranger on CUDA: torch's fused Adam kernel with each step count on its parameter's device (the
    kernel reads it there), through RAdam's unrectified first steps and a Lookahead pull (step 6)."""
    net = nn.Sequential(nn.Conv2d(3, 4, 3), nn.BatchNorm2d(4), nn.Flatten(), nn.Linear(4 * 4 * 4, 2))
    mode = FakeTensorMode()
    with mode:
        to_fake_cuda(net, mode)
        optimizer = Ranger(param_groups_weight_decay(net, 0.05), lr=1e-3, weight_decay=0.05, eps=1e-8)
        for _ in range(LOOKAHEAD_K + 1):
            for p in net.parameters():
                p.grad = torch.randn_like(p)
            optimizer.step()
    for p in net.parameters():
        state = optimizer.state[p]
        assert set(state) == {"step", "exp_avg", "exp_avg_sq", "lookahead_slow_buff"}
        assert all(v.device == CUDA and v.dtype == torch.float32 for v in state.values())
