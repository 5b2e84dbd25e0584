"""`posenet predict` on real renders and real checkpoints: a dataset split gives posenet eval's poses, a
user's files, folder, glob and video give one line each, another camera (focal length, size, lens) is
warped into the training one exactly, and bad inputs are one line or one recorded error."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from float_bounds import U32, forward_rel, gram_schmidt_gain, pose_checkpoint_rel, rotation_outputs
from posenet_helpers import calibrate_untrained, cli_ok

import posenet
from posenet.checkpoint import load_checkpoint, save_checkpoint
from posenet.cli import main
from posenet.data.camera import CameraMismatch, map_box, read_camera_file, resized, to_training_camera
from posenet.detection.detect import load_detector
from posenet.errors import PosenetError
from posenet.evaluation.evaluate import evaluate
from posenet.predict import Pose, Predictor, make_camera
from posenet.predict.batch import BatchPredictor
from posenet.predict.options import PREDICT_PASSES
from posenet.predict.overlay import LABEL_MARGIN, draw_label, label_style
from scgen.generator import Generator
from scgen.io import bop
from scgen.run.runner import RenderJob, run_render
from scgen.scenes.config.camera import camera_preset
from scgen.scenes.spec import CameraSpec

# a detector as a user could train it, shrunk to a step from random init: the test is of the path, not of
# its boxes (test_posenet_detector holds the learning)
TINY_DETECTOR = "preset: cpu\npretrained: null\nfpn_channels: 32\nhead_convs: 1\noptim: {threads: 1}\n"


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


@pytest.fixture(scope="module")
def detector_ckpt(dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("detector")
    (root / "tiny.yaml").write_text(TINY_DETECTOR)
    cli_ok("train-detector", "--data", dataset_dir, "--out", root / "run", "--config", root / "tiny.yaml",
            "--max-steps", 1)  # fmt: skip
    return root / "run" / "last.pt"


@pytest.fixture(scope="module")
def user_folder(dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """What a user brings: the test split's images and the dataset's camera.json, nothing else."""
    root = tmp_path_factory.mktemp("user")
    for i, image in enumerate(sorted((dataset_dir / "test").rglob("rgb/*"))):
        shutil.copy(image, root / f"frame{i:02d}{image.suffix}")
    shutil.copy(dataset_dir / bop.CAMERA_FILE, root / "camera.json")
    return root


def test_a_split_gives_eval_poses_and_the_field_files(dataset_dir: Path, pose_ckpt: Path, tmp_path: Path):
    out = tmp_path / "pred"
    cli_ok("predict", "--data", dataset_dir, "--split", "test", "--ckpt", pose_ckpt, "--out", out,
            "--format", "bop", "--format", "speedplus")  # fmt: skip
    records = {(r["scene_id"], r["im_id"]): r for r in _lines(out / "predictions.jsonl")}
    result = evaluate(dataset_dir, pose_ckpt, "test", workers=0, batch_size=1, passes=PREDICT_PASSES)
    assert len(records) == len(result.records) > 0
    for r in result.records:
        mine = records[r["scene_id"], r["im_id"]]
        # the same crops (the box, then predict's default re-crops: eval's are the same code), batch size
        # (1) and decoding: the same float32 arithmetic, so the same floats (how another batch size moves
        # them is test_posenet_eval's batched test)
        np.testing.assert_array_equal(mine["R"], r["R"])
        np.testing.assert_array_equal(mine["t"], r["t"])
        R = np.array(mine["R"]).reshape(3, 3)
        w, x, y, z = mine["quaternion"]  # scalar first: R of the quaternion is R
        Rq = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                       [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                       [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])  # fmt: skip
        # a wrong convention (order, sign, transpose) moves entries by O(1); R is a rotation to float32's
        # rounding (Gram-Schmidt of the network's 6D: ~10 u), so the quaternion's R is within 10 u of it:
        # 16 times that sits far from both
        np.testing.assert_allclose(Rq, R, rtol=0, atol=16 * 10 * U32)
        assert 0.0 <= mine["confidence"] <= 1.0 and mine["score"] == 1.0
    csv = (out / "results.csv").read_text().splitlines()
    assert csv[0] == "scene_id,im_id,obj_id,score,R,t,time" and len(csv) == len(records) + 1
    sub = (out / "submission.csv").read_text().splitlines()
    assert len(sub) == len(records) and all(len(row.split(",")) == 8 for row in sub)
    assert len(list((out / "overlays").glob("*.jpg"))) == len(records) and (out / "sheet.jpg").is_file()


def test_files_folder_glob_and_video(user_folder: Path, pose_ckpt: Path, tmp_path: Path):
    images = sorted(user_folder.glob("frame*"))
    camera = user_folder / "camera.json"
    box = "100,60,120,120"
    one = _lines(_predict_to(tmp_path / "one", images[0], pose_ckpt, camera, box) / "predictions.jsonl")
    folder = _lines(_predict_to(tmp_path / "dir", user_folder, pose_ckpt, camera, box) / "predictions.jsonl")
    pattern = str(user_folder / "frame0*")
    globbed = _lines(_predict_to(tmp_path / "glob", pattern, pose_ckpt, camera, box) / "predictions.jsonl")
    assert (
        len(one) == 1
        and len(folder) == len(images)
        and len(globbed) == len(list(user_folder.glob("frame0*")))
    )
    assert folder[0]["R"] == one[0]["R"] and [r["source"] for r in folder] == [str(p) for p in images]
    video = tmp_path / "approach.mp4"
    first = cv2.imread(str(images[0]))
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, first.shape[1::-1])
    for path in images:
        writer.write(cv2.imread(str(path)))
    writer.release()
    out = _predict_to(tmp_path / "video", video, pose_ckpt, camera, box)
    frames = _lines(out / "predictions.jsonl")
    assert [r["source"] for r in frames] == [f"approach.mp4#{i:06d}" for i in range(len(images))]
    assert all(r["R"] is not None for r in frames)
    cap = cv2.VideoCapture(str(out / "overlay.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(images)
    cap.release()


def _predict_to(out: Path, source: object, ckpt: Path, camera: Path, box: str) -> Path:
    cli_ok("predict", source, "--ckpt", ckpt, "--camera", camera, "--box", box, "--out", out)
    return out


def test_the_detector_boxes_every_image(
    user_folder: Path, pose_ckpt: Path, detector_ckpt: Path, tmp_path: Path
):
    out = tmp_path / "det"
    cli_ok("predict", user_folder, "--ckpt", pose_ckpt, "--detector", detector_ckpt, "--camera",
            user_folder / "camera.json", "--out", out, "--no-vis")  # fmt: skip
    records = _lines(out / "predictions.jsonl")
    assert len(records) == len(list(user_folder.glob("frame*")))
    for r in records:  # a found box with its score and a pose, or an honest miss
        assert (r["box"] is not None and r["R"] is not None) or r["flags"] == ["no_detection"]
    assert not (out / "overlays").exists() and not (out / "sheet.jpg").exists()
    # predict prepares each frame (decode, warp, detector) a frame ahead in another thread: the records
    # are still the Predictor's one image at a time
    predictor = Predictor.load(pose_ckpt, detector_ckpt)
    camera = read_camera_file(user_folder / "camera.json")
    for r in records:
        pose = predictor(cv2.imread(r["source"]), camera)
        assert r["box"] == (list(pose.box) if pose.box is not None else None), r["source"]
        assert r["R"] == (pose.R.ravel().tolist() if pose.R is not None else None), r["source"]


def test_a_bad_image_is_recorded_and_the_batch_goes_on(user_folder: Path, pose_ckpt: Path, tmp_path: Path):
    folder = tmp_path / "in"
    shutil.copytree(user_folder, folder)
    (folder / "frame99.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    args = ["predict", folder, "--ckpt", pose_ckpt, "--camera", folder / "camera.json", "--box", "9,9,50,50"]
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--out", out]])
    assert res.exit_code == 1
    assert "Warning: " in res.output and "frame99.png" in res.output
    assert res.output.strip().splitlines()[-1].startswith("Error: 1 of")
    records = _lines(out / "predictions.jsonl")
    assert records[-1]["error"].startswith("cannot read image") and records[-1]["source"].endswith(
        "frame99.png"
    )
    assert all(r["R"] is not None for r in records[:-1])


@pytest.mark.parametrize(
    "args, message",
    [
        (["--ckpt", "missing.pt"], "checkpoint not found: missing.pt"),
        (["--camera", "1,2,3"], "--camera '1,2,3' needs 4 numbers"),
        (["--camera", "nosuchpreset"], "unknown camera preset 'nosuchpreset'"),
        (["--box", "1,2,3"], "--box must be x,y,w,h"),
        (["--source", "nothing/here*.png"], "no image matches nothing/here*.png"),
    ],
)
def test_bad_inputs_are_one_line_and_write_nothing(
    user_folder: Path, pose_ckpt: Path, tmp_path: Path, args: list[str], message: str
):
    opts = {"--ckpt": str(pose_ckpt), "--camera": str(user_folder / "camera.json"), "--box": "1,1,9,9",
            "--source": str(user_folder)}  # fmt: skip
    opts.update(dict(zip(args[::2], args[1::2], strict=True)))
    source = opts.pop("--source")
    out = tmp_path / "new" / "out"
    res = CliRunner().invoke(
        main, ["predict", source, *sum(([k, v] for k, v in opts.items()), []), "--out", str(out)]
    )
    assert res.exit_code != 0 and res.output.count("\n") == 1, res.output
    assert res.output.startswith("Error: ") and message in res.output
    assert not (tmp_path / "new").exists()


def test_a_detector_checkpoint_as_the_pose_one_is_named(
    detector_ckpt: Path, user_folder: Path, tmp_path: Path
):
    out = cli_ok("predict", user_folder, "--ckpt", detector_ckpt, "--camera", "training", "--box", "1,1,9,9",
                  "--out", tmp_path / "o", code=1)  # fmt: skip
    assert (
        "is a detector checkpoint (posenet train-detector's), not a pose one" in out
        and out.count("\n") == 1
        and not (tmp_path / "o").exists()
    )


def test_an_existing_output_needs_overwrite(user_folder: Path, pose_ckpt: Path, tmp_path: Path):
    out = tmp_path / "out"
    image = sorted(user_folder.glob("frame*"))[0]
    args = ["predict", image, "--ckpt", pose_ckpt, "--camera", "training", "--box", "1,1,60,60", "--out", out]
    cli_ok(*args, "--no-vis")
    assert "exists (give --overwrite" in cli_ok(*args, code=1)
    cli_ok(*args, "--overwrite")


def test_an_old_checkpoint_takes_its_dataset(dataset_dir: Path, pose_ckpt: Path, tmp_path: Path):
    """A checkpoint from before predict (no object, no camera) is named, and --data fills both in."""
    state = load_checkpoint(pose_ckpt)
    del state["camera"]
    state["object"] = {"extent": state["object"]["extent"], "diameter": state["object"]["diameter"]}
    old = tmp_path / "old.pt"
    save_checkpoint(old, state)
    with pytest.raises(Exception, match="predates posenet predict"):
        Predictor.load(old)
    new, refilled = Predictor.load(pose_ckpt), Predictor.load(old, data=dataset_dir)
    assert new.camera.same_as(refilled.camera)
    np.testing.assert_array_equal(new.obj.pm_points, refilled.obj.pm_points)


def test_another_camera_is_warped_into_the_training_one():
    """The same scenes rendered through the training camera (320x240, f 300) and through another (480x360,
    f 400, a wider view, barrel distortion): the other camera's visible mask, warped by predict's camera
    step, lands on the training camera's mask, and its box maps onto the training box."""
    other = CameraSpec(480, 360, (400.0, 0.0, 241.0, 0.0, 400.0, 178.5, 0.0, 0.0, 1.0), 0.0,
                       (-0.18, 0.05, 0.0005, -0.0003, 0.0))  # fmt: skip
    with Generator.load(
        seed=4, resolution=(320, 240), backend="mitsuba", quality="draft", camera="ideal"
    ) as gen:
        for index in range(3):
            spec = gen.scene(index)
            a = gen.render(spec).annotation
            b = gen.render(dataclasses.replace(spec, camera=other)).annotation
            train = make_camera(spec.camera.K_mat, None, (spec.camera.width, spec.camera.height))
            user = make_camera(other.K_mat, other.dist, (other.width, other.height))
            warped = to_training_camera(b.mask_visib.astype(np.uint8) * 255, user, train) > 127
            # exact up to resampling: the masks differ on a fraction of the outline's pixels (measured at
            # most 0.3 of them), and their centres agree to a pixel (measured 0.6 px at most)
            outline = cv2.Canny(a.mask_visib.astype(np.uint8) * 255, 0, 1).astype(bool).sum()
            assert (warped ^ a.mask_visib).sum() <= 0.5 * outline, index
            centre = np.argwhere(warped).mean(0) - np.argwhere(a.mask_visib).mean(0)
            assert np.abs(centre).max() <= 1.0, (index, centre)
            # bbox_visib is whole pixels in each image: resampling moves an edge by up to 1 px of quantisation
            # and half a pixel more where the threshold (127) cuts the resampled outline
            mapped = np.array(map_box(tuple(b.bbox_visib), user, train))
            np.testing.assert_allclose(mapped, a.bbox_visib, atol=1.5)
            # without its lens the same image lands elsewhere: the distortion is what the warp undid
            pinhole = make_camera(other.K_mat, None, (other.width, other.height))
            wrong = to_training_camera(b.mask_visib.astype(np.uint8) * 255, pinhole, train) > 127
            assert (wrong ^ a.mask_visib).sum() > (warped ^ a.mask_visib).sum()


