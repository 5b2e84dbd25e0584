"""What this machine gives a process: how many CPU cores it may run on (the default count of workers and
threads), and how much memory there is."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity where the OS has one (a Slurm job, `taskset`,
    a container's cpuset give fewer than the machine has, and os.cpu_count() counts the machine's), else
    every core; at least 1."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


@contextlib.contextmanager
def seeing_cores(n: int | None) -> Iterator[None]:
    """While open, this process runs on only `n` of its cores (its first ones); all of them again after.
    For libraries that size a thread pool from the cores they see when they start (Blender's TBB task
    scheduler): their idle threads then spin for work on the cores other workers use. Does nothing where
    `n` is None or not fewer than the cores, or the OS sets no affinity."""
    if n is None or not hasattr(os, "sched_setaffinity") or n >= usable_cores():
        yield
        return
    cores = os.sched_getaffinity(0)
    os.sched_setaffinity(0, sorted(cores)[: max(1, n)])
    try:
        yield
    finally:
        os.sched_setaffinity(0, cores)


def physical_memory_bytes() -> int | None:
    """The machine's physical memory in bytes, None where the OS does not say (what no frame can exceed)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None
