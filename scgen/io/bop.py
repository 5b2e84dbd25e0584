"""The BOP format (docs/dataset.md): file names, millimetres on disk, and the entries of its JSON files.

One home for what scgen's writer produces and what validate, stats, posenet and its viewers read,
so the two sides cannot drift apart. Poses and sizes are metres in memory and millimetres on disk.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from scgen.errors import ScgenError
from scgen.io.image_file import read_image

if TYPE_CHECKING:  # trimesh loads in ~0.6 s: the command lines' help imports this module
    import trimesh

MM_PER_M = 1000.0
DIST_KEYS = ("k1", "k2", "p1", "p2", "k3")  # scene_camera.json's cam_dist: OpenCV's lens order (scenes.lens)
CAMERA_FILE = "camera.json"
MODELS_DIR = "models"
MODELS_INFO_FILE = "models_info.json"
SCENE_FILES = ("scene_gt", "scene_camera", "scene_gt_info")  # {name}.json in every scene folder
MASK_DIRS = {False: "mask", True: "mask_visib"}
MODELS_EVAL_DIR = "models_eval"  # the models bop_toolkit's error functions load (model_type "eval")
TEST_TARGETS_FILES = {"bop19": "test_targets_bop19.json", "bop24": "test_targets_bop24.json"}  # dataset root
TEST_SPLIT = "test"  # the split the test targets list
TARGETS_MIN_VISIB_FRACT = 0.1  # BOP19 targets: instances at least this visible (enumerate_test_targets.py)
DEPTH_MAX = 65535  # largest uint16 depth value; 0 means no measurement
EMPTY_BOX = (-1, -1, -1, -1)  # bop_toolkit's box of an empty silhouette
PLY_VERTEX_PROPERTIES = ("x", "y", "z", "nx", "ny", "nz", "red", "green", "blue")  # what inout.load_ply reads
TARGET_OBJ_ID = 1  # the target's BOP object id; the config's [[objects]] models follow it (2, 3, ...)


def model_file(obj_id: int) -> str:
    return f"obj_{obj_id:06d}.ply"


def scene_dir(root: Path, split: str, scene_id: int) -> Path:
    return Path(root) / split / f"{scene_id:06d}"


def scene_file(scene: Path, name: str) -> Path:
    """One of a scene folder's SCENE_FILES."""
    return scene / f"{name}.json"


def rgb_path(scene: Path, im_id: int, ext: str = "png") -> Path:
    return scene / "rgb" / f"{im_id:06d}.{ext}"


def mask_path(scene: Path, im_id: int, inst: int, visib: bool = False) -> Path:
    return scene / MASK_DIRS[visib] / f"{im_id:06d}_{inst:06d}.png"


def read_mask(path: Path) -> np.ndarray | None:
    """A mask PNG as a bool array (pixels over half of 8-bit white), or None when missing or unreadable."""
    img = read_image(Path(path))
    return None if img is None else img > 127


def xyz_path(scene: Path, im_id: int, inst: int) -> Path:
    """Our addition to BOP: the instance's model-coordinate map, cropped to its xyz_box."""
    return scene / "xyz" / f"{im_id:06d}_{inst:06d}.exr"


def depth_path(scene: Path, im_id: int) -> Path:
    return scene / "depth" / f"{im_id:06d}.png"


def depth_scale_for(max_depth_m: float) -> float:
    """The smallest power of ten (mm per depth unit) at which `max_depth_m` still fits in uint16.

    One scale per dataset, so a depth value means the same everywhere; BOP's own datasets use 0.1 or 1.
    """
    max_mm = max_depth_m * MM_PER_M
    return next(10.0**k for k in range(-3, 10) if max_mm / 10.0**k <= DEPTH_MAX)


