"""The detector and its box files end to end on a rendered dataset: learning, stored boxes, misses."""

from __future__ import annotations

import json
import math
import re
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from budget_checks import assert_the_decay_ends_at_the_budget
from click.testing import CliRunner
from float_bounds import forward_rel
from posenet_helpers import cli_ok

from posenet.checkpoint import load_checkpoint
from posenet.cli import main
from posenet.data.boxes import box_edges, edges_box
from posenet.detection.detect import (
    Detection,
    box_metrics,
    box_scores,
    detect,
    detector_dataset,
    load_detector,
)
from posenet.detection.detector import (
    DetectionDataset,
    build_detector,
    detector_config_from_dict,
    hflip,
    image_groups,
    load_detector_config,
    paste_target,
    target_boxes,
    visible_boxes,
)
from posenet.detection.segmenter import JOIN_SHARE, mask_box
from posenet.evaluation.evaluate import by_factor, evaluate
from posenet.evaluation.metrics import headline_add
from posenet.predict.predictor import detector_box
from scgen.cli import main as scgen_main

MASK = "mask-timm"


@pytest.fixture(scope="module")
def detector_run(dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The cpu preset as a user gets it (its pinned thread count gives the same losses every run)."""
    root = tmp_path_factory.mktemp("detector")
    cli_ok("train-detector", "--data", dataset_dir, "--out", root / "run", "--config", "cpu")
    return root / "run"


def test_detector_learns_its_boxes(dataset_dir: Path, detector_run: Path) -> None:
    """Mean IoU with the box it learns (target_boxes: bbox_obj clipped to the image) on the training
    images: trained well above an untrained network and above the best fixed box (the mean training box)."""
    cpu = torch.device("cpu")
    images = image_groups(dataset_dir, "train", 1)
    gt = [target_boxes(i) for i in images]
    model, state = load_detector(detector_run / "last.pt", cpu)
    trained = box_metrics(detect(model, detector_dataset(state, images), cpu), gt)
    torch.manual_seed(0)
    untrained = box_metrics(
        detect(build_detector(state["model_config"]), detector_dataset(state, images), cpu), gt
    )
    mean_box = tuple(float(v) for v in np.concatenate(gt).mean(0))
    fixed = box_metrics([Detection(i[0].key, mean_box, 1.0, 0.0) for i in images], gt)
    print(f"mean IoU: trained {trained['mean_iou']:.3f}, untrained {untrained['mean_iou']:.3f}, "
          f"fixed box {fixed['mean_iou']:.3f}")  # fmt: skip
    assert trained["mean_iou"] >= 2 * untrained["mean_iou"]
    assert trained["mean_iou"] >= 1.5 * fixed["mean_iou"]
    assert (detector_run / "best.pt").is_file() and (detector_run / "tb").is_dir()


def test_detections_are_scored_on_the_box_the_detector_learns(dataset_dir: Path, detector_run: Path) -> None:
    """box_scores: IoU with target_boxes (bbox_obj clipped, what the detector learns and the pose network
    is cropped around), bbox_visib's beside it; a detection at the one box scores 1 there and less at the
    other where the two differ (occluded or clipped targets). Training selects best.pt on those scores."""
    images = [i for i in image_groups(dataset_dir, "train", 1) if len(target_boxes(i))]
    own, visib = [target_boxes(i) for i in images], [visible_boxes(i) for i in images]

    def at(boxes: list[np.ndarray]) -> list[Detection]:
        return [
            Detection(i[0].key, tuple(map(float, b[0])), 1.0, 0.0) for i, b in zip(images, boxes, strict=True)
        ]

    # some targets are partly hidden, so that the two boxes differ
    assert any(not np.array_equal(a, b) for a, b in zip(own, visib, strict=True))
    # the boxes are whole pixels, so a box's IoU with itself is computed exactly: 1; with another box, less
    on_own, on_visib = box_scores(at(own), images), box_scores(at(visib), images)
    assert on_own["mean_iou"] == 1.0 > on_own["visib_mean_iou"]
    assert on_visib["visib_mean_iou"] == 1.0 > on_visib["mean_iou"]
    state = load_checkpoint(detector_run / "best.pt", kind="detector")
    assert set(state["val"]) == set(on_own) and state["best_val_iou"] == state["val"]["mean_iou"]


def test_stored_detector_boxes_reused_byte_for_byte(
    dataset_dir: Path, detector_run: Path, pose_ckpt: Path, tmp_path: Path
) -> None:
    boxes = tmp_path / "boxes.json"
    out = cli_ok("boxes", "--data", dataset_dir, "--split", "test", "--detector", detector_run / "last.pt",
                  "--out", boxes)  # fmt: skip
    assert "detector" in out
    entries = json.loads(boxes.read_text())
    assert all(e["source"].startswith("detector") for e in entries)
    before = boxes.read_bytes()
    runs = []
    for name in ("a", "b"):
        printed = cli_ok("eval", "--data", dataset_dir, "--ckpt", pose_ckpt, "--boxes", boxes,
                          "--json", tmp_path / f"{name}.json", "--workers", 0)  # fmt: skip
        assert f"boxes: {boxes} (detector:" in printed
        runs.append(json.loads((tmp_path / f"{name}.json").read_text()))
    assert boxes.read_bytes() == before
    for r in runs:
        r.pop("latency_ms"), r.pop("fps")
    assert runs[0] == runs[1]
    preds = [(tmp_path / f"{n}.predictions.jsonl").read_text() for n in "ab"]
    strip = [
        [{k: v for k, v in json.loads(ln).items() if k != "time_s"} for ln in p.splitlines()] for p in preds
    ]
    assert strip[0] == strip[1]


def test_miss_is_a_failure_for_every_metric(dataset_dir: Path, pose_ckpt: Path, tmp_path: Path) -> None:
    boxes = tmp_path / "gt.json"
    assert "ground-truth" in cli_ok("boxes", "--data", dataset_dir, "--out", boxes)
    entries = json.loads(boxes.read_text())
    missed = entries[0]
    entries[0] = {**missed, "bbox": [], "score": 0.0, "source": "detector:test"}
    with_miss = tmp_path / "miss.json"
    with_miss.write_text(json.dumps(entries))
    full = evaluate(dataset_dir, pose_ckpt, boxes=boxes, workers=0)
    res = evaluate(dataset_dir, pose_ckpt, boxes=with_miss, workers=0)
    assert res.summary["n"] == full.summary["n"] and res.summary["missed"] == 1
    key = (missed["scene_id"], missed["image_id"])
    rec = next(r for r in res.records if (r["scene_id"], r["im_id"]) == key)
    assert rec["missed"] and rec["R"] is None
    assert all(rec[k] == math.inf for k in ("re_deg", "te_m", "add_m", "adds_m", "mssd_m", "esa"))
    key_add, _ = headline_add(res.summary["symmetric"])
    others = [r for r in full.records if (r["scene_id"], r["im_id"]) != key]
    # a share of counted instances: the same integer count over the same n, so the same float
    assert res.summary["add_0.02m"] == sum(r[key_add] < 0.02 for r in others) / len(full.records)
    for k in ("re_deg", "te_m", "esa"):  # the means are over the estimated instances
        assert res.summary[k] == pytest.approx(np.mean([r[k] for r in others]))
    written = tmp_path / "miss_eval.json"
    cli_ok("eval", "--data", dataset_dir, "--ckpt", pose_ckpt, "--boxes", with_miss, "--json", written,
            "--workers", 0)  # fmt: skip
    lines = written.with_suffix(".predictions.jsonl").read_text().splitlines()
    line = next(ln for ln in lines if (json.loads(ln)["scene_id"], json.loads(ln)["im_id"]) == key)
    assert "Infinity" not in line and json.loads(line)["re_deg"] is None  # standard JSON
    assert "ground truth" in evaluate(dataset_dir, pose_ckpt, workers=0).summary["boxes"]


def test_by_factor_with_a_box_file_gives_the_gap_to_gt_boxes(
    dataset_dir: Path, pose_ckpt: Path, tmp_path: Path
) -> None:
    groups = tmp_path / "groups.json"
    res = CliRunner().invoke(scgen_main, ["stats", str(dataset_dir), "--sample-groups", "3", "--groups-out",
                                          str(groups)])  # fmt: skip
    assert res.exit_code == 0, res.output
    boxes = tmp_path / "gt.json"
    cli_ok("boxes", "--data", dataset_dir, "--out", boxes)
    on_gt = by_factor(dataset_dir, [pose_ckpt], groups, workers=0)
    with_file = by_factor(dataset_dir, [pose_ckpt], groups, boxes=boxes, workers=0)
    assert "groups_gt_boxes" not in on_gt and with_file["groups_gt_boxes"] == on_gt["groups"]
    assert with_file["groups"] == on_gt["groups"]  # the file holds the GT boxes themselves
    printed = cli_ok("eval", "--data", dataset_dir, "--ckpt", pose_ckpt, "--by-factor", groups, "--boxes",
                      boxes, "--workers", 0)  # fmt: skip
    assert f"boxes: {boxes} (gt)" in printed and "gdrnet vs GT boxes (pp)" in printed
    assert "+0.00" in printed and "illumination/" in printed


def test_copy_paste_and_mirror_move_the_target_with_its_box(dataset_dir: Path) -> None:
    """At scale 1 the pasted pixels are the donor's target (its whole-object mask), inside the appended box
    (the donor's target_boxes) and clear of the image's own; mirroring maps a box onto the mirrored pixels."""
    donor = next(i for i in image_groups(dataset_dir, "train", 1) if i[0].px_count_visib > 50)
    donor_img = cv2.cvtColor(cv2.imread(str(donor[0].rgb)), cv2.COLOR_BGR2RGB).astype(np.float32) / 255
    own = np.float32([[0, 0, 20, 20]])
    canvas = np.zeros_like(donor_img)
    out, boxes = paste_target(canvas, own, donor, np.random.default_rng(0), (1.0, 1.0))
    assert len(boxes) == 2 and np.array_equal(boxes[0], own[0])
    x0, y0, x1, y1 = (int(v) for v in target_boxes(donor[:1])[0])
    px, py, qx, qy = (int(v) for v in boxes[1])
    assert (qx - px, qy - py) == (x1 - x0, y1 - y0) and (px >= 20 or py >= 20)
    mask = cv2.imread(str(donor[0].mask), cv2.IMREAD_GRAYSCALE)[y0:y1, x0:x1] > 0
    assert np.array_equal(out[py:qy, px:qx][mask], donor_img[y0:y1, x0:x1][mask])
    assert not out[:py].any() and not out[qy:].any() and not out[:, :px].any() and not out[:, qx:].any()
    flipped, fboxes = hflip(out, boxes)
    fx0, fy0, fx1, fy1 = (int(v) for v in fboxes[1])
    assert np.array_equal(flipped[fy0:fy1, fx0:fx1], out[py:qy, px:qx][:, ::-1])


def _shown(dataset_dir: Path) -> list:
    return [i for i in image_groups(dataset_dir, "train", 1) if i[0].px_count_visib > 50]


def test_the_mask_box_of_a_visible_mask_is_its_bbox_visib(dataset_dir: Path) -> None:
    """A perfect mask gives scgen's bbox_visib to the pixel edge; cutting the target in two with a
    background stripe (an occluder) keeps one box; a weaker blob far away does not move it."""
    for insts in _shown(dataset_dir)[:6]:
        mask = (cv2.imread(str(insts[0].mask_visib), cv2.IMREAD_GRAYSCALE) > 0).astype(np.float32)
        want = visible_boxes(insts)[0]
        box, score = mask_box(mask, 0.3)
        assert np.array_equal(box, want) and score == 1.0
        x0, y0, x1, y1 = (int(v) for v in want)
        cut = mask.copy()
        cut[:, (x0 + x1) // 2 : (x0 + x1) // 2 + 2] = 0  # narrower than JOIN_SHARE of the diagonal
        assert JOIN_SHARE * math.hypot(*mask.shape) > 2
        assert np.array_equal(mask_box(cut, 0.3)[0], want)
        far = mask.copy()
        fx = 0 if x0 > mask.shape[1] - x1 else mask.shape[1] - 3
        fy = 0 if y0 > mask.shape[0] - y1 else mask.shape[0] - 3
        far[fy : fy + 3, fx : fx + 3] = 0.9  # a 3x3 false blob in the corner farthest from the target
        assert np.array_equal(mask_box(far, 0.3)[0], want)
    assert mask_box(np.full((24, 32), 0.2, np.float32), 0.3) is None  # nothing reaches the threshold


def test_the_training_mask_moves_with_the_image_and_its_boxes(dataset_dir: Path) -> None:
    """The mask network's training items: after copy-paste, zoom, mirror and colour, the mask's extent
    about each target box is that box to interpolation's pixel, and the mask sits on the image's own
    pixels (what it covers is not the black zoom border)."""
    cfg = detector_config_from_dict({"preset": "cpu", "arch": MASK})
    cfg.paste_prob = cfg.zoom_prob = cfg.flip_prob = cfg.color_prob = 1.0
    data = DetectionDataset(_shown(dataset_dir), cfg, train=True, seed=3)
    for index in range(6):
        image, target = data[index]
        mask = target["masks"][0].numpy()
        for box in target["boxes"].numpy():  # the image's own target, then any pasted one
            x0, y0, x1, y1 = (int(v) for v in np.round(box))
            ys, xs = np.nonzero(mask[max(0, y0 - 2) : y1 + 2, max(0, x0 - 2) : x1 + 2])
            extent = (
                np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1])
                + [max(0, x0 - 2), max(0, y0 - 2)] * 2
            )
            assert np.abs(extent - box).max() <= 1.5
        assert image.shape[1:] == mask.shape and image.numpy()[:, mask > 0].max() > 0


def test_the_mask_detector_trains_and_runs_in_onnxruntime(dataset_dir: Path, tmp_path: Path) -> None:
    """mask-timm through train-detector (one step: the loop is FCOS's, whose learning is tested above; its
    own is measured in docs/posenet-research.md) into a checkpoint; exported, onnxruntime's probabilities
    equal torch's and give the same boxes."""
    from posenet.export.onnx_export import (
        MaskProbabilities,
        export_detector_onnx,
        onnx_session,
        run_detector_onnx,
    )

    # a low threshold, so the one-step network's faint mask still gives boxes to compare
    (tmp_path / "mask.yaml").write_text(
        f"preset: cpu\narch: {MASK}\nscore_thresh: 0.01\noptim: {{threads: 1}}\n"
    )
    cli_ok("train-detector", "--data", dataset_dir, "--out", tmp_path / "run", "--config",
            tmp_path / "mask.yaml", "--max-steps", 1)  # fmt: skip
    model, state = load_detector(tmp_path / "run" / "last.pt", torch.device("cpu"))
    graph = tmp_path / "mask.onnx"
    export_detector_onnx(model, graph, (320, 240), state["model_config"]["score_thresh"])
    session = onnx_session(graph)
    rel = forward_rel(model)
    boxed = 0
    for insts in image_groups(dataset_dir, "train", 1)[:4]:
        rgb = cv2.cvtColor(cv2.imread(str(insts[0].rgb)), cv2.COLOR_BGR2RGB).astype(np.float32) / 255
        image = torch.from_numpy(rgb.transpose(2, 0, 1))[None]
        with torch.inference_mode():
            want = MaskProbabilities(model)(image)[0].numpy()
            logits = float(model.logits(image).abs().max())
            on_torch = model([image[0]])[0]
        (got,) = session.run(None, {"image": image.numpy()})
        # onnxruntime sums in another order: a logit moves by float_bounds' rel of the logits' scale, a
        # probability by at most a quarter of that (the sigmoid's slope)
        assert np.abs(got[0] - want).max() <= rel * logits / 4
        on_onnx = run_detector_onnx(session, rgb)
        assert (on_onnx is None) == (len(on_torch["boxes"]) == 0)
        if on_onnx is not None:
            boxed += 1
            # a pixel at the threshold may fall either side of it on another runtime's rounding
            assert np.abs(on_onnx[0] - on_torch["boxes"][0].double().numpy()).max() <= 1
    assert boxed


def test_minutes_fit_the_detector_schedule_to_the_budget(dataset_dir: Path, tmp_path: Path) -> None:
    """train-detector --minutes: the schedule is fitted while it runs, its decay ends at the budget; a
    resumed run keeps that schedule (not its config's epochs) and cannot take a budget (one line)."""
    (tmp_path / "tiny.yaml").write_text(
        "preset: cpu\npretrained: null\nfpn_channels: 32\nhead_convs: 1\nmin_size: 120\nmax_size: 160\n"
        "optim: {threads: 1, warmup_iters: 2, epochs: 500}\n"  # small and quick: many steps in the budget
    )
    run = tmp_path / "run"
    tic = time.perf_counter()
    out = cli_ok("train-detector", "--data", dataset_dir, "--out", run, "--config", tmp_path / "tiny.yaml",
                  "--minutes", 0.4)  # fmt: skip
    wall = time.perf_counter() - tic
    fitted = re.search(r"schedule fitted to (\d+) steps", out)
    assert fitted, out
    total = int(fitted[1])
    rows = [json.loads(ln) for ln in (run / "train_log.jsonl").read_text().splitlines()]
    schedule = torch.load(run / "last.pt", weights_only=False)["schedule_steps"]
    anneal_point = load_detector_config(str(tmp_path / "tiny.yaml")).optim.anneal_point
    assert_the_decay_ends_at_the_budget(rows, total, schedule, anneal_point)
    # it stops at the budget or at its schedule's end, never before both; past the budget by at most the
    # step under way, then the last checkpoint and its val scoring
    assert wall >= 24.0 or rows[-1]["step"] == schedule
    assert wall < 24.0 + rows[-1]["step_s"] + 15.0
    cli_ok("train-detector", "--data", dataset_dir, "--out", run, "--resume", "--max-steps", schedule + 2)
    last = json.loads((run / "train_log.jsonl").read_text().splitlines()[-1])
    assert last["step"] == schedule  # the fitted schedule's end, not past it toward the config's 500 epochs
    res = CliRunner().invoke(main, ["train-detector", "--data", str(dataset_dir), "--out", str(run),
                                    "--resume", "--minutes", "1"])  # fmt: skip
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1
    assert "--minutes fits a new run's whole schedule" in res.output


def test_the_light_preset_runs_the_cpu_network_at_half_the_side_with_two_conv_heads() -> None:
    """`--config light`: the cpu preset's FCOS at 160x120 with two conv layers a head branch (a third of
    its time an image, docs/benchmarks.md); its checkpoint's config reloads to the same preset."""
    light, cpu = load_detector_config("light"), load_detector_config("cpu")
    assert detector_config_from_dict(light.to_dict()) == light
    assert light.optim == cpu.optim and light.pretrained == cpu.pretrained
    nets = {}
    for name, cfg in (("light", light), ("cpu", cpu)):
        net = build_detector(cfg.model_dict(), pretrained=None).eval()
        sizes = []
        net.backbone.register_forward_hook(lambda _m, args, _out, sizes=sizes: sizes.append(args[0].shape))
        with torch.inference_mode():
            net([torch.rand(3, 240, 320)])
        convs = [m for m in net.head.classification_head.conv if isinstance(m, torch.nn.Conv2d)]
        nets[name] = (tuple(sizes[0][-2:]), len(convs))
    # torchvision's transform resizes to the short side min_size (long side <= max_size), padded to 32
    assert nets == {"light": ((128, 160), 2), "cpu": ((256, 320), 4)}


def test_a_detector_s_edges_give_the_box_of_the_pixels_it_found() -> None:
    """Detectors give pixel edges where pixel i spans [i, i + 1) (torchvision's boxes; mask_box below), the
    convention they learn (target_boxes). The box predict crops around is the box of those pixels, the one
    `posenet boxes --detector` writes (detection_entries): a target over pixels x 30..44, y 10..19 is
    [30, 10, 15, 10], not half a pixel off."""
    prob = np.zeros((48, 64))
    prob[10:20, 30:45] = 0.9
    edges, score = mask_box(prob, 0.1)
    assert detector_box(edges, score) == ((30.0, 10.0, 15.0, 10.0), 0.9)
    assert edges_box(box_edges((30.0, 10.0, 15.0, 10.0))) == (30.0, 10.0, 15.0, 10.0)
