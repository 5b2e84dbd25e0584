"""Worker processes end with the process that started them, even when it was killed by a signal."""

from __future__ import annotations

import os
import threading
import time


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
