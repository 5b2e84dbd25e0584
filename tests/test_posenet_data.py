"""The data pipeline on a real rendered dataset: items, targets, augmentation, sampler, boxes."""

from __future__ import annotations

import dataclasses
import itertools
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from click.testing import CliRunner
from posenet_helpers import occluded_dataset, tiny_pose_checkpoint

from posenet.cli import main
from posenet.config import DataConfig, smoke_config
from posenet.data import EpochSampler, open_split
from posenet.data.boxes import read_boxes
from posenet.data.crop import box_center, crop
from posenet.data.dataset import PoseDataset, region_labels
from posenet.data.io import read_mask
from posenet.data.layout import Instance
from posenet.data.object_model import farthest_point_sampling, load_object_model
from posenet.errors import PosenetError


def no_aug(**changes):
    cfg = smoke_config()
    return dataclasses.replace(
        cfg.data, color_prob=0.0, bg_prob=0.0, dzi_prob=0.0, **changes
    ), cfg.model_config()


def test_training_item_shapes_and_ranges(dataset_dir: Path) -> None:
    cfg = smoke_config()
    mc = cfg.model_config()
    ds = open_split(dataset_dir, "train", cfg.data, mc, train=True)
    R, r = mc.input_res, mc.output_res
    item = ds[(0, 0)]
    shapes = {k: tuple(v.shape) for k, v in item.items()}
    assert shapes["roi_img"] == (3, R, R) and shapes["roi_coord2d"] == (2, r, r)
    assert shapes["roi_xyz"] == (3, r, r) and shapes["roi_mask_visib"] == shapes["roi_mask_full"] == (1, r, r)
    assert shapes["roi_region"] == (r, r) and shapes["site"] == (3,)
    assert float(item["roi_img"].min()) >= 0.0 and float(item["roi_img"].max()) <= 1.0
    vis = item["roi_mask_visib"][0] > 0
    assert vis.any()
    assert bool((item["roi_mask_full"][0][vis] > 0).all()), "visible must lie inside full"
    xyz = item["roi_xyz"].permute(1, 2, 0)[vis]
    assert float(xyz.min()) >= -1e-3 and float(xyz.max()) <= 1 + 1e-3
    assert bool((item["roi_region"][vis] > 0).all()) and bool((item["roi_region"][~vis] == 0).all())
    assert int(item["roi_region"].max()) <= mc.num_regions


def test_region_labels_are_nearest_fps_centres(dataset_dir: Path) -> None:
    cfg, mc = no_aug()
    ds = open_split(dataset_dir, "train", cfg, mc, train=True)
    centres = ds.obj.fps_points
    assert centres.shape == (mc.num_regions, 3)
    far = np.linalg.norm(ds.obj.vertices - ds.obj.vertices.mean(0), axis=1).max()
    # the same vertex, its distance summed in another order: a few u64, inside isclose's rtol 1e-5
    assert np.isclose(np.linalg.norm(centres[0] - ds.obj.vertices.mean(0)), far)
    pts = np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]])
    labels = region_labels(pts, np.array([[1, 0]]), np.array([[5.0, 5, 5], [0.1, 0, 0]]))
    assert labels.tolist() == [[2, 0]]
    line = np.linspace(0, 1, 11)[:, None] * np.array([[1.0, 0, 0]])
    assert np.allclose(sorted(farthest_point_sampling(line, 3)[:, 0]), [0.0, 0.5, 1.0])  # linspace: ~1 u64


def test_augmentation_is_a_function_of_seed_epoch_and_index(dataset_dir: Path) -> None:
    cfg = dataclasses.replace(smoke_config().data, color_prob=1.0, bg_prob=1.0, dzi_prob=1.0)
    mc = smoke_config().model_config()
    ds = open_split(dataset_dir, "train", cfg, mc, train=True)
    a, b, c = ds[(2, 1)], ds[(2, 1)], ds[(3, 1)]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not torch.equal(a["roi_img"], c["roi_img"])
    assert not torch.equal(a["crop_center"], c["crop_center"])


