"""Which rendezvous-sequence frame each image of a dataset is, read from metadata.csv: the one reader of
sequence ids, times and motion for the floors above and for posenet (which reads datasets through
scgen.io)."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

from scgen.errors import ScgenError

METADATA_FILE = "metadata.csv"  # a dataset's table of every sample's factors (docs/dataset.md)
Vector = tuple[float, ...]


@dataclass(frozen=True)
class SequenceFrame:
    """Frame `frame` of sequence `sequence_id`, `time_s` seconds after its frame 0; the labelled motion
    there (dt/dt and the angular velocity relative to the camera, camera axes), whether it is in eclipse,
    the orbit's altitude, and what the chaser knows of itself: its camera's attitude in LVLH (quaternion
    w, x, y, z, camera -> LVLH), the camera's rate relative to LVLH (camera axes) and its thrust (LVLH,
    m/s^2 of the model's scale). None where the dataset has no such column (those written before them)."""

    sequence_id: int
    frame: int
    time_s: float
    velocity: Vector | None = None
    angular_velocity: Vector | None = None
    eclipse: bool | None = None
    altitude_km: float | None = None
    camera_attitude: Vector | None = None
    camera_rate: Vector | None = None
    thrust: Vector | None = None


# the optional columns: (field, its metadata.csv columns)
_VECTORS = (
    ("velocity", ("vx", "vy", "vz")),
    ("angular_velocity", ("wx", "wy", "wz")),
    ("camera_attitude", ("cam_qw", "cam_qx", "cam_qy", "cam_qz")),
    ("camera_rate", ("cam_wx", "cam_wy", "cam_wz")),
    ("thrust", ("thrust_x", "thrust_y", "thrust_z")),
)


def _frame(r: dict[str, str]) -> SequenceFrame:
    vectors = {name: tuple(float(r[c]) for c in cols) for name, cols in _VECTORS if cols[0] in r}
    eclipse = bool(int(r["eclipse"])) if "eclipse" in r else None
    altitude = float(r["altitude_km"]) if "altitude_km" in r else None
    return SequenceFrame(int(r["sequence_id"]), int(r["frame"]), float(r["time_s"]), eclipse=eclipse,
                         altitude_km=altitude, **vectors)  # fmt: skip


def read_sequence_frames(root: str | Path) -> dict[tuple[int, int], SequenceFrame]:
    """(scene_id, im_id) -> its SequenceFrame for every image of a sequence dataset at `root`; empty for a
    dataset of independent frames (no `sequence_id` column) or one without metadata.csv."""
    path = Path(root) / METADATA_FILE
    if not path.is_file():
        return {}
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        if not rows or "sequence_id" not in rows[0]:
            return {}
        return {(int(r["scene_id"]), int(r["im_id"])): _frame(r) for r in rows}
    except (OSError, KeyError, ValueError, csv.Error) as exc:
        raise ScgenError(f"{path}: cannot read the sequence frames ({type(exc).__name__}: {exc})") from exc