def test_a_speedplus_camera_file_reads_its_lens(tmp_path: Path):
    path = tmp_path / "camera.json"
    K = [[2988.6, 0, 960], [0, 2988.3, 600], [0, 0, 1]]
    dist = [-0.22, 0.51, -0.0007, -0.0002, -0.13]
    path.write_text(json.dumps({"Nu": 1920, "Nv": 1200, "cameraMatrix": K, "distCoeffs": dist}))
    cam = read_camera_file(path)
    assert cam.size == (1920, 1200) and cam.distorted and cam.K[0, 0] == 2988.6


def test_the_readme_predict_example_runs_as_written(pose_ckpt: Path, user_folder: Path, tmp_path: Path):
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = readme[readme.index("## Python API") :]
    example = re.findall(r"```python\n(.*?)```", section, re.S)[1]
    (tmp_path / "runs" / "cpu").mkdir(parents=True)
    shutil.copy(pose_ckpt, tmp_path / "runs" / "cpu" / "last.pt")
    shutil.copy(sorted(user_folder.glob("frame*"))[0], tmp_path / "frame.png")
    out = subprocess.run([sys.executable, "-c", example], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    quaternion = json.loads(out.stdout[: out.stdout.index("]") + 1])
    # scipy normalises it in float64 (~4 u64 an entry), numpy's norm adds ~3 u64, repr and JSON are exact:
    # 64 u64 (7e-15) holds that with room, where anything but a unit quaternion is off by O(1)
    assert len(quaternion) == 4 and abs(np.linalg.norm(quaternion) - 1) < 64 * 2**-53


def _fcos_scales(ckpt: Path, images: list[np.ndarray]) -> tuple[float, float]:
    """The scales of FCOS's outputs over `images` (BGR, as the detector is fed them): the largest
    |class or centre-ness logit|, and the largest box code times its anchor's size in the images' pixels
    (torchvision's decode: a box edge is the anchor's centre -/+ code x anchor size, then resized back)."""
    fcos, _ = load_detector(ckpt, torch.device("cpu"))
    anchor = max(max(s) for s in fcos.anchor_generator.sizes)
    logit = box = 0.0
    with torch.no_grad():
        for image in images:
            rgb = cv2.cvtColor(image, cv2.COLOR_BGR2RGB).astype(np.float32) / 255
            batch, _ = fcos.transform([torch.from_numpy(rgb.transpose(2, 0, 1))])
            head = fcos.head(list(fcos.backbone(batch.tensors).values()))
            logit = max(logit, float(head["cls_logits"].abs().max()), float(head["bbox_ctrness"].abs().max()))
            resize = max(n / r for n, r in zip(rgb.shape[:2], batch.image_sizes[0], strict=True))
            box = max(box, float(head["bbox_regression"].abs().max()) * anchor * resize)
    return logit, box


def _detector_rounding(ckpt: Path, seen: list[np.ndarray], scale: float) -> tuple[float, float]:
    """How far two float32 runs of the detector on the images `seen` (BGR, as it is fed them) may move a
    score and a box edge, the edge in pixels of an image `scale` times theirs: each output by float_bounds'
    rel of its scale (_fcos_scales). score = sqrt(sigmoid(class) sigmoid(centre-ness)) moves by at most half
    of each logit's error (d score / d logit <= 1/2); an edge by its code's error times the anchor's size and
    its own rounding (rel of the image's size)."""
    rel = forward_rel(load_detector(ckpt, torch.device("cpu"))[0])
    logit, box = _fcos_scales(ckpt, seen)
    return rel * logit, scale * rel * (box + max(seen[0].shape[:2]))


def test_onnx_gives_torch_poses(user_folder: Path, pose_ckpt: Path, detector_ckpt: Path, tmp_path: Path):
    """posenet export writes both graphs; predict through onnxruntime finds torch's boxes and scores and,
    at one box, torch's poses. onnxruntime's kernels sum in another order than torch's, so each output
    agrees to float_bounds' rounding of its scale (the poses are compared at a given box: how a pose
    moves with its crop box is the network's sensitivity, which no rounding model bounds)."""
    pose_onnx, det_onnx = tmp_path / "pose.onnx", tmp_path / "det.onnx"
    cli_ok("export", "--ckpt", pose_ckpt, "--onnx", pose_onnx, "--detector", detector_ckpt,
            "--detector-onnx", det_onnx)  # fmt: skip
    common = [user_folder, "--ckpt", pose_ckpt, "--camera", user_folder / "camera.json", "--no-vis"]
    common += ["--min-score", 0]  # every box: the 1-step detector's scores are not the point here
    common += ["--passes", 1]  # rounding at one crop (re-crops: the batched path's test, _same_pose)
    cli_ok("predict", *common, "--detector", detector_ckpt, "--out", tmp_path / "torch")
    cli_ok("predict", *common, "--detector", det_onnx, "--onnx", pose_onnx, "--out", tmp_path / "onnx")
    torch_lines, onnx_lines = (_lines(tmp_path / d / "predictions.jsonl") for d in ("torch", "onnx"))
    assert len(torch_lines) == len(onnx_lines) > 0
    frames = [cv2.imread(str(p)) for p in sorted(user_folder.glob("frame*"))]
    score, edge = _detector_rounding(detector_ckpt, frames, 1)
    # the JSON rounds a score to 1e-4 and a box to 0.01 px
    for a, b in zip(torch_lines, onnx_lines, strict=True):
        assert a["flags"] == b["flags"] and a["score"] == pytest.approx(b["score"], abs=score + 1e-4)
        if a["R"] is not None:
            np.testing.assert_allclose(b["box"], a["box"], rtol=0, atol=edge + 0.01)
    given = ["--box", "100,60,120,120"]
    with rotation_outputs() as rot6d:
        cli_ok("predict", *common, *given, "--out", tmp_path / "torch_box")
    cli_ok("predict", *common, *given, "--onnx", pose_onnx, "--out", tmp_path / "onnx_box")
    bound = _pose_rounding(pose_ckpt, rot6d)
    for a, b in zip(
        *(_lines(tmp_path / d / "predictions.jsonl") for d in ("torch_box", "onnx_box")), strict=True
    ):
        np.testing.assert_allclose(b["R"], a["R"], rtol=0, atol=bound.R)
        np.testing.assert_allclose(b["t"], a["t"], rtol=0, atol=bound.t * np.linalg.norm(a["t"]))
    # the batched path runs the one-image detector graph on a batch's images side by side, one
    # onnxruntime thread each: predict's one-at-a-time poses (its own sessions sum in another order)
    camera = read_camera_file(user_folder / "camera.json")
    on_torch = Predictor.load(pose_ckpt, detector_ckpt, min_score=0.0, passes=1)
    with rotation_outputs() as rot6d:
        for frame in frames:
            on_torch(frame, camera)
    bound = _pose_rounding(pose_ckpt, rot6d, score, edge)
    on_onnx = Predictor.load(pose_ckpt, det_onnx, onnx=pose_onnx, min_score=0.0, passes=1)
    one = [on_onnx(frame, camera) for frame in frames]
    batched = BatchPredictor(on_onnx, 3, det_onnx)
    for i, (a, b) in enumerate(zip(one, batched(frames, camera), strict=True)):
        _same_pose(a, b, f"image {i}, onnxruntime batched", bound)
    batched.close()


def _write_video(path: Path, images: list[Path]) -> None:
    first = cv2.imread(str(images[0]))
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, first.shape[1::-1])
    for image in images:
        writer.write(cv2.imread(str(image)))
    writer.release()


