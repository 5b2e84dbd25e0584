"""A shuffling, rank-sharding sampler whose order depends only on (seed, epoch), resumable mid-epoch.

It yields (epoch, index) pairs so that the Dataset derives each sample's augmentation from
(seed, epoch, index) alone: the same batches come out whatever the worker count, and a resumed run
sees exactly the batches it would have seen without the interruption.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator

import torch
from torch.utils.data import Sampler


class EpochSampler(Sampler[tuple[int, int]]):
    """Batches of `batch_size` per rank over `world` ranks; an incomplete last global batch is dropped.

    One iterator runs epoch after epoch without end, from the start `set_epoch` chose: a DataLoader's
    processes then read ahead across an epoch's end, where a new iterator per epoch makes the first step
    of every epoch wait for its batch to load (on the 16-image learning set, every second step). The
    training loop stops at its step."""

    def __init__(self, n: int, batch_size: int, world: int = 1, rank: int = 0, seed: int = 0) -> None:
        self.n, self.batch_size, self.world, self.rank, self.seed = n, batch_size, world, rank, seed
        self.epoch = 0
        self.skip_batches = 0

    @property
    def steps_per_epoch(self) -> int:
        return self.n // (self.batch_size * self.world)

    def set_epoch(self, epoch: int, skip_batches: int = 0) -> None:
        """Start the stream at `epoch`, after its first `skip_batches` steps."""
        self.epoch, self.skip_batches = epoch, skip_batches

    def epoch_indices(self, epoch: int, skip_batches: int = 0) -> list[tuple[int, int]]:
        """This rank's (epoch, index) pairs of `epoch` after its first `skip_batches` steps."""
        g = torch.Generator().manual_seed(self.seed * 100_003 + epoch)
        perm = torch.randperm(self.n, generator=g)[: self.steps_per_epoch * self.batch_size * self.world]
        mine = perm[self.rank :: self.world].tolist()[skip_batches * self.batch_size :]
        return [(epoch, i) for i in mine]

    def __iter__(self) -> Iterator[tuple[int, int]]:
        if self.steps_per_epoch == 0:  # fewer samples than one batch: no batch, rather than a spin
            return
        for epoch in itertools.count(self.epoch):
            yield from self.epoch_indices(epoch, self.skip_batches if epoch == self.epoch else 0)
