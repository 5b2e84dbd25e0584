"""The primitives the bundled models are built from: each a (material, mesh) part in the builder's units,
before scgen.scenes.model.normalise_parts centres and scales the whole."""

from __future__ import annotations

import numpy as np
import trimesh

Part = tuple[str, trimesh.Trimesh]


def box(extents, centre, material: str) -> Part:
    """An axis-aligned box of `extents` centred on `centre`."""
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(centre)
    return material, m


def cylinder(p0, p1, radius: float, material: str, sections: int = 16) -> Part:
    """A closed cylinder from `p0` to `p1`."""
    return material, trimesh.creation.cylinder(radius=radius, segment=[p0, p1], sections=sections)


def revolve(profile: np.ndarray, sections: int) -> trimesh.Trimesh:
    """The solid swept by a closed (radius, z) profile about z, its faces wound outward (positive volume)
    whichever way the profile runs: a one-sided renderer (Mitsuba's BSDFs) shades only a face's front."""
    mesh = trimesh.creation.revolve(profile, sections=sections)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def dish(centre, radius: float, depth: float, material: str) -> Part:
    """A thin parabolic reflector, opening towards +z, built by revolving its profile."""
    r = np.linspace(0.0, radius, 24)
    z = depth * (r / radius) ** 2
    inner = np.column_stack([r, z])
    outer = np.column_stack([r[::-1], z[::-1] - 0.01])
    profile = np.vstack([inner, outer])
    m = revolve(profile, sections=48)
    m.apply_translation(centre)
    return material, m


def nozzle(centre, radius: float, length: float, material: str) -> Part:
    """A bell nozzle pointing along -z."""
    s = np.linspace(0, 1, 12)
    r = radius * (0.35 + 0.65 * s**1.5)
    z = -length * s
    profile = np.vstack([np.column_stack([r, z]), np.column_stack([r[::-1] * 0.9, z[::-1]])])
    m = revolve(profile, sections=24)
    m.apply_translation(centre)
    return material, m