def test_a_glob_follows_a_folders_rules(user_folder: Path, pose_ckpt: Path, tmp_path: Path):
    """A quoted glob over a folder that also holds a video and notes skips them, as the folder does."""
    folder = tmp_path / "in"
    shutil.copytree(user_folder, folder)
    _write_video(folder / "clip.mp4", sorted(folder.glob("frame*")))
    (folder / "notes.txt").write_text("not an image\n")
    box = "100,60,120,120"
    by_folder = _predict_to(tmp_path / "dir", folder, pose_ckpt, folder / "camera.json", box)
    by_glob = _predict_to(tmp_path / "glob", f"{folder}/*", pose_ckpt, folder / "camera.json", box)
    records = [_lines(out / "predictions.jsonl") for out in (by_folder, by_glob)]
    assert [{**r, "time_ms": None} for r in records[0]] == [{**r, "time_ms": None} for r in records[1]]
    assert [Path(r["source"]).name for r in records[1]] == [p.name for p in sorted(folder.glob("frame*"))]


def test_an_image_its_camera_cannot_take_is_one_record_and_the_batch_goes_on(
    user_folder: Path, pose_ckpt: Path, tmp_path: Path
):
    """Another aspect ratio, a larger image, and an inline camera's principal point far from an image's
    centre are each an error record and a warning naming the file; an image scaled down from the camera's
    size goes through the camera scaled with it."""
    folder = tmp_path / "in"
    shutil.copytree(user_folder, folder)
    image = cv2.imread(str(sorted(folder.glob("frame*"))[0]))
    cv2.imwrite(str(folder / "half.png"), cv2.resize(image, (160, 120), interpolation=cv2.INTER_AREA))
    cv2.imwrite(str(folder / "square.png"), cv2.resize(image, (240, 240)))
    cv2.imwrite(str(folder / "large.png"), cv2.resize(image, (640, 480)))
    camera = read_camera_file(folder / "camera.json")
    inline = ",".join(f"{v:g}" for v in (camera.K[0, 0], camera.K[1, 1], camera.K[0, 2], camera.K[1, 2]))
    refused = {
        "file": {"square.png": "(another aspect ratio)", "large.png": "(larger than the camera's images)"},
        "inline": {"half.png": "principal point", "large.png": "principal point"},
    }
    for name, cam in (("file", folder / "camera.json"), ("inline", inline)):
        out = tmp_path / name
        args = ["predict", folder, "--ckpt", pose_ckpt, "--camera", cam, "--box", "30,20,60,60", "--out", out]
        res = CliRunner().invoke(main, [str(a) for a in args])
        last = res.output.strip().splitlines()[-1]
        assert res.exit_code == 1 and last.startswith(f"Error: {len(refused[name])} of"), res.output
        records = {Path(r["source"]).name: r for r in _lines(out / "predictions.jsonl")}
        assert len(records) == len(list(folder.glob("*.png")))  # the batch went on past each
        for file, r in records.items():
            if file in refused[name]:
                assert refused[name][file] in r["error"] and f"{file}: the image is" in res.output, file
            else:
                assert "error" not in r and r["R"] is not None, (name, file)
    # the scaled camera is the resized image's, exactly: pixel centres at integers, the lens unchanged
    half = camera.for_image((160, 120))
    np.testing.assert_array_equal(half.K, resized(camera, (160, 120)).K)
    np.testing.assert_array_equal(half.K[:2, :2], camera.K[:2, :2] / 2)  # halving is exact in binary
    assert half.K[0, 2] == (camera.K[0, 2] + 0.5) / 2 - 0.5 and np.array_equal(half.dist, camera.dist)
    with pytest.raises(CameraMismatch, match="another aspect ratio"):
        Predictor.load(pose_ckpt)(cv2.imread(str(folder / "square.png")), camera, (30, 20, 60, 60))


