"""scgen's bottom floor: the file formats and IO every floor above may import, and the one module posenet
reads scgen datasets through (tests/test_layering.py holds it to that).

`bop` (the BOP format: file names, millimetres, the JSON entries), `atomic` (writes that are whole or
absent), `exr` (xyz maps in OpenEXR), `image_file` (decoding images, and why one cannot be read),
`buffers` (what a renderer hands to annotation and the writer), `camera_presets` (the `--camera` presets
and each one's intrinsics), `sequence_frames` (which rendezvous frame each image is, from metadata.csv),
`cores` (the cores a process may run on: default workers and threads), `machine_cache` (what scgen keeps
on a machine between runs), `yaml_file` (YAML configs with YAML 1.2's floats, 1e-3 included),
`output_path` (the one rule for an output path) and `parent_watch` (worker pools that end with their
parent). The names below are posenet's interface.
"""

from scgen.errors import ScgenError
from scgen.io import bop
from scgen.io.atomic import atomic_write_bytes, atomic_write_text, remove_stale_temporaries
from scgen.io.bop import NOT_A_FOLDER, not_a_dataset
from scgen.io.camera_presets import preset_intrinsics
from scgen.io.cores import physical_memory_bytes, usable_cores
from scgen.io.exr import read_xyz_exr
from scgen.io.image_file import read_image, why_unreadable
from scgen.io.output_path import (
    check_output,
    existing_parent,
    first_missing,
    make_output_folder,
    write_output,
)
from scgen.io.sequence_frames import METADATA_FILE, SequenceFrame, read_sequence_frames
from scgen.io.yaml_file import NUMBER_FORM, load_yaml

__all__ = [
    "METADATA_FILE",
    "NOT_A_FOLDER",
    "NUMBER_FORM",
    "ScgenError",
    "SequenceFrame",
    "atomic_write_bytes",
    "atomic_write_text",
    "bop",
    "check_output",
    "existing_parent",
    "first_missing",
    "load_yaml",
    "make_output_folder",
    "not_a_dataset",
    "physical_memory_bytes",
    "preset_intrinsics",
    "read_image",
    "read_sequence_frames",
    "read_xyz_exr",
    "remove_stale_temporaries",
    "usable_cores",
    "why_unreadable",
    "write_output",
]