def test_background_replacement_keeps_only_the_visible_target(dataset_dir: Path) -> None:
    cfg, mc = no_aug()
    plain = open_split(dataset_dir, "train", cfg, mc, train=True)

    def roi_mask(inst: Instance, path: Path) -> np.ndarray:  # the mask cropped as the RoI image is
        return crop(read_mask(path), plain._roi(inst, None), mc.input_res, nearest=True) > 0

    # the sample whose RoI shows the most of the target hidden behind an occluder
    hidden = [roi_mask(i, i.mask) & ~roi_mask(i, i.mask_visib) for i in plain.instances]
    idx = int(np.argmax([h.sum() for h in hidden]))
    inst, hidden = plain.instances[idx], torch.from_numpy(hidden[idx])
    visib = torch.from_numpy(roi_mask(inst, inst.mask_visib))
    assert hidden.sum() > 20 and visib.sum() > 20
    original = plain[(0, idx)]["roi_img"]
    grey = np.float32(64) / 255  # the dataset backgrounds below are uniform: every window of them is grey
    assert (original[:, hidden] != grey).any()
    for from_dataset in (0.0, 1.0):
        bg_cfg = dataclasses.replace(cfg, bg_prob=1.0, bg_from_dataset=from_dataset)
        swapped = open_split(dataset_dir, "train", bg_cfg, mc, train=True)
        swapped._bg_pool = [np.full((60, 80, 3), 64, np.uint8)]
        img = swapped[(0, idx)]["roi_img"]
        assert torch.equal(img[:, visib], original[:, visib])
        if from_dataset:  # outside the visible mask, the occluder over the target included: all background
            assert bool((img[:, ~visib] == grey).all())
        else:  # noise
            assert (img[:, ~visib] != original[:, ~visib]).float().mean() > 0.5


def test_training_keeps_every_instance_evaluation_keeps(tmp_path_factory: pytest.TempPathFactory) -> None:
    root = occluded_dataset(tmp_path_factory)
    mc = smoke_config().model_config()
    cfg = DataConfig(workers=0)  # the default keeps everything, as the paper trains
    train = open_split(root, "train", cfg, mc, train=True)
    evaluation = open_split(root, "train", cfg, mc, train=False)

    def keys(ds: PoseDataset) -> list[tuple[int, int, int]]:
        return [(i.scene_id, i.im_id, i.inst) for i in ds.instances]

    assert keys(train) == keys(evaluation)
    assert all(i.px_count_visib > 0 for i in train.instances)
    assert any(i.visib_fract <= 0.3 for i in train.instances)  # GDR-Net's filter would drop these...
    gdrnet = open_split(root, "train", dataclasses.replace(cfg, min_visib_fract=0.3), mc, train=True)
    assert len(gdrnet) < len(train)  # ...as 0.3 still does
    assert all(torch.isfinite(train[(0, i)]["site"]).all() for i in range(len(train)))


def test_surface_points_lie_on_the_mesh_and_are_fixed(dataset_dir: Path) -> None:
    obj, again = (load_object_model(dataset_dir, 1, num_regions=8, num_pm=3000) for _ in range(2))
    assert obj.pm_points.shape == (3000, 3) and np.array_equal(obj.pm_points, again.pm_points)
    mesh = trimesh.load(str(dataset_dir / "models" / "obj_000001.ply"), force="mesh", process=False)
    # in the file's millimetres: trimesh's closest-point tolerances misjudge small triangles in metres
    _, distance_mm, _ = trimesh.proximity.closest_point(mesh, obj.pm_points * 1000.0)
    # 1e-6 m: float64 samples on the file's triangles, scaled to metres and back: a few u64 x 100 mm, 1e-14 mm
    assert distance_mm.max() < 1e-3


