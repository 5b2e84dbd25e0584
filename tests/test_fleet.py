"""The bundled fleet: each model is what its builder makes, its declared symmetry holds on its surface and
no other model has one, and `scgen render --model NAME` labels it as it labels the spacecraft."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from posenet.data.object_model import load_object_model
from scgen.assets.build import BUILDERS
from scgen.assets.fleet import Z_AXIS_SYMMETRY
from scgen.cli import main as scgen_main
from scgen.io import bop
from scgen.scenes.bundled_models import BUNDLED_MODELS, DEFAULT_MODEL
from scgen.scenes.model import bundled_model_dir, load_target

FLEET = [name for name in BUNDLED_MODELS if name != DEFAULT_MODEL]
GLB_ROUNDING = 2.0**-23  # parts.glb stores float32 vertices: a relative error of one unit in the last place
HALF_TURNS = {
    "x": np.diag([1.0, -1.0, -1.0]),
    "y": np.diag([-1.0, 1.0, -1.0]),
    "z": np.diag([-1.0, -1.0, 1.0]),
}


def turn_about_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def farthest_off_surface(mesh: trimesh.Trimesh, R: np.ndarray) -> float:
    """The largest distance of a vertex of `mesh` turned by R from the unturned surface (metres)."""
    _, distance, _ = trimesh.proximity.ProximityQuery(mesh).on_surface(mesh.vertices @ R.T)
    return float(distance.max())


def test_every_bundled_model_has_a_builder_and_is_what_it_builds():
    assert set(BUILDERS) == set(BUNDLED_MODELS)
    for name in BUNDLED_MODELS:
        stored, built = load_target(name), BUILDERS[name]()
        assert [m for m, _ in stored.parts] == [m for m, _ in built.parts], name
        for (_, a), (_, b) in zip(stored.parts, built.parts, strict=True):
            assert np.array_equal(a.faces, b.faces)
            assert np.abs(a.vertices - b.vertices).max() <= 4 * GLB_ROUNDING * built.diameter, name
        assert stored.symmetries == built.symmetries
        (info,) = bop.read_json(bundled_model_dir(name) / bop.MODELS_INFO_FILE).values()
        assert info["diameter"] == pytest.approx(built.diameter * bop.MM_PER_M)


@pytest.mark.parametrize("name", BUNDLED_MODELS)
def test_every_part_faces_outward(name):
    """Each part of each bundled model encloses a positive volume (divergence theorem over its faces): its
    faces are wound outward, the side a one-sided BSDF (Mitsuba's) shades."""
    for material, mesh in load_target(name).parts:
        assert mesh.volume > 0, f"{name}: a {material} part of {len(mesh.faces)} faces is wound inward"


def test_the_upper_stage_looks_the_same_turned_about_its_axis_by_any_angle():
    model = load_target("upper_stage")
    assert model.symmetries == Z_AXIS_SYMMETRY
    # every part is revolved from a profile in 24 or more sections: a turned vertex stays on its ring, which
    # the faceted surface follows to within the sagitta r (1 - cos(pi / 24)) at the largest radius r
    radius = np.linalg.norm(model.mesh.vertices[:, :2], axis=1).max()
    sagitta = radius * (1.0 - np.cos(np.pi / 24))
    for angle in (0.3, 1.9, 4.4):
        assert farthest_off_surface(model.mesh, turn_about_z(angle)) <= sagitta + 1e-9
    # and it is the axis: about x the stage (nozzle at one end) does not map onto itself
    assert farthest_off_surface(model.mesh, HALF_TURNS["x"]) > 10 * sagitta


@pytest.mark.parametrize("name", [n for n in FLEET if n != "upper_stage"])
def test_the_others_have_no_half_turn_symmetry(name):
    """No half turn about its axes maps an asymmetric model onto itself: each moves some part of it off its
    surface by more than a tenth of BOP's ADD threshold (10 % of the diameter)."""
    model = load_target(name)
    assert model.symmetries == {}
    for axis, R in HALF_TURNS.items():
        assert farthest_off_surface(model.mesh, R) > 0.01 * model.diameter, axis


def test_render_takes_a_bundled_model_by_name_and_carries_its_symmetry(tmp_path):
    out = tmp_path / "stage"
    args = ["render", "--out", str(out), "--n", "2", "--model", "upper_stage", "--backend", "mitsuba",
            "--resolution", "64x48", "--quality", "draft", "--quiet"]  # fmt: skip
    result = CliRunner().invoke(scgen_main, args)
    assert result.exit_code == 0, result.output
    (info,) = json.loads((out / "models" / bop.MODELS_INFO_FILE).read_text()).values()
    assert info["symmetries_continuous"] == Z_AXIS_SYMMETRY["symmetries_continuous"]
    turns = np.asarray(load_object_model(out, 1, num_regions=8, num_pm=64).symmetries)
    assert len(turns) == int(np.ceil(np.pi / 0.01))  # BOP's discretisation of a continuous symmetry
    assert np.allclose(turns[:, 2, :3], [0.0, 0.0, 1.0]) and np.allclose(turns[:, :3, 3], 0.0)


def test_an_unknown_model_name_is_refused_naming_the_bundled_ones(tmp_path):
    out = tmp_path / "none"
    result = CliRunner().invoke(scgen_main, ["render", "--out", str(out), "--n", "1", "--model", "cubesatt",
                                             "--backend", "mitsuba", "--quiet"])  # fmt: skip
    assert result.exit_code != 0
    assert "cubesatt" in result.output and "upper_stage" in result.output
    assert not out.exists()