@pytest.fixture(scope="module")
def lens_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 training samples through SPEED+'s lens (its distortion, as scgen renders it), at 480x300."""
    out = tmp_path_factory.mktemp("lens") / "ds"
    job = RenderJob(out=out, n=2, seed=3, backend="mitsuba", quality="draft", resolution=(480, 300),
                    camera="speedplus", ratios=(1.0, 0.0, 0.0))  # fmt: skip
    run_render(job, progress=False)
    return out


def test_a_lens_dataset_carries_its_lens_and_predict_takes_it(
    lens_dataset: Path, pose_ckpt: Path, tmp_path: Path
):
    """camera.json holds the lens as every image's scene_camera entry does, and --data predicts its images
    through it: the same poses as each image with --camera camera.json (the same warp)."""
    camera = read_camera_file(lens_dataset / bop.CAMERA_FILE)
    np.testing.assert_array_equal(camera.dist, camera_preset("speedplus")["dist"])
    assert camera.size == (480, 300)
    by_data = tmp_path / "data"
    cli_ok("predict", "--data", lens_dataset, "--split", "train", "--ckpt", pose_ckpt, "--out", by_data,
            "--no-vis")  # fmt: skip
    records = _lines(by_data / "predictions.jsonl")
    assert len(records) == 2 and all(r["R"] is not None for r in records)
    for r in records:
        one = tmp_path / f"one{r['im_id']}"
        cli_ok("predict", r["source"], "--ckpt", pose_ckpt, "--camera", lens_dataset / bop.CAMERA_FILE,
                "--box", ",".join(map(repr, r["box"])), "--out", one, "--no-vis")  # fmt: skip
        alone = _lines(one / "predictions.jsonl")[0]
        # the same image, camera (camera.json holds the scene_camera entry's values), network and box (the
        # dataset's integer bbox_obj, exact through JSON's 0.01 px): the same arithmetic, the same floats
        np.testing.assert_array_equal(alone["R"], r["R"])
        np.testing.assert_array_equal(alone["t"], r["t"])


