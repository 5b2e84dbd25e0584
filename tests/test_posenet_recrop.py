"""Re-crop from the network's own pose, and tracking along a sequence (posenet.predict.recrop, .track).

The tests' checkpoints train for 2 steps and have learned nothing, so what is tested of the network is the
wiring (each pass crops around the box of the pose before; eval's passes are predict's); the box update
itself is a pure function of a pose, tested at the ground-truth poses of real renders.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from posenet.cli import main
from posenet.data.boxes import boxes_from_gt, clip_box
from posenet.data.camera import make_camera, project
from posenet.data.crop import roi_from_box
from posenet.data.layout import scan_split
from posenet.data.object_model import load_object_model
from posenet.detection.detector import target_boxes
from posenet.evaluation.evaluate import evaluate
from posenet.navigation.estimate import state_from_camera
from posenet.navigation.noise import NoiseModel
from posenet.navigation.scene import sequence_frames
from posenet.predict.options import SAME_CROP_IOU
from posenet.predict.predictor import Predictor, Timings
from posenet.predict.recrop import box_iou, in_view, model_box, next_crop, projected_box
from posenet.predict.sources import dataset_frames, load_frame
from posenet.predict.track import DETECTOR, NONE, POSE, SEARCH_EVERY, TRACK, Tracker
from scgen.io import read_sequence_frames
from tests.posenet_helpers import cli_ok, tiny_pose_checkpoint
from tests.test_posenet_predict import TINY_DETECTOR

# The annotated bbox_obj spans the pixel centres the silhouette covers; the projected vertices' extent,
# rounded inwards to pixel centres, contains it exactly (the silhouette lies in their hull) and exceeds it
# where a part thinner than a pixel (a strut, an antenna tip) covers no centre at its end: by at most 2 px
# per edge on these fixtures' spacecraft (deterministic renders, not a timing), "to rounding".
EDGE_PX = 2.0


def _instances(root: Path, split: str = "test") -> list:
    return [i for i in scan_split(root, split, 1, lens=True) if i.px_count_visib > 0]


def _camera(inst):
    return make_camera(inst.K, inst.dist, inst.image_size)


def test_the_box_at_the_true_pose_is_the_true_box(dataset_dir: Path, sequence_dataset: Path):
    """projected_box at the ground-truth pose gives the annotated bbox_obj (to EDGE_PX, never inside it), also
    where the box reaches past the image, and model_box, of the convex hull's vertices only, the same box;
    so a re-crop from any box at a pose equal to the truth crops as training did, and moves a shifted box
    onto the true one."""
    for root in (dataset_dir, sequence_dataset):
        obj = load_object_model(root, 1, 4, 100)
        for inst in _instances(root, "test") + _instances(root, "train"):
            box = projected_box(obj.vertices, inst.R, inst.t, _camera(inst))
            assert box is not None and model_box(obj, inst.R, inst.t, _camera(inst)) == box  # the hull's
            x, y, w, h = inst.bbox_obj
            excess = np.array([x - box[0], y - box[1], box[0] + box[2] - x - w, box[1] + box[3] - y - h])
            assert excess.min() >= 0 and excess.max() <= EDGE_PX, (inst.key, box, inst.bbox_obj)
    obj, insts = load_object_model(dataset_dir, 1, 4, 100), _instances(dataset_dir)
    shifted = boxes_from_gt(insts, noise=0.2, seed=3)
    before = [box_iou(tuple(e["bbox"]), i.bbox_obj) for i, e in zip(insts, shifted, strict=True)]
    after = [box_iou(projected_box(obj.vertices, i.R, i.t, _camera(i)), i.bbox_obj) for i in insts]
    for inst, iou in zip(insts, after, strict=True):
        w, h = inst.bbox_obj[2:]  # every edge out by at most EDGE_PX
        assert iou >= w * h / ((w + 2 * EDGE_PX) * (h + 2 * EDGE_PX))
    assert np.mean(after) > np.mean(before)


def test_box_geometry():
    """IoU, clipping to the image and the share in view, on boxes worked by hand."""
    assert box_iou((0, 0, 10, 10), (0, 0, 10, 10)) == 1.0
    assert box_iou((0, 0, 10, 10), (5, 0, 10, 10)) == 50 / 150  # integer areas, one quotient: the same float
    assert box_iou((0, 0, 10, 10), (20, 0, 10, 10)) == 0.0
    assert clip_box((-5, 2, 10, 4), (8, 8)) == (0, 2, 5, 4)
    assert clip_box((9, 0, 3, 3), (8, 8)) is None
    assert in_view((-5, 0, 10, 8), (8, 8), 0.5) and not in_view((-6, 0, 10, 8), (8, 8), 0.5)  # 40, 32 of 80
    R, t = np.eye(3), np.array([0.0, 0.0, -1.0])
    assert projected_box(np.zeros((1, 3)), R, t, make_camera(np.eye(3))) is None  # behind the camera


def test_the_detector_learns_the_clipped_full_object_box(dataset_dir: Path):
    """target_boxes: bbox_obj clipped to the image, in pixel edges; a box past the border is cut there."""
    insts = _instances(dataset_dir, "train")
    boxes = target_boxes(insts)
    assert len(boxes) == len(insts)
    for inst, (x0, y0, x1, y1) in zip(insts, boxes, strict=True):
        # whole pixels clipped at whole-pixel borders: small integers, exact in the float32 edges
        assert (x0, y0, x1 - x0, y1 - y0) == clip_box(inst.bbox_obj, inst.image_size)
        assert 0 <= x0 < x1 <= inst.image_size[0] and 0 <= y0 < y1 <= inst.image_size[1]


def test_each_pass_crops_around_the_pose_before(dataset_dir: Path, pose_ckpt: Path):
    """Predictor(passes=2), the default: the second crop is projected_box of the first pass's pose (at
    --same-crop-iou 1, every time); passes=1 is the single pass, whose pose the two-pass run starts from.
    At the default gate the second pass runs exactly where that box overlaps the first by IoU < the gate."""
    one, two = Predictor.load(pose_ckpt, passes=1), Predictor.load(pose_ckpt, same_crop_iou=1.0)
    gated = Predictor.load(pose_ckpt)
    assert two.passes == gated.passes == 2 and gated.same_crop_iou == SAME_CROP_IOU
    for frame in dataset_frames(dataset_dir, "test", 1)[:3]:
        frame = load_frame(frame)
        first = one(frame.image, frame.camera, frame.box)
        assert first.crops == (frame.box,)
        # two's first pass is one's: the same network, crop and batch (1), so the same floats; the
        # re-crop is whole pixels of the training camera, which the dataset's frames were taken with
        # (map_box hands such a box back as it is): every comparison below is exact
        second = two(frame.image, frame.camera, frame.box)
        expected = projected_box(one.obj.vertices, first.R, first.t, one.camera)
        if expected is None:  # the untrained pose projects nowhere: the first pass's stands
            assert second.crops == (frame.box,) and np.array_equal(second.t, first.t)
            continue
        assert frame.camera.same_as(one.camera)
        assert len(second.crops) == 2 and second.box == frame.box
        assert second.crops[1] == expected
        assert second.to_json()["crops"] == [[round(v, 2) for v in expected]]
        kept = gated(frame.image, frame.camera, frame.box)
        if box_iou(expected, frame.box) < SAME_CROP_IOU:
            assert kept.crops == second.crops and np.array_equal(kept.t, second.t)
        else:  # the same crop again: the first pass's pose stands
            assert kept.crops == (frame.box,) and np.array_equal(kept.t, first.t)
        # next_crop, the gate itself: a box the pose's own is stops the passes, unless the gate is 1
        assert next_crop(one.obj, first.R, first.t, one.camera, expected, SAME_CROP_IOU) is None
        assert next_crop(one.obj, first.R, first.t, one.camera, expected, 1.0) == expected


def test_eval_passes_recrop_and_report_the_box_iou(dataset_dir: Path, pose_ckpt: Path, tmp_path: Path):
    """eval --passes: pass 1 on the boxes given (GT: IoU 1; noisy: under 1), then the re-crops; one IoU per
    pass in the JSON summary."""
    noisy = tmp_path / "noisy.json"
    noisy.write_text(json.dumps(boxes_from_gt(_instances(dataset_dir), noise=0.2, seed=1)))
    gt = evaluate(dataset_dir, pose_ckpt, workers=0, passes=2).summary
    assert gt["passes"] == 2 and len(gt["box_iou"]) == 2 and gt["box_iou"][0] == 1.0
    out = tmp_path / "eval.json"
    args = ["eval", "--data", dataset_dir, "--ckpt", pose_ckpt, "--boxes", noisy, "--passes", 3,
            "--same-crop-iou", 0.9]  # fmt: skip
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--workers", 0, "--json", out]])
    assert res.exit_code == 0, res.output
    summary = json.loads(out.read_text())
    assert gt["same_crop_iou"] == SAME_CROP_IOU and summary["same_crop_iou"] == 0.9
    assert len(summary["box_iou"]) == 3 and 0 < summary["box_iou"][0] < 1
    assert "crop box IoU with bbox_obj, per pass" in res.output


@pytest.fixture(scope="module")
def sequence_ckpt(sequence_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_pose_checkpoint(sequence_dataset, tmp_path_factory)


def test_the_latency_of_a_stage_run_twice_an_image_is_both_runs(dataset_dir: Path, pose_ckpt: Path):
    """With two passes the pose network runs twice an image, and the crop stage four times (the warp, the
    model's box at the first pose, each pass's crop): predict's per-image latency is each stage's total
    over the images."""
    predictor = Predictor.load(pose_ckpt, passes=2, same_crop_iou=1.0)  # every second pass runs
    frames = [load_frame(f) for f in dataset_frames(dataset_dir, "test", 1)[:2]]
    passes = sum(len(predictor(frame.image, frame.camera, frame.box).crops) for frame in frames)
    assert passes > len(frames)  # a re-crop ran (a pose projecting nowhere keeps its first pass)
    runs = {stage: len(ms) for stage, ms in predictor.timings.ms.items()}
    # per image: the warp and the one re-crop box (passes - 1 = 1), then a crop per pass that ran
    assert runs["pose_network"] == passes and runs["crop"] == 2 * len(frames) + passes
    per_image = predictor.timings.per_image_ms(len(frames))
    # np.sum and Python's sum of these few float64 runs differ by a few ulps (2.2e-16 each); 1e-12 is far
    # above that and far below a run left out or counted twice (each is a share of the total, not 1e-12)
    for stage, ms in predictor.timings.ms.items():
        assert per_image[stage] == pytest.approx(sum(ms) / len(frames), rel=1e-12)
    empty = Timings()
    assert empty.per_image_ms(0) == {}


def test_a_tracked_sequence_keeps_its_target(sequence_dataset: Path, sequence_ckpt: Path):
    """Along each rendered sequence, the filter started at frame k's labelled state (pose, velocity and
    angular velocity; the chaser's own state from metadata.csv) predicts frame k + 1, and the crop seeded
    there is the model's box at that prediction: HCW and Euler's equations are the dynamics scgen
    rendered with, so it is the true box to EDGE_PX (never inside it) and the true centre lies in the crop.
    The tracker then runs the real network on that box, with no detector run."""
    predictor = Predictor.load(sequence_ckpt, passes=1)  # one pass: the seed box is under test
    wide = {"rot": np.diag([np.radians(10.0) ** 2] * 3).tolist(), "t": np.diag([0.05**2] * 3).tolist()}
    white = {"rot": 0.0, "t": 0.0}  # nothing persistent: the filter takes the errors for white
    noise = NoiseModel([0.0], [wide["rot"]], [wide["t"]], [0.0], 0, {}, wide, white, white, 0.0)
    tracker = Tracker(predictor, noise, min_confidence=0.0)
    frames = {f.key: f for f in dataset_frames(sequence_dataset, "test", 1)}
    truth = {i.key: i for i in _instances(sequence_dataset)}
    order = read_sequence_frames(sequence_dataset)
    keys = sorted(frames, key=lambda k: (order[k].sequence_id, order[k].frame))
    pairs = [
        (a, b) for a, b in zip(keys, keys[1:], strict=False) if order[a].sequence_id == order[b].sequence_id
    ]
    assert len(pairs) >= 2
    for before, key in pairs:
        was, now, seq = truth[before], truth[key], order[before]
        assert seq.camera_attitude is not None  # the filter runs in LVLH on the chaser's own state
        tracker.reset(seq)
        motion = np.array(seq.velocity), np.array(seq.angular_velocity)
        start = state_from_camera(seq.time_s, was.R, was.t, *motion, sequence_frames(seq),
                                  tracker.body.centre_of_mass, 1e-12 * np.eye(12))  # fmt: skip
        tracker.filter.start_from(start, sequence_frames(seq))
        frame = load_frame(frames[key])
        at = (order[key].time_s, sequence_frames(order[key]))
        seed, source = tracker.seed(*at, frame.camera.for_image(now.image_size))
        assert source == TRACK and seed is not None
        x, y, w, h = now.bbox_obj
        excess = np.array([x - seed[0], y - seed[1], seed[0] + seed[2] - x - w, seed[1] + seed[3] - y - h])
        assert excess.min() >= -1e-6 and excess.max() <= EDGE_PX, (key, seed, now.bbox_obj)
        roi = roi_from_box(seed, now.image_size, predictor.pad_scale)
        centre = project(np.zeros((1, 3)), now.R, now.t, _camera(now))[0]
        assert np.all(np.abs(centre - roi.center) <= roi.scale / 2), (key, centre, roi)
        tracked = tracker(frame.image, frame.camera, *at)
        # the given box comes back as its own floats (Predictor: user_crops[0])
        assert tracked.source == TRACK and tracked.pose.box == seed and tracker.detections == 0
        assert tracked.estimate is not None and tracked.step.prior is not None


def test_predict_track_on_a_sequence_dataset(
    sequence_dataset: Path, sequence_ckpt: Path, tmp_path_factory: pytest.TempPathFactory
):
    """predict --track --data: the frames in time order with their sequence, frame and time; each
    sequence starts at the detector, and the printed count of detector runs is the records'; each
    sequence's overlays are a video of its frames at the images' size."""
    root = tmp_path_factory.mktemp("track")
    (root / "tiny.yaml").write_text(TINY_DETECTOR)
    data = ["--data", sequence_dataset]
    cli_ok("train-detector", *data, "--out", root / "det", "--config", root / "tiny.yaml", "--max-steps", 1)
    ckpt = root / "last.pt"  # a copy: the shared checkpoint stays read-only, with no noise beside it
    shutil.copy(sequence_ckpt, ckpt)
    track = ("predict", *data, "--ckpt", ckpt, "--detector", root / "det" / "last.pt", "--track",
             "--min-score", 0, "--out", root / "pred")  # fmt: skip
    refused = CliRunner().invoke(main, [str(a) for a in track])
    assert refused.exit_code != 0 and "posenet calibrate" in refused.output and not (root / "pred").exists()
    cli_ok(
        "calibrate", *data, "--ckpt", ckpt, "--split", "train", "--min-confidence", 0
    )  # untrained: never confident
    output = cli_ok(*track)
    records = [json.loads(line) for line in (root / "pred" / "predictions.jsonl").read_text().splitlines()]
    order = read_sequence_frames(sequence_dataset)
    seen = [order[r["scene_id"], r["im_id"]] for r in records]
    assert [(r["sequence_id"], r["frame"], r["time_s"]) for r in records] == sorted(
        (s.sequence_id, s.frame, s.time_s) for s in seen
    )
    assert all(r["box_source"] in (TRACK, POSE, DETECTOR, NONE) for r in records)
    for i, r in enumerate(records):  # no pose between searches only after one that found nothing
        if r["box_source"] == NONE:
            searched = [p for p in records[max(0, i - SEARCH_EVERY) : i] if p["box_source"] == DETECTOR]
            assert searched and "no_detection" in searched[-1]["flags"]
    firsts = [r for i, r in enumerate(records) if i == 0 or records[i - 1]["sequence_id"] != r["sequence_id"]]
    assert all(r["box_source"] == DETECTOR and r["filter"] is None for r in firsts)
    # the filter starts at the first of two measurements that agree (the untrained network's noise,
    # calibrated, is wide enough for any two): online from the second frame on, and the smoother, which
    # runs over the filter's steps, from the first
    for i, r in enumerate(records):
        assert (r["filter"] is None) == (r in firsts)
        assert r["smoothed"] is not None or (r in firsts and records[i + 1]["filter"] is None)
        if r["filter"] is not None:
            for key, sigma in (("t", "t"), ("velocity", "velocity"), ("omega", "omega_deg")):
                assert len(r["filter"][key]) == 3 and len(r["filter"]["sigma"][sigma]) == 3
            assert {"coasting", "rejected", "twin", "nis"} <= set(r["filter"])
    ran = sum(r["box_source"] == DETECTOR for r in records)
    assert f"the detector ran on {ran} of {len(records)} inputs" in output
    for sequence_id in {r["sequence_id"] for r in records}:
        video = cv2.VideoCapture(str(root / "pred" / "sequences" / f"{sequence_id:06d}.mp4"))
        frames = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
        size = (int(video.get(cv2.CAP_PROP_FRAME_WIDTH)), int(video.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        video.release()
        assert frames == sum(r["sequence_id"] == sequence_id for r in records)
        camera = json.loads((sequence_dataset / "camera.json").read_text())
        assert size == (camera["width"], camera["height"])
    assert not list((root / "pred" / "sequences").glob("*.partial.mp4"))


def test_eval_refuses_passes_with_by_factor(tmp_path: Path):
    """--by-factor compares checkpoints over groups at one pass; --passes there is refused, not ignored."""
    args = ["eval", "--data", tmp_path, "--ckpt", tmp_path / "a.pt", "--by-factor", tmp_path / "g.json"]
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--passes", 2]])
    assert res.exit_code != 0 and "--passes re-crops the estimates of one evaluation" in res.output