def encode_depth(depth_m: np.ndarray, depth_scale: float) -> np.ndarray:
    """A BOP depth image: uint16 with depth_mm = value * depth_scale. 0 means no measurement: nothing
    was hit, or the surface lies farther than the scale can hold (stars, Earth), so nothing wraps."""
    units = np.round(np.asarray(depth_m, np.float64) * MM_PER_M / depth_scale)
    return np.where(units <= DEPTH_MAX, units, 0).astype(np.uint16)


def bbox(xs: np.ndarray, ys: np.ndarray) -> list[int]:
    """bop_toolkit's 2D box of pixel coordinates (misc.calc_2d_bbox): [x, y, max - min, max - min], so a
    single pixel has w = h = 0; EMPTY_BOX when there are none."""
    if len(xs) == 0:
        return list(EMPTY_BOX)
    x, y = int(np.min(xs)), int(np.min(ys))
    return [x, y, int(np.max(xs)) - x, int(np.max(ys)) - y]


def box_pixels(box: Any) -> tuple[int, int, int, int]:
    """The pixels a BOP box [x, y, w, h] spans, as (x, y, columns, rows): columns x .. x + w."""
    x, y, w, h = (int(v) for v in box)
    return x, y, w + 1, h + 1


def gt_info_entry(
    px_count_all: int,
    bbox_obj: list[int],
    mask_visib: np.ndarray,
    px_count_valid: int,
    xyz_box: list[int] | None,
) -> dict[str, Any]:
    """A scene_gt_info.json entry as bop_toolkit's calc_gt_info writes it, plus our `xyz_box`.

    `px_count_all` and `bbox_obj` are those of the whole silhouette, the part past the image border
    included; `px_count_valid` counts its pixels inside the image with a depth value. Both boxes are
    EMPTY_BOX when nothing is visible. `xyz_box` ([x, y, columns, rows] inside the image, or None) is the
    crop of the xyz map.
    """
    ys, xs = np.nonzero(mask_visib)
    n_visib = len(xs)
    return {
        "bbox_obj": list(bbox_obj) if n_visib else list(EMPTY_BOX),
        "bbox_visib": bbox(xs, ys),
        "px_count_all": int(px_count_all),
        "px_count_valid": int(px_count_valid),
        "px_count_visib": n_visib,
        "visib_fract": n_visib / px_count_all if px_count_all else 0.0,
        "xyz_box": xyz_box,
    }


def gt_info_canvas(width: int, height: int) -> tuple[int, int, int, int]:
    """(x, y, w, h) of the canvas on which bop_toolkit's calc_gt_info measures an object's whole
    silhouette (px_count_all, bbox_obj): the image grown by one image size past each border."""
    return -width, -height, 3 * width, 3 * height


def targets_bop19(images: Iterable[tuple[int, int, list[dict], list[dict]]]) -> list[dict[str, int]]:
    """test_targets_bop19.json from (scene_id, im_id, scene_gt entries, scene_gt_info entries) per test
    image: per image and object, the instances at least TARGETS_MIN_VISIB_FRACT visible (as
    bop_toolkit's enumerate_test_targets.py lists them)."""
    out = []
    for scene_id, im_id, gts, infos in images:
        counts = Counter(
            gt["obj_id"] for gt, info in zip(gts, infos, strict=True)
            if info["visib_fract"] >= TARGETS_MIN_VISIB_FRACT
        )  # fmt: skip
        out += [{"im_id": im_id, "inst_count": n, "obj_id": obj_id, "scene_id": scene_id}
                for obj_id, n in sorted(counts.items())]  # fmt: skip
    return out


def targets_bop24(images: Iterable[tuple[int, int]]) -> list[dict[str, int]]:
    """test_targets_bop24.json from (scene_id, im_id) of every test image: BOP24's detection task is
    evaluated on whole images, every object in them."""
    return [{"im_id": im_id, "scene_id": scene_id} for scene_id, im_id in images]


