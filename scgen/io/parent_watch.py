"""Worker processes end with the process that started them, even when it was killed by a signal."""

from __future__ import annotations

import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any


def exit_with_parent(poll_s: float = 0.5) -> None:
    """In a pool's worker process: end it once the process that started it is gone.

    A main process killed by a signal (SIGTERM, SIGKILL) runs no clean-up, and its workers would keep
    waiting on the pool's queue, each holding a renderer in memory. A daemon thread notices the new parent
    (the process is re-parented) and exits; the samples are written atomically, so nothing is lost.
    """
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _start_worker(initializer: Callable[..., None] | None, *initargs: Any) -> None:
    exit_with_parent()
    if initializer is not None:
        initializer(*initargs)


def spawn_pool(
    workers: int, initializer: Callable[..., None] | None = None, initargs: tuple[Any, ...] = ()
) -> ProcessPoolExecutor:
    """A pool of `workers` spawned processes (no forked renderer state) that each run `initializer` and
    end with this process (exit_with_parent).

    Their numpy's BLAS runs on one thread (OPENBLAS_NUM_THREADS, unless set): the renderer's threads hold
    the cores, and waking BLAS threads beside them cost about 1.4 ms per small call (a 3 x 3 inverse),
    some 20 ms of a 64 x 48 Mitsuba sample on 2 cores.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # read as a process loads numpy: here, the workers
    return ProcessPoolExecutor(workers, mp.get_context("spawn"), _start_worker, (initializer, *initargs))