def test_surface_points_are_uniform_over_area_not_vertices(tmp_path: Path) -> None:
    big = trimesh.creation.box((100.0, 100.0, 100.0))  # mm, 12 faces
    small = trimesh.creation.box((20.0, 20.0, 20.0))
    for _ in range(4):
        small = small.subdivide()  # 3072 faces: nearly every vertex is on the small box
    small.apply_translation((200.0, 0.0, 0.0))
    models = tmp_path / "models"
    models.mkdir()
    trimesh.util.concatenate([big, small]).export(models / "obj_000001.ply")
    info = {"diameter": 300.0, "size_x": 210.0, "size_y": 100.0, "size_z": 100.0}
    (models / "models_info.json").write_text(json.dumps({"1": info}))
    obj = load_object_model(tmp_path, 1, num_regions=4, num_pm=3000)
    p = small.area / (small.area + big.area)  # 0.038
    sigma = np.sqrt(p * (1 - p) / 3000)
    on_small = float(np.mean(obj.pm_points[:, 0] > 0.15))
    assert abs(on_small - p) < 4 * sigma
    assert np.mean(obj.vertices[:, 0] > 0.15) > 0.9  # sampling vertices would put > 90 % there


def test_evaluation_items_have_no_targets_and_no_jitter(dataset_dir: Path) -> None:
    cfg = smoke_config()
    ds = open_split(dataset_dir, "test", cfg.data, cfg.model_config(), train=False)
    inst = ds.instances[0]
    item = ds[0]
    assert "roi_xyz" not in item and "site" not in item
    # the item's float32 centre of a box in a 320 px image: 2^-24 x 320 = 2e-5 px a rounding, a few of them
    # (x + w / 2 and the conversion) stay under 1e-4 px
    assert np.allclose(item["crop_center"].numpy(), box_center(inst.bbox_obj), atol=1e-4)
    assert torch.equal(ds[0]["roi_img"], item["roi_img"])


def test_sampler_shards_are_disjoint_deterministic_and_resumable() -> None:
    a, b = EpochSampler(50, 4, world=2, rank=0, seed=1), EpochSampler(50, 4, world=2, rank=1, seed=1)
    assert a.steps_per_epoch == 6
    ia, ib = [i for _, i in a.epoch_indices(0)], [i for _, i in b.epoch_indices(0)]
    assert len(ia) == len(ib) == 24 and not set(ia) & set(ib) and len(set(ia) | set(ib)) == 48
    assert ia == [i for _, i in EpochSampler(50, 4, world=2, rank=0, seed=1).epoch_indices(0)]
    epoch1 = a.epoch_indices(1)
    assert {e for e, _ in epoch1} == {1} and [i for _, i in epoch1] != ia
    assert a.epoch_indices(1, skip_batches=2) == epoch1[8:]
    # one stream over the epochs' ends, from where set_epoch starts it: a resumed run's batches
    assert list(itertools.islice(a, 24 + 24)) == a.epoch_indices(0) + epoch1
    a.set_epoch(1, skip_batches=2)
    assert list(itertools.islice(a, 16 + 24)) == epoch1[8:] + a.epoch_indices(2)
    assert list(EpochSampler(3, 4)) == []  # fewer samples than a batch: no batch, and no endless wait