def test_the_python_api_takes_what_the_cli_takes(user_folder: Path, pose_ckpt: Path, tmp_path: Path):
    """Grey, BGRA, 16-bit, 12-bit-in-16 and float [0, 1] versions of one image give its uint8 pose exactly
    (each converts back to the same bytes: 257 x, 4095 / 255 x and x / 255 round back to x); other kinds
    are one PosenetError. The CLI reads a 12-bit PNG alike, with one warning."""
    predictor = Predictor.load(pose_ckpt)
    camera = read_camera_file(user_folder / "camera.json")
    bgr = cv2.imread(str(sorted(user_folder.glob("frame*"))[0]))
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    box = (100.0, 60.0, 120.0, 120.0)
    uint8 = predictor(bgr, camera, box)
    for name, image, same_as in [
        ("bgra", np.dstack([bgr, np.full(bgr.shape[:2], 7, np.uint8)]), bgr),
        ("uint16", bgr.astype(np.uint16) * 257, bgr),
        ("float", bgr.astype(np.float32) / 255, bgr),
        ("grey", grey, np.dstack([grey] * 3)),
        ("grey1", grey[..., None], np.dstack([grey] * 3)),
    ]:
        np.testing.assert_array_equal(
            predictor(image, camera, box).R, predictor(same_as, camera, box).R, name
        )
    twelve = np.round(bgr.astype(np.float64) * 4095 / 255).astype(np.uint16)
    with pytest.warns(UserWarning, match="read as 12-bit data"):
        np.testing.assert_array_equal(predictor(twelve, camera, box).R, uint8.R)
    for bad, message in [
        (bgr.astype(np.int32), "uint8, uint16 or float"),
        (bgr.astype(np.float32), r"must lie in \[0, 1\]"),
        (bgr[..., :2], "H x W x 1, 3 or 4"),
    ]:
        with pytest.raises(PosenetError, match=message):
            predictor(bad, camera, box)
    folder = tmp_path / "deep"
    folder.mkdir()
    cv2.imwrite(str(folder / "a12.png"), twelve)
    cv2.imwrite(str(folder / "b12.png"), twelve)
    out = tmp_path / "out"
    output = cli_ok("predict", folder, "--ckpt", pose_ckpt, "--camera", user_folder / "camera.json", "--box",
                     ",".join(map(str, box)), "--out", out, "--no-vis")  # fmt: skip
    assert output.count("read as 12-bit data") == 1 and "a12.png" in output
    assert all(r["R"] == uint8.R.ravel().tolist() for r in _lines(out / "predictions.jsonl"))


