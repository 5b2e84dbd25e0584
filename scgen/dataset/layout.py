"""The on-disk dataset layout (docs/dataset.md): paths, manifest, records and the metadata table."""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.bop import NOT_A_FOLDER, not_a_dataset, read_json
from scgen.io.sequence_frames import METADATA_FILE

MANIFEST = "scgen.json"
# 2: depth by default, scene_gt_info in bop_toolkit's conventions, models_eval/, test targets
FORMAT = "scgen-bop/2"
OBJ_ID = bop.TARGET_OBJ_ID  # the target's obj_id, as the dataset modules name it
CHUNK = 1000  # samples per BOP scene folder (a sequence has its own): scene_id = sample_id // CHUNK
# --rgb-format: an rgb/ file extension, or auto (the camera's: scgen.dataset.writer.rgb_format_for)
RGB_FORMATS = ("auto", "png", "jpg")
TARGET_INSTANCE = 0  # the target is each image's first annotated instance (scene_gt entry 0)


class Layout:
    """Paths of one dataset's files; sample ids double as BOP im_ids.

    A BOP scene folder holds `scene_size` consecutive samples: CHUNK, or a sequence's frames (the
    manifest's `sequence.frames`), so that scene_id is the sequence id. Given, or read from the manifest on
    first use."""

    def __init__(self, root: str | Path, scene_size: int | None = None) -> None:
        self.root = Path(root)
        self._scene_size = scene_size

    @property
    def scene_size(self) -> int:
        """Samples per BOP scene folder."""
        if self._scene_size is None:
            if not self.manifest_path.is_file():
                return CHUNK
            self._scene_size = scene_size_of(read_json(self.manifest_path))
        return self._scene_size

    def scene_id(self, sample_id: int) -> int:
        """The BOP scene of a sample: its chunk, or its sequence."""
        return sample_id // self.scene_size

    def chunk_dir(self, split: str, sample_id: int) -> Path:
        return bop.scene_dir(self.root, split, self.scene_id(sample_id))

    def rgb(self, split: str, sample_id: int, ext: str = "png") -> Path:
        return bop.rgb_path(self.chunk_dir(split, sample_id), sample_id, ext)

    def mask(self, split: str, sample_id: int, visib: bool = False, inst: int = TARGET_INSTANCE) -> Path:
        return bop.mask_path(self.chunk_dir(split, sample_id), sample_id, inst, visib)

    def xyz(self, split: str, sample_id: int, inst: int = TARGET_INSTANCE) -> Path:
        return bop.xyz_path(self.chunk_dir(split, sample_id), sample_id, inst)

    def depth(self, split: str, sample_id: int) -> Path:
        return bop.depth_path(self.chunk_dir(split, sample_id), sample_id)

    @property
    def camera_path(self) -> Path:
        return self.root / bop.CAMERA_FILE

    @property
    def models_dir(self) -> Path:
        return self.root / bop.MODELS_DIR

    @property
    def models_eval_dir(self) -> Path:
        return self.root / bop.MODELS_EVAL_DIR

    def test_targets(self, kind: str) -> Path:
        """test_targets_{kind}.json, kind bop19 or bop24 (bop.TEST_TARGETS_FILES)."""
        return self.root / bop.TEST_TARGETS_FILES[kind]

    def record(self, split: str, sample_id: int) -> Path:
        return self.chunk_dir(split, sample_id) / "records" / f"{sample_id:06d}.json"

    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST

    @property
    def metadata_path(self) -> Path:
        return self.root / METADATA_FILE

    @property
    def config_path(self) -> Path:
        """The resolved generator config (every sampling distribution) the dataset was rendered with."""
        return self.root / "config.json"

    @property
    def splits_path(self) -> Path:
        return self.root / "splits.json"

    def record_paths(self) -> Iterator[Path]:
        yield from sorted(self.root.glob("*/[0-9]*/records/[0-9]*.json"))


def scene_size_of(manifest: dict[str, Any]) -> int:
    """Samples per BOP scene folder of a dataset with this manifest: its sequences' frames, else CHUNK."""
    sequence = manifest.get("sequence")
    return int(sequence["frames"]) if sequence else CHUNK


def sample_count(manifest: dict[str, Any]) -> int:
    """Samples (images) of a whole dataset with this manifest: n, or n sequences of their frames."""
    sequence = manifest.get("sequence")
    return int(manifest["n"]) * (int(sequence["frames"]) if sequence else 1)


DATASET_FILES = "dataset files"  # bytes_by_kind's kind of the root's files, models/ and models_eval/


def bytes_by_kind(root: str | Path) -> dict[str, int]:
    """Bytes on disk under a dataset folder by kind: each per-sample folder of the chunks (rgb, mask,
    mask_visib, xyz, depth, records, ...), the chunks' own BOP JSON files ("scene json"), and the files
    of the dataset as a whole (DATASET_FILES: at the root, models/, models_eval/)."""
    root = Path(root)
    kinds: dict[str, int] = defaultdict(int)
    for path in root.rglob("*"):
        if path.is_file():
            parts = path.relative_to(root).parts  # split / chunk / folder / file for a sample's file
            kind = parts[2] if len(parts) == 4 else "scene json" if len(parts) == 3 else DATASET_FILES
            kinds[kind] += path.stat().st_size
    return dict(kinds)


def dumps(obj: Any) -> str:
    """Canonical JSON (sorted keys, fixed indent) so identical content gives identical bytes."""
    return json.dumps(obj, indent=1, sort_keys=True) + "\n"


def open_dataset(root: str | Path) -> tuple[Layout, dict[str, Any]]:
    """The layout and manifest of an existing dataset; a clear error when `root` is not one."""
    layout = Layout(root)
    if not layout.root.is_dir():
        raise ScgenError(not_a_dataset(root, NOT_A_FOLDER))
    if not layout.manifest_path.is_file():
        raise ScgenError(not_a_dataset(root, f"has no {MANIFEST} (make one with `scgen render`)"))
    manifest = read_json(layout.manifest_path)
    if manifest.get("format") != FORMAT:
        raise ScgenError(
            f"unsupported dataset format {manifest.get('format')!r} in {layout.manifest_path} "
            f"(this scgen reads and writes {FORMAT!r}; render the dataset again)"
        )
    return layout, manifest


def object_names(manifest: dict[str, Any]) -> dict[int, str]:
    """obj_id -> model name of every labelled object: the target's (the manifest's `model`), then those of
    the config's [[objects]] (the manifest's `objects`, written only where there are some)."""
    others = {int(k): entry["name"] for k, entry in manifest.get("objects", {}).items()}
    return {OBJ_ID: manifest["model"]["name"], **dict(sorted(others.items()))}


def read_metadata(root: str | Path) -> list[dict[str, str]]:
    """Rows of metadata.csv (strings; callers convert the columns they use)."""
    layout, _ = open_dataset(root)
    if not layout.metadata_path.is_file():
        raise ScgenError(
            f"dataset {root} has no metadata.csv: the render did not finish (re-run it to resume)"
        )
    with open(layout.metadata_path, newline="") as f:
        return list(csv.DictReader(f))
