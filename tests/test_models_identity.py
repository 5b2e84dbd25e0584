"""γ = 0 at init: AFR and PGSA variants reproduce the ConvNeXt control exactly for the same shared weights."""

from __future__ import annotations

import pytest
import torch

from posenet.models import create_model

WITH_MODULES = ["ggca", "mecs", "afr", "pgsa", "gap-gdrnet"]


def assert_same_outputs(name: str, preset: str, train: bool) -> None:
    torch.manual_seed(0)
    control = create_model("convnext", preset)
    variant = create_model(name, preset)
    result = variant.load_state_dict(control.state_dict(), strict=False)
    assert result.unexpected_keys == []
    assert result.missing_keys and all(
        k.startswith(("geo_head.refine.", "pnp.pgsa.")) for k in result.missing_keys
    )
    control.train(train)
    variant.train(train)
    r, o = variant.config.input_res, variant.config.output_res
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
    assert_same_outputs(name, "smoke", train)


def test_full_model_is_exact_identity_at_init_paper_size() -> None:
    torch.set_num_threads(1)
    assert_same_outputs("gap-gdrnet", "paper", False)