def test_a_detection_under_the_score_floor_is_none(
    user_folder: Path, pose_ckpt: Path, detector_ckpt: Path, tmp_path: Path
):
    """--min-score: a best box scoring under it is no_detection, its score kept; 0 takes every box."""
    folder = tmp_path / "in"
    folder.mkdir()
    cv2.imwrite(str(folder / "black.png"), np.zeros((240, 320, 3), np.uint8))
    shutil.copy(sorted(user_folder.glob("frame*"))[0], folder / "frame.png")
    common = [folder, "--ckpt", pose_ckpt, "--detector", detector_ckpt, "--camera", "training", "--no-vis"]
    cli_ok("predict", *common, "--min-score", 0, "--out", tmp_path / "all")
    cli_ok("predict", *common, "--min-score", 1, "--out", tmp_path / "none")
    found, floored = (_lines(tmp_path / d / "predictions.jsonl") for d in ("all", "none"))
    assert all(r["R"] is not None and r["flags"] != ["no_detection"] for r in found)
    for a, b in zip(found, floored, strict=True):  # a score is a probability: under 1
        assert b["flags"] == ["no_detection"] and b["R"] is None and b["score"] == a["score"] < 1


@dataclasses.dataclass(frozen=True)
class Rounding:
    """How far two float32 runs of predict on the same inputs may move each output: another batch size
    is another GEMM blocking (float_bounds). The detector's score and box edges (_detector_rounding), R's
    entries by the pose network's rel times the Gram-Schmidt gain of the 6D outputs its forwards gave
    (float_bounds.gram_schmidt_gain), t by rel of |t|."""

    score: float
    edge: float
    R: float
    t: float


def _pose_rounding(ckpt: Path, rot6d: list[torch.Tensor], score: float = 0.0, edge: float = 0.0) -> Rounding:
    """Rounding with the pose network's bounds over the 6D outputs `rot6d` (float_bounds.rotation_outputs)."""
    gain = max(gram_schmidt_gain(row) for d6 in rot6d for row in d6)
    rel = pose_checkpoint_rel(ckpt)
    return Rounding(score, edge, gain * rel, rel)


