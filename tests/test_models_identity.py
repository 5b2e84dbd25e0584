"""γ = 0 at init: AFR and PGSA variants reproduce the ConvNeXt control exactly for the same shared weights."""

from __future__ import annotations

import pytest
import torch

from posenet.models import ModelConfig, build_model

WITH_MODULES = ["ggca", "mecs", "afr", "pgsa", "gap-gdrnet"]


def assert_same_outputs(name: str, config: ModelConfig, control_config: ModelConfig, train: bool) -> None:
    torch.manual_seed(0)
    control = build_model("convnext", control_config)
    variant = build_model(name, config)
    result = variant.load_state_dict(control.state_dict(), strict=False)
    assert result.unexpected_keys == []
    assert result.missing_keys and all(
        k.startswith(("geo_head.refine.", "pnp.pgsa.")) for k in result.missing_keys
    )
    control.train(train)
    variant.train(train)
    r, o = config.input_res, config.output_res
    img, coord = torch.rand(2, 3, r, r), torch.rand(2, 2, o, o)
    with torch.no_grad():
        want, got = control(img, coord), variant(img, coord)
    assert want.keys() == got.keys()
    for key in want:
        assert torch.equal(want[key], got[key]), key


@pytest.mark.parametrize("train", [False, True])
@pytest.mark.parametrize("name", WITH_MODULES)
def test_modules_are_exact_identities_at_init_smoke(name: str, train: bool) -> None:
    torch.set_num_threads(1)
    assert_same_outputs(name, ModelConfig.smoke(name), ModelConfig.smoke("convnext"), train)


def test_full_model_is_exact_identity_at_init_paper_size() -> None:
    torch.set_num_threads(1)
    assert_same_outputs("gap-gdrnet", ModelConfig.paper("gap-gdrnet"), ModelConfig.paper("convnext"), False)
