"""Which rendezvous-sequence frame each image of a dataset is, read from metadata.csv: the one reader of
sequence ids and times for the floors above and for posenet (which reads datasets through scgen.io)."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

from scgen.errors import ScgenError

METADATA_FILE = "metadata.csv"  # a dataset's table of every sample's factors (docs/dataset.md)


@dataclass(frozen=True)
class SequenceFrame:
    """Frame `frame` of sequence `sequence_id`, `time_s` seconds after its frame 0."""

    sequence_id: int
    frame: int
    time_s: float


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
        return {
            (int(r["scene_id"]), int(r["im_id"])): SequenceFrame(
                int(r["sequence_id"]), int(r["frame"]), float(r["time_s"])
            )
            for r in rows
        }
    except (OSError, KeyError, ValueError, csv.Error) as exc:
        raise ScgenError(f"{path}: cannot read the sequence frames ({type(exc).__name__}: {exc})") from exc
