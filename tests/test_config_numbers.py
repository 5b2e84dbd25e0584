"""Config numbers as a user writes them: 1e-3 and 1E-3 are floats in every YAML config (scgen's, posenet's,
the detector's), and a wrongly typed value's message shows the form expected."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from posenet.config import load_config as load_train_config
from posenet.detection.detector import load_detector_config
from posenet.errors import PosenetError
from scgen.cli import main
from scgen.errors import ScgenError
from scgen.io import load_yaml
from scgen.scenes.config.scene import load_config as load_scene_config


def test_exponent_floats_are_floats_and_nothing_else_changes():
    text = "a: 1e-3\nb: 1E-3\nc: 2.5e3\nd: .5e-2\ne: +1e+3\nf: 1.0e-3\n"
    text += "g: 10\nh: 0x10\ni: '1e-3'\nj: 1e\nk: 1_000\n"
    assert load_yaml(text) == {
        "a": 0.001, "b": 0.001, "c": 2500.0, "d": 0.005, "e": 1000.0, "f": 0.001,
        "g": 10, "h": 16, "i": "1e-3", "j": "1e", "k": 1000,
    }  # fmt: skip
    assert isinstance(load_yaml("n: 10")["n"], int)


@pytest.mark.parametrize("written", ["1e-3", "1E-3", "1.0e-3", "0.001"])
def test_posenet_configs_read_the_learning_rate_as_written(tmp_path: Path, written: str):
    path = tmp_path / "c.yaml"
    path.write_text(f"preset: smoke\noptim: {{lr: {written}, eps: 1e-8}}\n")
    cfg = load_train_config(str(path))
    assert cfg.optim.lr == 0.001 and cfg.optim.eps == 1e-8
    path.write_text(f"preset: cpu\noptim: {{lr: {written}}}\n")
    assert load_detector_config(str(path)).optim.lr == 0.001


def test_scgen_configs_read_exponent_floats(tmp_path: Path):
    path = tmp_path / "c.yaml"
    path.write_text("shadow:\n  caster_prob: 5e-1\n")
    assert load_scene_config(path)["shadow"]["caster_prob"] == 0.5


@pytest.mark.parametrize(
    "line, message",
    [
        ("optim: {lr: fast}", "config 'optim.lr' must be a number such as 0.001 or 1e-3, got 'fast'"),
        ("optim: {lr: true}", "config 'optim.lr' must be a number such as 0.001 or 1e-3, got True"),
        ("optim: {batch_size: 8.5}", "config 'optim.batch_size' must be a whole number such as 8, got 8.5"),
        (
            "optim: {grad_centralization: 1}",
            "config 'optim.grad_centralization' must be true or false, got 1",
        ),
        (
            "data: {brightness: [0.5, x]}",
            r"'data.brightness' must be a list of 2 numbers such as \[0.5, 1.5\]",
        ),
    ],
)
def test_a_wrongly_typed_value_names_the_form_expected(tmp_path: Path, line: str, message: str):
    path = tmp_path / "c.yaml"
    path.write_text(f"preset: smoke\n{line}\n")
    with pytest.raises(PosenetError, match=message):
        load_train_config(str(path))


def test_scgen_names_the_number_form_in_one_line(tmp_path: Path):
    path = tmp_path / "c.yaml"
    path.write_text("shadow:\n  caster_prob: often\n")
    with pytest.raises(ScgenError, match="'shadow.caster_prob' must be a number such as 0.001 or 1e-3"):
        load_scene_config(path)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", "--n", "1", "--out", str(out), "--config", str(path)])
    assert result.exit_code != 0 and result.output.count("\n") == 1 and "1e-3" in result.output
    assert not out.exists()
