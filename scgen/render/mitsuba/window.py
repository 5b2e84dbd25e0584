"""The film Mitsuba path-traces for a sample: a window over the region the objects cover.

Mitsuba compiles the film's size (and a crop's offset) into its render kernels as constants, so every new
window size costs frozen recordings (two, each compiling its kernels: about a second each here). The
window is therefore a camera of its own over part of the frame (the same focal length, the principal
point moved by the window's offset: no constant changes with it), each side an eighth, a quarter, a half
or the whole of the frame's (16 sizes, whose recordings a worker makes in its first samples), placed
inside the frame over the region. A finer ladder (2^k and 3 * 2^(k-1) px, ~130 sizes at 640x480) wasted
fewer pixels but was still recording a size in 4 of 5 samples after 40, and lost what it saved.
"""

from __future__ import annotations

import math

from scgen.render.region import Region

# The film's pixel filter: a tent of radius 1 px, whose spread (standard deviation 1/sqrt(6) = 0.408 px)
# is Cycles' Blackman-Harris at scgen's 1.5 px width (the window spans +-1.5 px: 0.416 px), so the two
# backends blur alike before the camera stage's PSF. Mitsuba's default gaussian (0.5 px, radius 2 px) was
# softer and splats each sample into 25 pixels where the tent's 3 x 3 take 9: the splat was most of an
# empty pixel's cost (docs/benchmarks.md, "Mitsuba: the pixel filter, the sky's maps kept, one light sphere").
FILTER_RADIUS_PX = 1.0  # a sample reaches this far from its pixel's centre
PIXEL_FILTER: dict[str, str | float] = {"type": "tent", "radius": FILTER_RADIUS_PX}
# A pixel's value is its samples' filter-weighted mean, misses included: a pixel within the filter's
# radius of an object is exact only if every sample within that radius of it is drawn, and those lie in
# pixels whose centre is up to another radius and half a pixel farther.
REACH_PX = 2 * FILTER_RADIUS_PX + 0.5
RUNGS = (8, 4, 2, 1)  # a window's side: the frame's side divided by one of these (rounded up)


def ladder_side(n: int, side: int) -> int:
    """The smallest rung (ceil(side / r) for r in RUNGS) holding n pixels."""
    return next(rung for rung in (math.ceil(side / r) for r in RUNGS) if rung >= n)


def film_window(region: Region) -> Region:
    """The pixels Mitsuba renders for `region`: a ladder-sized window holding it, inside the frame."""
    if region.full:
        return region
    x0, x1 = _placed(region.x0, region.x1, region.width)
    y0, y1 = _placed(region.y0, region.y1, region.height)
    return Region(x0, y0, x1, y1, region.width, region.height)


def _placed(lo: int, hi: int, side: int) -> tuple[int, int]:
    """[start, end) of the rung holding [lo, hi), moved back from the frame's far edge if need be."""
    size = ladder_side(hi - lo, side)
    start = min(lo, side - size)
    return start, start + size
