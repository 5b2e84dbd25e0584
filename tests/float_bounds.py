"""The one home for the tests' rounding bounds: how far two float32 forwards of one network may differ
(below), and two ray casters' depths (median_depth_gap).

Two runs of the same network differ in their summation order (another batch size is another GEMM
blocking; onnxruntime and torch have their own kernels; a module and its written-out equations group
their sums apart). By the probabilistic model of rounding (Higham & Mary 2019), a dot product of K terms
errs by ~sqrt(K) u relative (u = 2^-24, float32's unit roundoff), and L layers' errors add in quadrature:
sqrt(L K) u. Five times that (the model's tail bound at a probability far beyond any test's runs) bounds
each output relative to its scale. L counts every conv and linear layer (an upper bound on the longest
chain: a ResNet's downsampling shortcuts run beside its blocks, not after them) and K is the widest fan-in.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch
from torch import nn

from posenet.checkpoint import load_model

U32 = 2**-24  # float32's unit roundoff
U32_RAY_HIT = 128  # two ray casters' depths at one pixel, in u32 of the scale: median_depth_gap


def depth_and_width(model: nn.Module) -> tuple[int, int]:
    """L, the conv and linear layers of `model`, and K, the most products one output of them sums: a
    conv's in-channels per group x kernel taps, a transposed conv's taps that reach one output
    (ceil(kernel / stride) per axis), a linear layer's in-features."""
    depth = width = 0
    for m in model.modules():
        if isinstance(m, nn.modules.conv._ConvTransposeNd):
            taps = math.prod(-(-k // s) for k, s in zip(m.kernel_size, m.stride, strict=True))
        elif isinstance(m, nn.modules.conv._ConvNd):
            taps = math.prod(m.kernel_size)
        elif isinstance(m, nn.Linear):
            depth, width = depth + 1, max(width, m.in_features)
            continue
        else:
            continue
        depth, width = depth + 1, max(width, m.in_channels // m.groups * taps)
    return depth, width


def forward_rel(model: nn.Module) -> float:
    """5 sqrt(L K) u: two float32 forwards of `model` differ by at most this times each output's scale."""
    depth, width = depth_and_width(model)
    return 5 * math.sqrt(depth * width) * U32


def pose_checkpoint_rel(ckpt: Path) -> float:
    """forward_rel of a pose checkpoint's network (the suite's tiny one: L = 63, K = 1280, 8.5e-5)."""
    return forward_rel(load_model(ckpt, torch.device("cpu"))[0])


@contextmanager
def rotation_outputs() -> Iterator[list[torch.Tensor]]:
    """The 6D rotation output (B x 6) of every pose-network forward run inside, in order: what each R is
    the Gram-Schmidt of (posenet.geometry.rot6d_to_mat)."""
    seen: list[torch.Tensor] = []

    def keep(_module: nn.Module, _args: object, out: object) -> None:
        if isinstance(out, dict) and "rot6d" in out:
            seen.append(out["rot6d"].detach().clone())

    handle = nn.modules.module.register_module_forward_hook(keep)
    try:
        yield seen
    finally:
        handle.remove()


def gram_schmidt_gain(d6: torch.Tensor) -> float:
    """How many times the 6D output's rounding (rel of its largest entry s) an entry of R = rot6d_to_mat(d6)
    can move: x = a1 / |a1| by sqrt(3) s / |a1|, z = x cross a2 / |x cross a2| by sqrt(3) s (1 + |a2| / |a1|)
    / |x cross a2|, y = z cross x by the sum of both; an entry by at most its column's norm (which the
    allocentric-to-egocentric rotation keeps). A 6D output whose a2 lies near a1 is ill-conditioned: the
    tiny checkpoint's gains reach ~16."""
    a1, a2 = d6[:3].double(), d6[3:].double()
    s, n1 = float(d6.abs().max()), float(a1.norm())
    across = float(torch.linalg.cross(a1 / n1, a2).norm())
    return math.sqrt(3) * s * (1 / n1 + (1 + float(a2.norm()) / n1) / across)


def median_depth_gap(a: np.ndarray, b: np.ndarray, t: np.ndarray, diameter: float) -> float:
    """The median over the pixels both depth maps hit of |a - b| in u32 of the scale of the coordinates
    a hit is computed from: its depth, and the target's vertices, within |t| + D of the camera.

    At most U32_RAY_HIT for two ray casters that meet the same triangle on the same pixel-centre ray in
    float32: the hit distance is a ratio of triple products of vertex differences, ~16 roundings of
    coordinates of that scale, times 1/cos of the incidence, under 1/0.7 for most pixels (a body's pixels
    spread as cos(incidence): on a sphere a quarter lie past 60 deg), so ~32 u / 0.7 each and 128 u
    between two. A ray through another point of its pixel (a convention off by d px) moves a slanted
    surface by ~tan(incidence) z d / f: 0.1 px at f = 300 px and 45 deg is 3e-4 z, thousands of u."""
    both = (a > 0) & (b > 0)
    scale = b[both] + float(np.linalg.norm(t)) + diameter
    return float(np.median(np.abs(a[both] - b[both]) / scale)) / U32
