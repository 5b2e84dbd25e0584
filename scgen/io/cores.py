"""How many CPU cores this process may run on: the default count of workers and threads."""

from __future__ import annotations

import os


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity where the OS has one (a Slurm job, `taskset`,
    a container's cpuset give fewer than the machine has, and os.cpu_count() counts the machine's), else
    every core; at least 1."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1
