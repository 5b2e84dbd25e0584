"""Several objects per image on a rendered multi-object dataset: the detector of every object, predict
with one pose network per object, eval per object and overall. Untrained networks: the assertions are on
structure and on what no training changes (labels, boxes, ids), never on accuracy."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from posenet_helpers import RESOLUTION, TINY_POSE, cli_ok

from posenet.checkpoint import load_checkpoint
from posenet.cli import main
from posenet.data.camera import make_camera
from posenet.data.layout import object_ids
from posenet.detection.detect import detect, detector_dataset, detector_obj_ids, load_detector
from posenet.detection.detector import DetectionDataset, image_groups, labelled_boxes, load_detector_config
from posenet.predict.objects import ObjectsPredictor
from posenet.predict.sources import dataset_frames, load_frame
from scgen.run.runner import RenderJob, run_render

ROOT = Path(__file__).resolve().parents[1]
TINY_DETECTOR = "preset: cpu\noptim: {batch_size: 4}\n"


@pytest.fixture(scope="module")
def multi(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """20 images of the servicer-and-client config (obj 1 the target, 2 and 3 beside it), a detector of
    every object and tiny pose networks of objects 1 and 2, each trained 2 steps."""
    root = tmp_path_factory.mktemp("multi")
    data = root / "data"
    job = RenderJob(out=data, n=20, seed=3, backend="mitsuba", quality="draft", resolution=RESOLUTION,
                    config_path=ROOT / "examples" / "servicer_client.toml")  # fmt: skip
    run_render(job, progress=False)
    (root / "tiny.yaml").write_text(TINY_POSE)
    (root / "det.yaml").write_text(TINY_DETECTOR)
    cli_ok("train-detector", "--data", data, "--out", root / "det", "--config", root / "det.yaml",
            "--max-steps", 2)  # fmt: skip
    out = {"data": data, "detector": root / "det" / "last.pt"}
    for k in (1, 2):
        cli_ok("train", "--data", data, "--out", root / f"pose{k}", "--config", root / "tiny.yaml",
                "--max-steps", 2, "--obj-id", k)  # fmt: skip
        out[f"pose{k}"] = root / f"pose{k}" / "last.pt"
    return out


def test_the_detector_learns_every_object_as_a_class(multi: dict[str, Path]) -> None:
    """Without --obj-id the classes are models_info's objects, recorded in the checkpoint; each training
    item labels its boxes with its instances' classes; every box detected names one of those objects."""
    data = multi["data"]
    ids = object_ids(data)
    assert len(ids) >= 2 and ids[0] == 1
    model, state = load_detector(multi["detector"], torch.device("cpu"))
    assert detector_obj_ids(state) == ids and state["config"]["obj_ids"] == ids
    assert model.head.classification_head.num_classes == len(ids) + 1
    images = image_groups(data, "test", ids)
    item = DetectionDataset(
        images, load_detector_config(str(multi["detector"].parent / "config.yaml")), False
    )
    for index, insts in enumerate(images):
        want = labelled_boxes(insts, ids)
        _, target = item[index]
        assert np.array_equal(target["boxes"].numpy(), want[:, :4])
        assert target["labels"].tolist() == want[:, 4].astype(int).tolist()
        assert {ids[k - 1] for k in target["labels"].tolist()} <= {i.obj_id for i in insts}
    dets = detect(model, detector_dataset(state, images), torch.device("cpu"))
    found = [f for d in dets for f in d.found]
    assert found and {f.obj_id for f in found} <= set(ids)
    for d in dets:  # the best box is the first kept; one object's detection is its own best box
        assert d.box == (d.found[0].box if d.found else None)
        for k in ids:
            mine = [f for f in d.found if f.obj_id == k]
            assert d.of(k).box == (mine[0].box if mine else None)


def test_obj_id_keeps_one_class_and_an_old_checkpoint_reads_as_its_object(multi: dict[str, Path]) -> None:
    """--obj-id K is today's one-class detector; a checkpoint without a class list is its config's obj_id."""
    cfg = load_detector_config("cpu", 2, object_ids(multi["data"]))
    assert cfg.classes() == [2] and cfg.obj_ids == []
    assert load_detector_config("cpu", None, [1]).classes() == [1]  # a one-object dataset: as before
    state = load_checkpoint(multi["detector"], kind="detector")
    old = {k: v for k, v in state.items() if k != "obj_ids"} | {"config": {**state["config"], "obj_id": 4}}
    assert detector_obj_ids(old) == [4]


