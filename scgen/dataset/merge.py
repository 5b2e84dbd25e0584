"""`scgen merge`: join shard outputs into one dataset equal to a single run with the same seed."""

from __future__ import annotations

import shutil
from pathlib import Path

from scgen.dataset.layout import MANIFEST, Layout, open_dataset, sample_count
from scgen.dataset.writer import finalize
from scgen.errors import ScgenError

SAMPLE_FOLDERS = ("rgb", "mask", "mask_visib", "xyz", "depth", "records")


def merge_shards(out: Path, shards: list[Path]) -> tuple[int, int]:
    """Copy every complete sample of `shards` into `out` (created from the first shard); finalize.

    Returns (samples in out, samples of the whole dataset). Shards must share one manifest (seed, n, config,
    model, backend, ...); `out` may be one of the shards or a new folder.
    """
    manifests = [open_dataset(s)[1] for s in shards]
    for s, m in zip(shards[1:], manifests[1:], strict=True):
        if m != manifests[0]:
            diff = sorted(k for k in m.keys() | manifests[0].keys() if m.get(k) != manifests[0].get(k))
            raise ScgenError(f"cannot merge {s} with {shards[0]}: different settings ({', '.join(diff)})")
    if out.exists() and (out / MANIFEST).exists() and open_dataset(out)[1] != manifests[0]:
        raise ScgenError(f"cannot merge into {out}: it holds a dataset made with different settings")
    if out.exists() and not out.is_dir():
        raise ScgenError(f"output {out} exists and is not a directory")
    if not (out / MANIFEST).exists():
        shutil.copytree(shards[0], out, dirs_exist_ok=True, ignore=_only_static)
    layout = Layout(out)
    for shard in shards:
        if shard.resolve() == out.resolve():
            continue
        for record in Layout(shard).record_paths():
            chunk = record.parent.parent
            rel = chunk.relative_to(shard)
            for folder in SAMPLE_FOLDERS:
                for f in (chunk / folder).glob(f"{record.stem}*"):
                    dest = out / rel / folder / f.name
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    if folder != "records":
                        shutil.copy2(f, dest)
            dest = out / rel / "records" / record.name  # the record last: the sample is then complete
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(record, dest)
    return finalize(layout), sample_count(manifests[0])


def _only_static(directory: str, names: list[str]) -> list[str]:
    """copytree filter: keep the dataset's static files, skip the split folders' samples."""
    return [n for n in names if n in ("train", "val", "test")]
