"""Triangle meshes of non-target objects, identical for every backend (so labels agree).

The geometry itself lives in scgen.scenes.props, where the sampler uses it to place occluders
and shadow casters; this module only places it in the camera frame as one mesh.
"""

from __future__ import annotations

import numpy as np
import trimesh

from scgen.scenes.props import local_pieces
from scgen.scenes.spec import PropSpec


def prop_mesh(prop: PropSpec) -> trimesh.Trimesh:
    """The prop's triangle mesh in the camera frame."""
    pieces = local_pieces(prop.shape, np.asarray(prop.size), prop.seed)
    offsets = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
    vertices = np.concatenate([v for v, _ in pieces]) @ prop.pose.R_mat.T + prop.pose.t_vec
    faces = np.concatenate([f + o for (_, f), o in zip(pieces, offsets, strict=True)])
    return trimesh.Trimesh(vertices, faces, process=False)
