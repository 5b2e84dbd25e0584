"""Every variant, paper and smoke configurations: output shapes, backward, local backbone weights, config."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import timm
import torch

from posenet.errors import PosenetError
from posenet.models import VARIANTS, ModelConfig, create_model
from posenet.models.backbone import Backbone


def inputs(config: ModelConfig, batch: int) -> tuple[torch.Tensor, torch.Tensor]:
    r, o = config.input_res, config.output_res
    return torch.rand(batch, 3, r, r), torch.rand(batch, 2, o, o)


def expected_shapes(config: ModelConfig, batch: int) -> dict[str, tuple[int, ...]]:
    o = config.output_res
    return {
        "mask": (batch, 1, o, o),
        "xyz": (batch, 3, o, o),
        "region": (batch, config.num_regions + 1, o, o),
        "rot6d": (batch, 6),
        "site": (batch, 3),
        "features": (batch, config.head_channels, o, o),
    }


@pytest.fixture(autouse=True)
def _one_thread() -> None:
    torch.set_num_threads(1)
    torch.manual_seed(0)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_paper_config_shapes(name: str) -> None:
    model = create_model(name).eval()
    config = model.config
    assert (config.input_res, config.output_res, config.head_channels) == (256, 64, 256)
    with torch.no_grad():
        out = model(*inputs(config, batch=1))
    assert {k: tuple(v.shape) for k, v in out.items()} == expected_shapes(config, 1)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_smoke_config_shapes_and_backward(name: str) -> None:
    model = create_model(name, "smoke")
    config = model.config
    out = model(*inputs(config, batch=2))
    assert {k: tuple(v.shape) for k, v in out.items()} == expected_shapes(config, 2)
    sum(v.square().mean() for v in out.values()).backward()
    grads = {n: p.grad for n, p in model.named_parameters()}
    assert all(g is not None and torch.isfinite(g).all() for g in grads.values())
    gammas = [g for n, g in grads.items() if n in ("geo_head.refine.gamma", "pnp.pgsa.gamma")]
    assert len(gammas) == int(config.ggca or config.mecs) + int(config.pgsa)
    assert all(g.abs().sum() > 0 for g in gammas)  # γ = 0 still learns


@pytest.mark.parametrize("name", list(VARIANTS))
def test_smoke_preset_keeps_the_variant_modules(name: str) -> None:
    kinds = {type(m).__name__ for m in create_model(name, "smoke").modules()}
    variant = VARIANTS[name]
    assert ("GGCA" in kinds) == variant.ggca
    assert ("MECS" in kinds) == variant.mecs
    assert ("AFR" in kinds) == (variant.ggca or variant.mecs)
    assert ("PGSA" in kinds) == variant.pgsa


@pytest.fixture(scope="module")
def backbone_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """ImageNet-style classifier state dicts (timm keys), as a user would have on disk."""
    root = tmp_path_factory.mktemp("weights")
    files = {}
    for name in ("resnet18", "convnext_atto"):
        torch.manual_seed(1)
        files[name] = root / f"{name}.pth"
        torch.save(timm.create_model(name, pretrained=False).state_dict(), files[name])
    return files


@pytest.mark.parametrize(("name", "backbone"), [("gdrnet", "resnet18"), ("pgsa", "convnext_atto")])
def test_local_backbone_weights_load(name: str, backbone: str, backbone_files: dict[str, Path]) -> None:
    """forward_features of these two is their stride-32 map (EfficientNet's adds a 1x1 conv head)."""
    config = ModelConfig.create(name, "smoke", backbone=backbone)
    path = backbone_files[backbone]
    reference = timm.create_model(config.backbone, pretrained=False)
    reference.load_state_dict(torch.load(path))
    model = create_model(name, "smoke", backbone=config.backbone, pretrained=str(path)).eval()
    x = torch.rand(1, 3, config.input_res, config.input_res)
    mean, std = (torch.tensor(reference.pretrained_cfg[k]).view(1, 3, 1, 1) for k in ("mean", "std"))
    with torch.no_grad():  # the backbone feeds its weights the normalisation they were trained with
        expected = reference.eval().forward_features((x - mean) / std)
        # the same float32 ops (InputNorm's (x - mean) / std, then the timm modules) on the same shapes in
        # one process: the same arithmetic, so the same floats, not merely close ones
        assert torch.equal(model.backbone(x), expected)
    saved = torch.load(path)
    conv = next(k for k in saved if k.endswith("weight") and saved[k].ndim == 4)  # stem conv
    assert any(torch.equal(saved[conv], v) for v in model.backbone.state_dict().values())


def test_wrong_weights_file_is_refused(backbone_files: dict[str, Path], tmp_path: Path) -> None:
    with pytest.raises(PosenetError, match="not a convnext_atto state dict"):
        resnet = str(backbone_files["resnet18"])
        create_model("convnext", "smoke", backbone="convnext_atto", pretrained=resnet)
    with pytest.raises(PosenetError, match="not found"):
        create_model("gdrnet", "smoke", pretrained=str(tmp_path / "missing.pth"))


def test_config_dict_identifies_and_rebuilds_checkpoints() -> None:
    d = json.loads(json.dumps(create_model("pgsa", "smoke", head_channels=32).config_dict()))
    assert d["variant"] == "pgsa" and "pretrained" not in d  # init-only: not part of the identity
    assert create_model(**d).config == ModelConfig.create("pgsa", "smoke", head_channels=32)
    smoke = ModelConfig.create("pgsa", "smoke")
    assert ModelConfig.create("pgsa", "smoke", pretrained="imagenet.pth").to_dict() == smoke.to_dict()
    assert d != create_model("afr", "smoke").config_dict()


@pytest.mark.parametrize(
    ("args", "overrides", "message"),
    [
        (("resnet",), {}, "unknown variant 'resnet'"),
        (("gdrnet", "large"), {}, "unknown preset 'large'"),
        (("gdrnet", "smoke"), {"ggca": True}, "is not variant 'gdrnet'"),
        (("gdrnet", "smoke"), {"backbone": "resnet_nonesuch"}, "unknown backbone 'resnet_nonesuch'"),
        (("gdrnet", "smoke"), {"width": 3}, "unknown model field"),
        (("gdrnet", "smoke"), {"head_channels": "abc"}, "head_channels must be int, got 'abc'"),
        (("gdrnet", "smoke"), {"fc_dims": [1.5]}, "fc_dims must be tuple"),
        (("gdrnet", "smoke"), {"input_res": 256}, "input_res / 4"),
    ],
)
def test_create_model_refuses_another_variant_and_bad_fields(
    args: tuple[str, ...], overrides: dict, message: str
) -> None:
    with pytest.raises(PosenetError, match=message):
        ModelConfig.create(*args, **overrides)


def test_overrides_within_the_variant_are_kept() -> None:
    config = ModelConfig.create("gap-gdrnet", "smoke", ggca=True, backbone="convnext_femto", fc_dims=[64, 32])
    assert (config.backbone, config.fc_dims, config.variant) == ("convnext_femto", (64, 32), "gap-gdrnet")
    # the backbone is free: GDR-Net on a ConvNeXt is still the gdrnet row, not the convnext one
    assert ModelConfig.create("gdrnet", "smoke", backbone="convnext_atto").variant == "gdrnet"


def test_smoke_preset_compares_every_variant_on_one_backbone() -> None:
    assert {ModelConfig.create(v, "smoke").backbone for v in VARIANTS} == {"tf_efficientnet_lite0"}
    assert [ModelConfig.create(v).backbone for v in ("gdrnet", "gap-gdrnet")] == ["resnet34", "convnext_tiny"]


def test_backbone_without_a_stride_32_map_is_refused() -> None:
    with pytest.raises(PosenetError, match="stride 16, not 32"):
        create_model("gdrnet", "smoke", backbone="vit_tiny_patch16_224")


def test_pnp_input_is_xyz_visible_mask_regions_and_roi_coordinates() -> None:
    model = create_model("gdrnet", "smoke").eval()
    config = model.config
    assert model.pnp.encoder[0][0].in_channels == 3 + 1 + config.num_regions + 2
    seen, shift = {}, {"mask": 0.0}

    def edit_head(module: torch.nn.Module, args: tuple, out: tuple) -> tuple:
        features, mask, xyz, region = out
        return features, mask + shift["mask"], xyz, region

    model.geo_head.register_forward_hook(edit_head)
    model.pnp.register_forward_pre_hook(lambda module, args: seen.update(x=args[0]))
    img, coord = inputs(config, batch=2)
    with torch.no_grad():
        out = model(img, coord)
        x = seen["x"]
        assert x.shape[1] == 3 + 1 + config.num_regions + 2
        assert torch.equal(x[:, :3], out["xyz"]) and torch.equal(x[:, 3:4], out["mask"].sigmoid())
        assert torch.allclose(x[:, 4:-2], out["region"][:, 1:].softmax(1)) and torch.equal(x[:, -2:], coord)
        shift["mask"] = 3.0  # only the mask logits change: the pose must see it
        moved = model(img, coord)
    assert torch.equal(moved["xyz"], out["xyz"]) and torch.equal(moved["region"], out["region"])
    # the mask channel moves by sigmoid(m + 3) - sigmoid(m), up to 0.6 a pixel; 1e-3 of an output's scale is
    # 12 times float_bounds' rounding between two forwards of this network (8.5e-5), so rounding alone never
    # passes it, while a pose that reads the mask moves by a share of its scale (seeded weights: 0.1 to 0.5)
    for key in ("rot6d", "site"):
        assert (moved[key] - out[key]).abs().max() > 1e-3 * out[key].abs().max()


@pytest.mark.parametrize(("name", "branch_end"), [("resnet18", "bn2"), ("convnext_atto", "mlp.fc2")])
def test_from_scratch_residual_branches_start_open(name: str, branch_end: str) -> None:
    """timm's from-scratch init closes every residual branch (ResNet's last BN at 0, ConvNeXt's layer
    scale at 1e-6), leaving a ~20 px receptive field; ours must start with the branches contributing."""
    torch.manual_seed(0)
    backbone = Backbone(name).eval()
    x = torch.rand(2, 3, 128, 128)
    with torch.no_grad():
        out = backbone(x)
        for module_name, module in backbone.named_modules():
            if module_name.endswith(branch_end):  # the branch's last layer: zero it to close the branch
                module.weight.zero_()
                module.bias.zero_()
        closed = backbone(x)
    assert float((out - closed).norm() / out.norm()) > 0.1