def results_csv(records: list[dict[str, Any]]) -> str:
    """Pose estimates as a BOP19 results file (what bop_toolkit's evaluation reads):
    `scene_id,im_id,obj_id,score,R,t,time`, R row-major and t in
    mm, space-separated; time = the image's seconds (the same for each of its estimates); score the
    record's `score` (posenet predict's pose confidence), else 1.0."""
    lines = ["scene_id,im_id,obj_id,score,R,t,time"]
    for r in (
        r for r in records if r["R"] is not None
    ):  # no estimate (missed, PnP failed): BOP counts it wrong
        R = " ".join(repr(float(v)) for v in r["R"])
        t = " ".join(repr(float(v) * MM_PER_M) for v in r["t"])
        score = float(r.get("score", 1.0))
        lines.append(f"{r['scene_id']},{r['im_id']},{r['obj_id']},{score!r},{R},{t},{r['time_s']!r}")
    return "\n".join(lines) + "\n"


def ply_vertex_properties(path: Path) -> list[str]:
    """Names of a PLY file's vertex properties, read from its header as bop_toolkit's inout.load_ply does
    (it finds normals by nx, ny, nz and colours by red, green, blue)."""
    props, in_vertex = [], False
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("ascii", "replace").strip()
            if line == "end_header":
                break
            if line.startswith("element"):
                in_vertex = line.split()[1] == "vertex"
            elif line.startswith("property") and in_vertex:
                props.append(line.split()[-1])
    return props


def gt_entry(R: np.ndarray, t_m: np.ndarray, obj_id: int) -> dict[str, Any]:
    """A scene_gt.json instance: model-to-camera rotation (row-major) and translation in millimetres."""
    return {"cam_R_m2c": [float(x) for x in np.asarray(R).reshape(9)],
            "cam_t_m2c": [float(x) for x in np.asarray(t_m) * MM_PER_M], "obj_id": obj_id}  # fmt: skip


