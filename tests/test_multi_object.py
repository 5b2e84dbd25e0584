"""Several labelled objects per scene (the config's `[[objects]]`): every instance is labelled as the
target is, on real Mitsuba renders: its xyz map reprojects onto its own pixels and lies on its own model,
its masks follow the depth order, and the target's own draws do not change for the objects beside it."""

from __future__ import annotations

import functools
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from scgen.cli import main as scgen_main
from scgen.dataset.validate import reprojection_error
from scgen.errors import ScgenError
from scgen.generator import Generator
from scgen.io import bop
from scgen.io.buffers import BACKGROUND_ID, TARGET_ID, object_instance_id
from scgen.render.mitsuba import raycast
from scgen.render.objects import objects_alone_depth
from scgen.scenes import load_config
from scgen.scenes.geometry import quat_to_matrix
from scgen.scenes.motion.orbit import Orbit, hcw_stm
from scgen.scenes.motion.tumble import mass_properties
from scgen.scenes.props import bounding_radius

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "servicer_client.toml"
RES = (256, 192)
SAMPLES = 5
# Two ray casts of one triangle (the scene's and the object's alone) place its float32 corners through
# different float64 products: each corner moves by at most 2^-24 of its coordinate, so a hit's depth by
# about that share of the depth, times the ray's 1/cos of its angle to the surface; 1e-4 leaves grazing
# hits (cos >= 0.0017, 89.9 deg) inside it.
DEPTH_RTOL = 1e-4
SURFACE_TOL = 0.005  # of the diameter: the xyz map's float32 values and the mesh's faceting (as the target's)


@functools.cache
def generator() -> Generator:
    return Generator.load(config=EXAMPLE, seed=5, resolution=RES, backend="mitsuba", quality="draft")


@functools.cache
def samples() -> list:
    return [generator().sample(i) for i in range(SAMPLES)]


def instances(sample):
    """(instance id, pose, obj_id, annotation, alone depth) of every labelled instance, the target first."""
    spec, buffers = sample.spec, sample.buffers
    yield TARGET_ID, spec.target, bop.TARGET_OBJ_ID, sample.annotation, buffers.target_depth
    for j, (obj, ann) in enumerate(zip(spec.objects, sample.objects, strict=True)):
        yield object_instance_id(j), obj.pose, obj.obj_id, ann, buffers.objects_depth[j]


def test_the_example_places_every_entry_apart_from_the_target_and_props():
    gen = generator()
    counts = {2: 1, 3: 2}  # obj_id: instances per scene in the example (smallsat once, upper_stage twice)
    radius = {k: float(np.linalg.norm(m.mesh.vertices, axis=1).max()) for k, m in gen.models.items()}
    assert sorted(gen.models) == [1, 2, 3]
    for i in range(20):
        spec = gen.scene(i)
        assert {k: sum(o.obj_id == k for o in spec.objects) for k in counts} == counts
        balls = [(spec.target.t_vec, radius[1])] + [
            (p.pose.t_vec, bounding_radius(p.shape, np.asarray(p.size))) for p in spec.props
        ]
        for obj in spec.objects:
            t = obj.pose.t_vec
            assert min(np.linalg.norm(t - c) - r for c, r in balls) > radius[obj.obj_id]
            balls.append((t, radius[obj.obj_id]))
        assert type(spec).from_dict(spec.to_dict()) == spec


def test_objects_draw_from_their_own_stream():
    """A scene with objects is the same scene without them, objects aside: the target, sun, sky and
    props keep every draw, so one-object datasets and their factor splits stay as they were."""
    alone = Generator.load(seed=5, resolution=RES, backend="mitsuba")
    for i in range(6):
        with_objects = generator().scene(i)
        assert with_objects.objects and replace(with_objects, objects=()) == alone.scene(i)
        assert "objects" not in alone.scene(i).to_dict()


