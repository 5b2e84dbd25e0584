"""The config's `[[objects]]`: labelled objects beside the target, each with its model, count, distance
range and attitude distribution, and in a `[sequence]` its separation from the target (docs/config.md,
"objects").

The table is kept only where given, so a one-object config (and its dataset) is what it always was.
An entry's `distance` and `pose` tables take the top-level ones' keys and default to them (pose: uniform);
its `model` is a bundled name (scgen.scenes.bundled_models) or a mesh file, a relative path read from the
config file's folder.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from scgen.errors import ScgenError
from scgen.scenes.attitude import check_pose
from scgen.scenes.bundled_models import BUNDLED_MODELS, DEFAULT_MODEL
from scgen.scenes.config.checks import check_distance, check_range

ENTRY_KEYS = ("model", "count", "distance", "pose", "separation_m")
SEPARATION_M = [8.0, 20.0]  # with [sequence]: the ellipse centre's distance from the target along V-bar (m)
MAX_INSTANCES = 64  # labelled objects a scene may hold beside the target (BOP's GT ids are per image)


def merge_objects(entries: Any, folder: Path | None) -> list[dict[str, Any]]:
    """The `[[objects]]` entries of one config layer, their model paths made absolute (relative to
    `folder`, the config file's, else the working folder); distance and pose are filled by resolve."""
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ScgenError("config key 'objects' must be a list of tables ([[objects]] in TOML)")
    out = []
    for i, entry in enumerate(entries):
        unknown = sorted(set(entry) - set(ENTRY_KEYS))
        if unknown:
            keys = ", ".join(ENTRY_KEYS)
            raise ScgenError(f"unknown config key 'objects[{i}].{unknown[0]}' (an entry takes {keys})")
        model = entry.get("model")
        if not isinstance(model, str) or not model:
            raise ScgenError(f"objects[{i}].model must be a bundled model name or a mesh path, got {model!r}")
        if model not in BUNDLED_MODELS:
            path = Path(model).expanduser()
            model = str((path if path.is_absolute() or folder is None else folder / path).resolve())
        out.append({**copy.deepcopy(entry), "model": model})
    return out


def resolve_objects(cfg: dict[str, Any], default_pose: dict[str, Any]) -> None:
    """Fill each entry's defaults (count 1, the top-level distance, `default_pose`: the built-in pose table,
    uniform) and check it: a model that exists, a count in [1, MAX_INSTANCES], the distance and pose as
    the top-level ones are checked."""
    entries = cfg["objects"]
    total = 0
    for i, entry in enumerate(entries):
        name = f"objects[{i}]"
        model = entry["model"]
        if model not in BUNDLED_MODELS and not Path(model).is_file():
            raise ScgenError(f"{name}.model: no bundled model or mesh file {model!r} "
                             f"(bundled: {', '.join(BUNDLED_MODELS)})")  # fmt: skip
        count = entry.setdefault("count", 1)
        if not isinstance(count, int) or isinstance(count, bool) or not 1 <= count <= MAX_INSTANCES:
            raise ScgenError(f"{name}.count must be an integer in [1, {MAX_INSTANCES}], got {count!r}")
        total += count
        entry["distance"] = _table(name, "distance", cfg["distance"], entry.get("distance"))
        entry["pose"] = _table(name, "pose", default_pose, entry.get("pose"))
        entry.setdefault("separation_m", list(SEPARATION_M))
        check_range(f"{name}.separation_m", entry["separation_m"], low=1e-6)
        check_distance(f"{name}.distance", entry["distance"])
        try:
            check_pose(entry["pose"])
        except ScgenError as exc:
            raise ScgenError(f"{name}.{exc}") from None
    if total > MAX_INSTANCES:
        raise ScgenError(f"[[objects]] holds {total} instances, more than a scene's {MAX_INSTANCES}")


def _table(entry: str, key: str, default: dict[str, Any], given: Any) -> dict[str, Any]:
    """`default` with the entry's overrides of its keys."""
    if given is None:
        return copy.deepcopy(default)
    if not isinstance(given, dict):
        raise ScgenError(f"config key '{entry}.{key}' must be a table")
    unknown = sorted(set(given) - set(default))
    if unknown:
        raise ScgenError(f"unknown config key '{entry}.{key}.{unknown[0]}'")
    return {**copy.deepcopy(default), **copy.deepcopy(given)}


def object_models(cfg: dict[str, Any], target: str | None) -> list[str]:
    """The models of the dataset's objects, obj_id 1 first (the target, `target`: a bundled name or a mesh
    path; None: the default), then each `[[objects]]` model not named before, in order."""
    models = [DEFAULT_MODEL if target is None else _key(target)]
    for entry in cfg.get("objects", ()):
        if entry["model"] not in models:
            models.append(entry["model"])
    return models


def _key(model: str | Path) -> str:
    """A model as `[[objects]]` names it: a bundled name, or the file's absolute path."""
    return str(model) if str(model) in BUNDLED_MODELS else str(Path(model).expanduser().resolve())