def test_predict_poses_each_object_with_its_own_network(multi: dict[str, Path], tmp_path: Path) -> None:
    """Two --pose checkpoints: every record names obj 1 or 2 (or none for an image without a detection),
    each posed record's box is a detector box of that object, and results.csv holds a row per posed
    object, with one time per image."""
    out = tmp_path / "pred"
    cli_ok("predict", "--data", multi["data"], "--split", "test", "--pose", multi["pose1"], "--pose",
            multi["pose2"], "--detector", multi["detector"], "--out", out, "--format", "bop", "--no-vis",
            "--min-score", 0, "--device", "cpu")  # fmt: skip
    records = [json.loads(line) for line in (out / "predictions.jsonl").read_text().splitlines()]
    assert {r["obj_id"] for r in records} <= {1, 2, None}
    posed = [r for r in records if r["R"] is not None]
    assert posed and all(r["obj_id"] in (1, 2) for r in posed)
    predictor = ObjectsPredictor.load([multi["pose1"], multi["pose2"]], multi["detector"], min_score=0.0)
    assert predictor.obj_ids == [1, 2]
    for frame in dataset_frames(multi["data"], "test", 1)[:3]:
        frame = load_frame(frame)
        assert frame.image is not None and frame.camera is not None
        found = predictor.detect(frame.image, frame.camera)
        for r in (r for r in posed if (r["scene_id"], r["im_id"]) == frame.key):
            assert any(k == r["obj_id"] and np.allclose(b, r["box"], atol=0.02) for k, b, _ in found)
    rows = list(csv.DictReader(io.StringIO((out / "results.csv").read_text())))
    assert len(rows) == len(posed) and {int(r["obj_id"]) for r in rows} <= {1, 2}
    times: dict[tuple[str, str], set[str]] = {}
    for r in rows:
        times.setdefault((r["scene_id"], r["im_id"]), set()).add(r["time"])
    assert all(len(t) == 1 for t in times.values())


def test_an_object_without_a_pose_network_is_skipped_with_one_warning(multi: dict[str, Path]) -> None:
    """A box of obj 3, which no checkpoint poses, gives no pose and one warning however often it comes."""
    predictor = ObjectsPredictor.load([multi["pose1"], multi["pose2"]], multi["detector"])
    edges = np.array([100.0, 80.0, 160.0, 140.0])
    predictor.detector = lambda rgb: [(edges, 0.9, 3), (edges, 0.8, 2)]
    said: list[str] = []
    predictor.warn = said.append
    image = np.zeros((RESOLUTION[1], RESOLUTION[0], 3), np.uint8)
    camera = make_camera(np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]]), None, RESOLUTION)
    for _ in range(2):
        poses = predictor(image, camera)
        assert [p.obj_id for p in poses] == [2] and poses[0].pose.score == 0.8
    assert len(said) == 1 and "object 3" in said[0]


def test_predict_refuses_several_pose_checkpoints_without_the_detector(multi: dict[str, Path]) -> None:
    args = ["predict", "--data", multi["data"], "--pose", multi["pose1"], "--pose", multi["pose2"]]
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--out", "/tmp/never_written_multi"]])
    assert res.exit_code == 1 and "give --detector" in res.output


def test_eval_scores_each_object_and_all(multi: dict[str, Path], tmp_path: Path) -> None:
    """One summary per checkpoint's object and an overall one whose instances are theirs summed."""
    out = tmp_path / "eval.json"
    text = cli_ok("eval", "--data", multi["data"], "--ckpt", multi["pose1"], "--ckpt", multi["pose2"],
                   "--workers", 0, "--json", out, "--bop-csv", tmp_path / "eval.csv")  # fmt: skip
    summary = json.loads(out.read_text())
    assert [o["obj_id"] for o in summary["objects"]] == [1, 2]
    assert summary["overall"]["n"] == sum(o["n"] for o in summary["objects"]) > 0
    assert "obj 1" in text and "obj 2" in text and " all" in text
    rows = list(csv.DictReader(io.StringIO((tmp_path / "eval.csv").read_text())))
    assert {int(r["obj_id"]) for r in rows} == {1, 2}