def _same_pose(a: Pose, b: Pose, what: str, bound: Rounding) -> None:
    """b is a to `bound`, each output in its own unit. The first crop is the box; the re-crops are whole
    training pixels (projected_box) taken to the user's image by the same map_box, so equal, unless a
    pose's rounding carries a projected extreme across a pixel centre. The confidence is a share of
    counted pixels, equal unless one sits within the rounding of its threshold (one output cell, the
    mask's 0.5). Either moves the next figures by more than rounding: how a pose moves with its crop is
    the network's sensitivity, which no rounding model bounds (as at a detector box that moved)."""
    assert a.flags == b.flags and (a.R is None) == (b.R is None), what
    assert a.score == pytest.approx(b.score, rel=0, abs=bound.score), what
    if a.box is not None:
        np.testing.assert_allclose(a.box, b.box, rtol=0, atol=bound.edge, err_msg=what)
        assert len(a.crops) == len(b.crops) > 0 and a.crops[1:] == b.crops[1:], what
    if a.R is not None:
        np.testing.assert_allclose(a.R, b.R, rtol=0, atol=bound.R, err_msg=what)
        np.testing.assert_allclose(a.t, b.t, rtol=0, atol=bound.t * np.linalg.norm(a.t), err_msg=what)
        assert a.confidence == b.confidence, what


def test_the_batched_path_gives_the_one_at_a_time_poses(
    user_folder: Path, pose_ckpt: Path, detector_ckpt: Path
):
    """BatchPredictor in batches of 3 over the test images at 640x480 (a camera of twice the training
    size, so each is warped; the last batch short), the detector batched (FCOS's best box at fixed shapes),
    given boxes mixed in, padded to fixed shapes or not, and with 3 passes (re-crops): the poses Predictor
    gives one image at a time. Under the score floor both give no_detection with the same score."""
    camera = read_camera_file(user_folder / "camera.json")
    big = resized(camera, (640, 480))
    images = [cv2.resize(cv2.imread(str(p)), (640, 480)) for p in sorted(user_folder.glob("frame*"))]
    assert len(images) % 3 != 0  # the last batch is short: the padding is exercised
    predictor = Predictor.load(pose_ckpt, detector_ckpt, min_score=0.0, passes=1)
    boxes = [None if i % 2 else (200.0, 150.0, 240.0, 180.0) for i in range(len(images))]
    with rotation_outputs() as rot6d:
        one = [predictor(image, big, box) for image, box in zip(images, boxes, strict=True)]
    seen = [to_training_camera(image, big, predictor.camera) for image in images]
    bound = _pose_rounding(pose_ckpt, rot6d, *_detector_rounding(detector_ckpt, seen, 640 / 320))
    for fixed in (False, True):
        batched = BatchPredictor(predictor, 3, detector_ckpt, fixed=fixed)
        assert batched.boxes.model is predictor.detector.model  # the checkpoint read once, for both paths
        for i, (a, b) in enumerate(zip(one, batched(images, big, boxes), strict=True)):
            _same_pose(a, b, f"image {i}, fixed {fixed}", bound)
        batched.close()
    predictor.passes = 3  # re-crops batched too: each pass's boxes alike
    with rotation_outputs() as rot6d:
        recropped = [predictor(image, big, box) for image, box in zip(images, boxes, strict=True)]
    again = BatchPredictor(predictor, 3, detector_ckpt)(images, big, boxes)
    bound3 = _pose_rounding(pose_ckpt, rot6d, bound.score, bound.edge)
    for i, (a, b) in enumerate(zip(recropped, again, strict=True)):
        _same_pose(a, b, f"image {i}, 3 passes", bound3)
    assert any(len(a.crops) > 1 for a in recropped)  # re-crops ran (a pose projecting nowhere stops them)
    predictor.passes = 1
    predictor.min_score = 1.0  # a score is a probability: under 1
    floored = BatchPredictor(predictor, 3, detector_ckpt)(images, big)
    assert all(p.flags == ("no_detection",) and p.R is None for p in floored)
    for i, p in enumerate(floored):
        _same_pose(predictor(images[i], big), p, f"image {i} under the floor", bound)
    with pytest.raises(PosenetError, match="CUDA graphs need a CUDA device"):
        BatchPredictor(predictor, 3, graphs=True)


