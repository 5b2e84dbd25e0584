"""A shuffling, rank-sharding sampler whose order depends only on (seed, epoch), resumable mid-epoch.

It yields (epoch, index) pairs so that the Dataset derives each sample's augmentation from
(seed, epoch, index) alone: the same batches come out whatever the worker count, and a resumed run
sees exactly the batches it would have seen without the interruption.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import torch
from torch.utils.data import Sampler

from posenet.data.curriculum import cone_cap_deg


class EpochSampler(Sampler[tuple[int, int]]):
    """Batches of `batch_size` per rank over `world` ranks; an incomplete last global batch is dropped."""

    def __init__(self, n: int, batch_size: int, world: int = 1, rank: int = 0, seed: int = 0) -> None:
        self.n, self.batch_size, self.world, self.rank, self.seed = n, batch_size, world, rank, seed
        self.epoch = 0
        self.skip_batches = 0

    @property
    def steps_per_epoch(self) -> int:
        return self.n // (self.batch_size * self.world)

    def set_epoch(self, epoch: int, skip_batches: int = 0) -> None:
        """Select the epoch's permutation and start after its first `skip_batches` steps."""
        self.epoch, self.skip_batches = epoch, skip_batches

    def __iter__(self) -> Iterator[tuple[int, int]]:
        g = torch.Generator().manual_seed(self.seed * 100_003 + self.epoch)
        perm = torch.randperm(self.n, generator=g)[: self.steps_per_epoch * self.batch_size * self.world]
        mine = perm[self.rank :: self.world].tolist()[self.skip_batches * self.batch_size :]
        return ((self.epoch, i) for i in mine)

    def __len__(self) -> int:
        return (self.steps_per_epoch - self.skip_batches) * self.batch_size


class CurriculumSampler(EpochSampler):
    """EpochSampler's steps, each batch drawn (with replacement) from the instances inside the attitude
    curriculum's corridor at that step (curriculum.py): `start_deg` about the nominal line of sight at
    step 0, every instance from step `widen_steps` on. The draws depend only on (seed, epoch), so a
    resumed run sees the batches it would have seen."""

    def __init__(self, tilts_deg: np.ndarray, batch_size: int, world: int, rank: int, seed: int,
                 start_deg: float, widen_steps: int) -> None:  # fmt: skip
        super().__init__(len(tilts_deg), batch_size, world, rank, seed)
        self.order = torch.from_numpy(np.argsort(tilts_deg, kind="stable"))
        self.sorted_tilts = np.sort(tilts_deg)
        self.start_deg, self.widen_steps = start_deg, max(1, widen_steps)

    def eligible(self, step: int) -> int:
        """How many instances (the least tilted first) the corridor holds at `step`: at least a batch."""
        cap = cone_cap_deg(self.start_deg, step / self.widen_steps)
        inside = int(np.searchsorted(self.sorted_tilts, cap, side="right"))
        return min(self.n, max(inside, self.batch_size * self.world))

    def __iter__(self) -> Iterator[tuple[int, int]]:
        g = torch.Generator().manual_seed(self.seed * 100_003 + self.epoch)
        per_step = self.batch_size * self.world
        first = self.epoch * self.steps_per_epoch
        draws = [self.order[torch.randint(self.eligible(first + b), (per_step,), generator=g)]
                 for b in range(self.steps_per_epoch)]  # fmt: skip
        mine = [i for d in draws[self.skip_batches :] for i in d[self.rank :: self.world].tolist()]
        return ((self.epoch, i) for i in mine)