def test_boxes_command_writes_bop_detections_that_evaluation_uses(dataset_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "boxes.json"
    res = CliRunner().invoke(main, ["boxes", "--data", str(dataset_dir), "--out", str(out), "--noise", "0.1"])
    assert res.exit_code == 0, res.output
    entries = json.loads(out.read_text())
    assert {"scene_id", "image_id", "category_id", "bbox", "score", "time"} <= set(entries[0])
    boxes = read_boxes(out, obj_id=1)
    cfg = smoke_config()
    ds = open_split(dataset_dir, "test", cfg.data, cfg.model_config(), train=False, boxes_file=out)
    inst = ds.instances[0]
    assert np.allclose(ds[0]["crop_center"].numpy(), box_center(boxes[inst.key]), atol=1e-4)  # as above
    assert not np.allclose(boxes[inst.key], inst.bbox_obj)  # noise moved it


def test_bad_datasets_are_refused(dataset_dir: Path, tmp_path: Path) -> None:
    cfg = smoke_config()
    mc = cfg.model_config()
    with pytest.raises(PosenetError, match="not a dataset"):
        open_split(tmp_path, "train", cfg.data, mc, train=True)
    with pytest.raises(PosenetError, match="no split 'nope'"):
        open_split(dataset_dir, "nope", cfg.data, mc, train=True)
    broken = tmp_path / "no_xyz"
    shutil.copytree(dataset_dir, broken)
    shutil.rmtree(next(broken.glob("train/*/xyz")))
    with pytest.raises(PosenetError, match="missing xyz maps"):
        open_split(broken, "train", cfg.data, mc, train=True)
    missing = tmp_path / "boxes.json"
    missing.write_text("[]")
    with pytest.raises(PosenetError, match="no box for"):
        open_split(dataset_dir, "test", cfg.data, mc, train=False, boxes_file=missing)


def test_train_images_takes_nested_subsets_of_the_train_split(dataset_dir: Path) -> None:
    model = smoke_config().model_config()
    every = open_split(dataset_dir, "train", DataConfig(), model, train=True)
    images = {n: {i.im_id for i in open_split(dataset_dir, "train", DataConfig(train_images=n), model,
                                              train=True).instances} for n in (3, 6)}  # fmt: skip
    assert len(images[3]) == 3 and len(images[6]) == 6 and images[3] < images[6]
    assert images[6] <= {i.im_id for i in every.instances}
    # the same subsets whatever the training seed; evaluation ignores the setting
    again = open_split(dataset_dir, "train", DataConfig(train_images=3), model, train=True, seed=9)
    assert {i.im_id for i in again.instances} == images[3]
    test = open_split(dataset_dir, "test", DataConfig(train_images=3), model, train=False)
    assert len(test) == len(open_split(dataset_dir, "test", DataConfig(), model, train=False))
    with pytest.raises(PosenetError, match="data.train_images 999 exceeds the"):
        open_split(dataset_dir, "train", DataConfig(train_images=999), model, train=True)


def test_a_truncated_image_is_refused_alike_by_train_train_detector_eval_and_boxes(
    dataset_dir: Path, tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """One train and one test image cut to 200 bytes, as a broken copy leaves them: every command that
    reads the split refuses it before any work, in one line naming the file, and writes nothing."""
    ckpt = tiny_pose_checkpoint(dataset_dir, tmp_path_factory)
    broken = tmp_path / "broken"
    shutil.copytree(dataset_dir, broken)
    cut = {}
    for split in ("train", "test"):
        cut[split] = sorted(broken.glob(f"{split}/*/rgb/*"))[0]
        cut[split].write_bytes(cut[split].read_bytes()[:200])
    runs = {
        "train": ["train", "--data", broken, "--out", tmp_path / "run", "--max-steps", 1],
        "train-detector": ["train-detector", "--data", broken, "--out", tmp_path / "det", "--max-steps", 1],
        "eval": ["eval", "--data", broken, "--ckpt", ckpt, "--json", tmp_path / "eval.json"],
        "boxes": ["boxes", "--data", broken, "--out", tmp_path / "boxes.json"],
    }
    for name, args in runs.items():
        res = CliRunner().invoke(main, [str(a) for a in args])
        split = "train" if name.startswith("train") else "test"
        assert res.exit_code != 0 and res.output.count("\n") == 1, (name, res.output)
        assert res.output.startswith("Error: 1 of the ") and f"{cut[split]}: truncated" in res.output, name
    # a broken val image is refused too, not dropped from the detector's validation
    broken_val = tmp_path / "broken_val"
    shutil.copytree(dataset_dir, broken_val)
    val_image = sorted(broken_val.glob("val/*/rgb/*"))[0]
    val_image.write_bytes(val_image.read_bytes()[:200])
    args = ["train-detector", "--data", broken_val, "--out", tmp_path / "det", "--max-steps", 1]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code != 0 and f"{val_image}: truncated" in res.output, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken", "broken_val"]
