"""How far two float32 forwards of one network may differ: the one home for the tests' rounding bounds.

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
from pathlib import Path

import torch
from torch import nn

from posenet.checkpoint import load_model

U32 = 2**-24  # float32's unit roundoff


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