def test_predict_batch_writes_the_one_at_a_time_records(
    user_folder: Path, pose_ckpt: Path, detector_ckpt: Path, tmp_path: Path
):
    """`posenet predict --batch 3`: the same records as without (poses to float rounding, as the Python
    API's test bounds them: _same_pose), a frame's time_ms its batch's share; --track and --cuda-graphs
    on a CPU are one-line refusals."""
    common = [user_folder, "--ckpt", pose_ckpt, "--detector", detector_ckpt, "--camera", "training",
              "--min-score", 0, "--no-vis"]  # fmt: skip
    common += ["--passes", 1]  # rounding at one crop (re-crops: the batched path's test, _same_pose)
    with rotation_outputs() as rot6d:
        cli_ok("predict", *common, "--out", tmp_path / "one")
    cli_ok("predict", *common, "--batch", 3, "--out", tmp_path / "three")
    one, three = (_lines(tmp_path / d / "predictions.jsonl") for d in ("one", "three"))
    assert [r["source"] for r in one] == [r["source"] for r in three]
    bound = _pose_rounding(pose_ckpt, rot6d)
    for a, b in zip(one, three, strict=True):
        assert a["flags"] == b["flags"] and set(b["time_ms"]) >= {"decode", "detector", "pose_network"}
        np.testing.assert_allclose(a["R"], b["R"], rtol=0, atol=bound.R)
        np.testing.assert_allclose(a["t"], b["t"], rtol=0, atol=bound.t * np.linalg.norm(a["t"]))
    for extra, message in [(["--track"], "take no --batch"), (["--filter"], "take no --batch"),
                           (["--cuda-graphs"], "CUDA graphs need")]:  # fmt: skip
        output = cli_ok(
            "predict", *common, "--batch", 2, *extra, "--device", "cpu", "--out", tmp_path / "x", code=1
        )
        assert message in output and not (tmp_path / "x").exists()


def test_a_label_wider_than_its_image_goes_on_over_lines():
    """An overlay's label with every flag, on a 320x240 image: broken over two lines that stay inside the
    image (a cut label inks the last column); a label that fits keeps one line."""
    long_label, short_label = "score 0.09 conf 0.00 behind_camera,low_confidence", "score 0.93 conf 0.88"
    for text, lines in ((long_label, 2), (short_label, 1)):
        image = np.zeros((240, 320, 3), np.uint8)
        leading = label_style(image)[2]
        draw_label(image, text, (0, 0, 255))
        rows = np.nonzero(image.any(axis=(1, 2)))[0]
        assert not image[:, -LABEL_MARGIN // 2 :].any(), text
        assert (lines - 1) * leading < rows.max() <= lines * leading + leading // 2, (text, rows.max())


def assert_filter_starts_and_holds(records: list[dict]) -> None:
    """One measurement cannot start the filter; two that agree within its gates do (which two, for an
    untrained network, depends on its noise), and from then on the clip's every frame has a state."""
    started = [r["filter"] is not None for r in records]
    assert not started[0] and any(started)
    assert all(started[started.index(True) :])


def test_track_a_users_video_on_the_filter(
    dataset_dir: Path, user_folder: Path, pose_ckpt: Path, detector_ckpt: Path, tmp_path: Path
):
    """--track on a video (no orbit known: the filter at constant velocity and rate in the camera frame):
    each frame's time is its index over the video's rate; --filter boxes every frame with the detector and
    filters the poses; a folder of images needs --dt, and takes it; the Python API (posenet.Tracker) gives
    the CLI's filtered and smoothed states for the same frames."""
    ckpt = tmp_path / "last.pt"  # a copy: the shared checkpoint stays read-only
    shutil.copy(pose_ckpt, ckpt)
    calibrate_untrained(dataset_dir, ckpt)
    images = sorted(user_folder.glob("frame*"))
    _write_video(tmp_path / "clip.mp4", images)
    common = ("--ckpt", ckpt, "--detector", detector_ckpt, "--camera", user_folder / "camera.json",
              "--min-score", 0, "--track", "--no-vis")  # fmt: skip
    cli_ok("predict", tmp_path / "clip.mp4", *common, "--out", tmp_path / "video")
    records = _lines(tmp_path / "video" / "predictions.jsonl")
    assert [r["time_s"] for r in records] == [
        i * (1 / 10.0) for i in range(len(images))
    ]  # 10 fps: index x dt
    assert all("filter" in r and "smoothed" in r for r in records)
    assert_filter_starts_and_holds(records)
    plain = [a for a in common if a != "--track"]
    cli_ok("predict", tmp_path / "clip.mp4", *plain, "--filter", "--out", tmp_path / "filtered")
    filtered = _lines(
        tmp_path / "filtered" / "predictions.jsonl"
    )  # the detector on every frame, then the filter
    assert [r["box_source"] for r in filtered] == ["detector"] * len(images)
    assert_filter_starts_and_holds(filtered)
    assert "give --dt" in cli_ok("predict", user_folder, *common, "--out", tmp_path / "folder", code=1)
    assert not (tmp_path / "folder").exists()
    cli_ok("predict", user_folder, *common, "--dt", 2.5, "--out", tmp_path / "folder")
    assert [r["time_s"] for r in _lines(tmp_path / "folder" / "predictions.jsonl")] == [
        2.5 * i for i in range(len(images))
    ]
    tracker = posenet.Tracker.load(ckpt, detector=detector_ckpt, min_score=0.0)
    camera = read_camera_file(user_folder / "camera.json")
    cap = cv2.VideoCapture(str(tmp_path / "clip.mp4"))
    for record in records:
        ok, image = cap.read()
        assert ok
        tracked = tracker(image, camera, time=record["time_s"])
        assert tracked.source == record["box_source"]
        if tracked.estimate is None:
            assert record["filter"] is None
        else:  # the same floats through the same code: only JSON's round trip of repr'd floats
            assert tracked.estimate.t.tolist() == record["filter"]["t"]
    cap.release()
    for estimate, record in zip(tracker.smoothed(), records, strict=True):
        assert (estimate is None and record["smoothed"] is None) or estimate.t.tolist() == record["smoothed"][
            "t"
        ]
