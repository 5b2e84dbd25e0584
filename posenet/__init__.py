"""posenet: GDR-Net / GAP-GDRNet 6D pose networks trained and evaluated on scgen (BOP-layout) datasets.

OpenMP's idle threads wait passively here (OMP_WAIT_POLICY=PASSIVE, unless the environment sets it):
otherwise torch's intra-op threads spin at every barrier, and on a shared CPU (the loader processes,
other jobs) a spinning thread holds the core that the thread it waits for needs. On 2 shared cores that
made a smoke-preset training step take 4-12 s instead of ~1 s. OpenMP reads the variable once, when torch
is imported: importing posenet first sets it.
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# the `posenet` command's imports (torch, timm), timed by posenet.console: a training run's first seconds
IMPORT_SECONDS: float | None = None