def gt_pose(entry: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(R, t in metres) of a scene_gt.json instance."""
    R = np.asarray(entry["cam_R_m2c"], dtype=np.float64).reshape(3, 3)
    return R, np.asarray(entry["cam_t_m2c"], dtype=np.float64) / MM_PER_M


def camera_K(entry: dict[str, Any]) -> np.ndarray:
    """The 3 x 3 intrinsics of a scene_camera.json entry."""
    return np.asarray(entry["cam_K"], dtype=np.float64).reshape(3, 3)


def camera_dist(entry: dict[str, Any]) -> tuple[float, ...]:
    """The lens distortion of a scene_camera.json entry: its cam_dist (OpenCV's k1, k2, p1, p2, k3), or
    zeros (a pinhole camera) without one."""
    dist = tuple(float(k) for k in entry.get("cam_dist", (0.0,) * len(DIST_KEYS)))
    if len(dist) != len(DIST_KEYS):
        raise ScgenError(f"cam_dist has {len(dist)} coefficients, not OpenCV's {len(DIST_KEYS)}: {dist}")
    return dist


def models_info_entry(bounds_m: np.ndarray, diameter_m: float) -> dict[str, float]:
    """A models_info.json entry (millimetres) from the model's bounds (2 x 3, metres) and diameter."""
    lo, hi = np.asarray(bounds_m) * MM_PER_M
    size = hi - lo
    return {"diameter": float(diameter_m * MM_PER_M), "min_x": float(lo[0]), "min_y": float(lo[1]),
            "min_z": float(lo[2]), "size_x": float(size[0]), "size_y": float(size[1]),
            "size_z": float(size[2])}  # fmt: skip


def model_size_m(info: dict[str, Any]) -> np.ndarray:
    """The size (x, y, z) of a models_info entry's bounding box, in metres."""
    return np.array([info["size_x"], info["size_y"], info["size_z"]], dtype=np.float64) / MM_PER_M


def model_box_m(info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(min corner, size) of a models_info entry's bounding box, in metres."""
    lo = np.array([info["min_x"], info["min_y"], info["min_z"]], dtype=np.float64) / MM_PER_M
    return lo, model_size_m(info)


NOT_A_FOLDER = "does not exist or is not a directory"


def not_a_dataset(root: str | Path, why: str) -> str:
    """The one wording of both CLIs (scgen, posenet) for a dataset argument that is not one."""
    return f"not a dataset folder: {root} {why}"


def read_json(path: Path) -> Any:
    """A JSON file of the dataset, or a one-line ScgenError naming it (and that it is missing, if it is)."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ScgenError(f"cannot read {path}: no such file") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ScgenError(f"cannot read {path}: {exc}") from exc


def read_models_info(root: Path) -> dict[str, Any]:
    return read_json(Path(root) / MODELS_DIR / MODELS_INFO_FILE)


def read_model_mesh(root: Path, obj_id: int, models_dir: str = MODELS_DIR) -> trimesh.Trimesh:
    """The object's PLY model (of MODELS_DIR or MODELS_EVAL_DIR), in metres."""
    import trimesh

    path = Path(root) / models_dir / model_file(obj_id)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except (OSError, ValueError) as exc:
        raise ScgenError(f"cannot read model {path}: {exc}") from exc
    mesh.vertices = np.asarray(mesh.vertices, dtype=np.float64) / MM_PER_M
    return mesh


def symmetry_transforms(info: dict[str, Any], max_sym_disc_step: float = 0.01) -> np.ndarray:
    """(K, 4, 4) model-frame transforms (metres) under which a models_info entry's object looks the same.

    The identity first, then each of its `symmetries_discrete` (row-major 4x4, translation in mm),
    each composed with every turn of its `symmetries_continuous` ({axis, offset in mm}: turns about the
    axis through the offset). A continuous symmetry is cut into ceil(pi / max_sym_disc_step) equal turns,
    so that no point moves more than max_sym_disc_step diameters from one to the next (BOP's
    get_symmetry_transformations; GDR-Net's 0.01 gives 315 turns). Malformed fields raise ValueError,
    KeyError or TypeError.
    """
    discrete = [np.eye(4)] + [_mm_to_m(s) for s in info.get("symmetries_discrete", [])]
    turns = [
        _turn(sym, angle)
        for sym in info.get("symmetries_continuous", [])
        for angle in np.linspace(0.0, 2.0 * np.pi, int(np.ceil(np.pi / max_sym_disc_step)), endpoint=False)
    ]
    return np.stack([turn @ d for d in discrete for turn in turns] if turns else discrete)


def _mm_to_m(flat: Any) -> np.ndarray:
    """A models_info 4x4 transform (16 numbers, row-major, translation in mm), translation in metres."""
    T = np.asarray(flat, dtype=np.float64).reshape(4, 4).copy()
    T[:3, 3] /= MM_PER_M
    return T


def _turn(sym: dict[str, Any], angle: float) -> np.ndarray:
    """The 4x4 turn by `angle` (radians) of a continuous symmetry: about its axis through its offset (mm)."""
    axis = np.asarray(sym["axis"], dtype=np.float64).reshape(3)
    offset = np.asarray(sym["offset"], dtype=np.float64).reshape(3) / MM_PER_M
    x, y, z = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k
    T[:3, 3] = offset - T[:3, :3] @ offset
    return T


def scene_dirs(root: Path, split: str) -> list[Path]:
    """The scene folders of a split (numbered folders holding a scene_gt.json), in scene order."""
    folders = Path(root, split).glob("[0-9]*")
    return sorted(p for p in folders if p.name.isdigit() and scene_file(p, "scene_gt").is_file())


def split_names(root: Path) -> list[str]:
    """The splits of a BOP dataset: its folders that hold at least one scene folder."""
    return sorted(p.name for p in Path(root).iterdir() if p.is_dir() and scene_dirs(root, p.name))
