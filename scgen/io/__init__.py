"""scgen's bottom floor: the file formats and IO every floor above may import, and the one module posenet
reads scgen datasets through (tests/test_layering.py holds it to that).

`bop` (the BOP format: file names, millimetres, the JSON entries), `atomic` (writes that are whole or
absent), `exr` (xyz maps in OpenEXR), `image_file` (decoding images, and why one cannot be read),
`buffers` (what a renderer hands to annotation and the writer), `camera_presets` (the `--camera` presets
and each one's intrinsics), `sequence_frames` (which rendezvous frame each image is, from metadata.csv),
`cores` (the cores a process may run on: default workers and threads), `machine_cache` (what scgen keeps
on a machine between runs), `yaml_file` (YAML configs with YAML 1.2's floats, 1e-3 included),
`output_path` (the one rule for an output path) and `parent_watch` (worker pools that end with their
parent). The names below are posenet's interface; each loads its module on first use.
"""

from importlib import import_module
from typing import Any

# each name's home module: loaded on first use, so that a command line's help, or a module needing one
# light name, does not load the BOP reader's trimesh or the image decoders
_HOMES = {
    "ScgenError": "scgen.errors",
    "bop": None,  # the submodule itself
    "atomic_write_bytes": "scgen.io.atomic",
    "atomic_write_text": "scgen.io.atomic",
    "remove_stale_temporaries": "scgen.io.atomic",
    "NOT_A_FOLDER": "scgen.io.bop",
    "not_a_dataset": "scgen.io.bop",
    "preset_intrinsics": "scgen.io.camera_presets",
    "physical_memory_bytes": "scgen.io.cores",
    "usable_cores": "scgen.io.cores",
    "read_xyz_exr": "scgen.io.exr",
    "read_image": "scgen.io.image_file",
    "why_unreadable": "scgen.io.image_file",
    "check_output": "scgen.io.output_path",
    "existing_parent": "scgen.io.output_path",
    "first_missing": "scgen.io.output_path",
    "make_output_folder": "scgen.io.output_path",
    "write_output": "scgen.io.output_path",
    "METADATA_FILE": "scgen.io.sequence_frames",
    "SequenceFrame": "scgen.io.sequence_frames",
    "read_sequence_frames": "scgen.io.sequence_frames",
    "NUMBER_FORM": "scgen.io.yaml_file",
    "load_yaml": "scgen.io.yaml_file",
}
__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module 'scgen.io' has no attribute {name!r}")
    home = _HOMES[name]
    if home is None:
        return import_module(f"scgen.io.{name}")
    return getattr(import_module(home), name)