def test_every_instance_xyz_reprojects_and_lies_on_its_own_model():
    surfaces = {k: trimesh.proximity.ProximityQuery(m.mesh) for k, m in generator().models.items()}
    diameters = {k: m.diameter for k, m in generator().models.items()}
    checked = set()
    for sample in samples():
        for _, pose, obj_id, ann, _ in instances(sample):
            vs, us = np.nonzero(ann.mask_visib)
            if len(us) < 20:
                continue
            assert not ann.xyz[~ann.mask_visib].any()
            C = ann.xyz[vs, us].astype(np.float64)
            err = reprojection_error(C, us, vs, sample.spec.camera, pose.R_mat, pose.t_vec)
            assert (err <= 0.5).mean() >= 0.995
            _, dist, _ = surfaces[obj_id].on_surface(C[:: max(1, len(C) // 400)])
            assert (dist <= SURFACE_TOL * diameters[obj_id]).mean() >= 0.99
            checked.add(obj_id)
    assert checked == {1, 2, 3}


def test_every_instance_masks_follow_the_depth_order():
    """Visible where it is the first surface hit, hidden exactly where something nearer covers it (another
    labelled object or a prop): the instances' visible masks partition their pixels, both ways."""
    hidden_by_objects = 0
    for sample in samples():
        buffers = sample.buffers
        claimed = np.zeros(buffers.depth.shape, np.int32)
        for instance, _, _, ann, alone in instances(sample):
            assert (ann.mask == (alone > 0)).all()
            assert not (ann.mask_visib & ~ann.mask).any()
            claimed += ann.mask_visib
            seen = ann.mask_visib
            assert np.allclose(buffers.depth[seen], alone[seen], rtol=DEPTH_RTOL, atol=0)
            hidden = ann.mask & ~ann.mask_visib
            assert (buffers.depth[hidden] < alone[hidden]).all()
            covering = buffers.instance[hidden]
            assert ((covering != instance) & (covering != BACKGROUND_ID)).all()
            hidden_by_objects += int(np.isin(covering, [TARGET_ID, *map(object_instance_id, range(3))]).sum())
            assert ann.r_occ == pytest.approx(1 - seen.sum() / max(1, ann.mask.sum()))
        assert claimed.max() <= 1
    assert hidden_by_objects > 0  # the example's objects do hide one another somewhere in these samples


@pytest.mark.parametrize(
    "entry, message",
    [
        ({"model": "smallsat", "colour": "red"}, "objects[0].colour"),
        ({"model": "no_such_model"}, "objects[0].model"),
        ({"model": "cubesat", "count": 0}, "objects[0].count"),
        ({"model": "cubesat", "distance": {"range_m": [3.0, 1.0]}}, "objects[0].distance.range_m"),
        ({"model": "cubesat", "pose": {"distribution": "spin"}}, "objects[0].pose.distribution"),
    ],
)
def test_a_bad_objects_entry_is_refused_naming_it(entry, message):
    with pytest.raises(ScgenError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_config(overrides={"objects": [entry]})


SEQUENCE = """
[sequence]
frames = 8
dt_s = 20.0

[[objects]]
model = "smallsat"
separation_m = [8.0, 12.0]

[[objects]]
model = "upper_stage"
"""


@functools.cache
def sequence_generator(folder: Path) -> Generator:
    config = folder / "sequence_objects.toml"
    config.write_text(SEQUENCE)
    return Generator.load(config=config, seed=2, resolution=RES, backend="mitsuba", quality="draft")


def test_each_object_of_a_sequence_flies_its_own_free_orbit_about_the_target(tmp_path_factory):
    """Each instance's centre of mass, seen from the target's in LVLH (through the camera's attitude the
    frames record), is a free HCW trajectory that does not drift: from frames 0 and 1 the state transition
    matrix predicts every later frame, and y0' = -2 n x0."""
    gen = sequence_generator(tmp_path_factory.mktemp("seq"))
    seq = gen.cfg["sequence"]
    scale = gen.model.diameter / seq["spacecraft_diameter_m"]
    centre = {k: mass_properties([mesh for _, mesh in m.parts]).centre_of_mass for k, m in gen.models.items()}
    for s in range(2):
        frames = gen.sequence(s)
        n = Orbit(frames[0].sequence.altitude_km * 1e3).n
        times = np.array([f.sequence.time_s for f in frames])
        for j, obj in enumerate(frames[0].objects):
            p = []
            for f in frames:
                R_lc = quat_to_matrix(np.asarray(f.sequence.camera_attitude))
                target = f.target.t_vec + f.target.R_mat @ centre[1]
                pose = f.objects[j].pose
                p.append(R_lc @ (pose.t_vec + pose.R_mat @ centre[obj.obj_id] - target) / scale)
            p = np.array(p)
            stm = hcw_stm(n, times[1] - times[0])
            v0 = np.linalg.solve(stm[:3, 3:], p[1] - stm[:3, :3] @ p[0])
            predicted = np.einsum(
                "kij,j->ki", hcw_stm(n, times - times[0])[:, :3], np.concatenate([p[0], v0])
            )
            # metres of tens of metres, through float64 poses and two solves: far below a millimetre
            assert np.abs(predicted - p).max() <= 1e-6 * np.abs(p).max()
            assert v0[1] == pytest.approx(-2 * n * p[0][0], abs=1e-9 * np.abs(v0).max() + 1e-12)
            assert np.linalg.norm(p, axis=1).min() > 4.0  # |y_c| / 2 of separation_m >= 8 m


def test_every_instance_of_a_sequence_is_labelled_exactly(tmp_path_factory):
    gen = sequence_generator(tmp_path_factory.mktemp("seq_labels"))
    surfaces = {k: trimesh.proximity.ProximityQuery(m.mesh) for k, m in gen.models.items()}
    checked = set()
    for sample in (gen.sample(i) for i in (0, 5, 8, 15)):
        for _, pose, obj_id, ann, alone in instances(sample):
            assert not (ann.mask_visib & ~ann.mask).any() and (ann.mask == (alone > 0)).all()
            vs, us = np.nonzero(ann.mask_visib)
            if len(us) < 10:
                continue
            C = ann.xyz[vs, us].astype(np.float64)
            err = reprojection_error(C, us, vs, sample.spec.camera, pose.R_mat, pose.t_vec)
            assert (err <= 0.5).mean() >= 0.99
            _, dist, _ = surfaces[obj_id].on_surface(C[:: max(1, len(C) // 200)])
            assert (dist <= SURFACE_TOL * gen.models[obj_id].diameter).mean() >= 0.99
            checked.add(obj_id)
    assert checked >= {2, 3}


def test_render_refuses_a_missing_object_model_in_one_line_and_writes_nothing(tmp_path):
    config = tmp_path / "objects.toml"
    config.write_text('[[objects]]\nmodel = "parts/servicer.glb"\n')
    out = tmp_path / "out"
    result = CliRunner().invoke(scgen_main, ["render", "--n", "1", "--out", str(out), "--backend", "mitsuba",
                                             "--config", str(config)])  # fmt: skip
    assert result.exit_code != 0
    line = result.output.strip().splitlines()[-1]
    assert line.startswith("Error:") and "objects[0].model" in line and "servicer.glb" in line
    assert not out.exists()


def test_through_a_lens_each_object_alone_is_its_whole_image_cast():
    """With lens distortion a straight edge's image bends past its corners' box: the cast of each object
    alone (over the pixels image_box keeps) equals a cast over every pixel of the image."""
    gen = Generator.load(config=EXAMPLE, seed=5, resolution=(240, 150), camera="speedplus", backend="mitsuba")
    raycast.start()
    checked = 0
    for i in range(3):
        spec = gen.scene(i)
        assert not spec.camera.pinhole
        for obj, alone in zip(spec.objects, objects_alone_depth(spec, gen.models), strict=True):
            model = gen.models[obj.obj_id]
            shape = raycast.place_mesh("whole", model.mesh.vertices, model.mesh.faces, obj.pose.R_mat,
                                       obj.pose.t_vec)  # fmt: skip
            _, whole = raycast.cast([shape], spec.camera, (0, 0, spec.camera.width, spec.camera.height))
            assert ((alone > 0) == (whole > 0)).all()
            checked += int((alone > 0).sum())
    assert checked > 0


def test_a_sequence_may_place_more_of_the_targets_own_model(tmp_path):
    """An `[[objects]]` entry naming the target's model adds instances of obj_id 1, each on its own orbit."""
    config = tmp_path / "more_of_the_target.toml"
    config.write_text('[sequence]\nframes = 3\ndt_s = 10.0\n\n[[objects]]\nmodel = "spacecraft"\ncount = 2\n')
    gen = Generator.load(config=config, seed=7, resolution=(160, 120), backend="mitsuba")
    frames = gen.sequence(0)
    assert sorted(gen.models) == [1] and all([o.obj_id for o in f.objects] == [1, 1] for f in frames)
