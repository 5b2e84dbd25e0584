"""Default worker and thread counts follow the cores a process may run on (a Slurm job, `taskset`, a
container's cpuset), not the machine's count."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from scgen.io.cores import seeing_cores

COUNTS = """
from posenet.training.train import cpu_threads
from scgen.io import usable_cores
from scgen.render.base import renderer_threads
print(usable_cores(), cpu_threads(0), renderer_threads("blender", 1))
"""


@pytest.mark.skipif(
    not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2, reason="needs 2 usable cores"
)
def test_a_process_held_to_one_core_defaults_to_one_worker_and_one_thread() -> None:
    one = min(os.sched_getaffinity(0))
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    done = subprocess.run(
        [sys.executable, "-c", COUNTS],
        env=env,
        preexec_fn=lambda: os.sched_setaffinity(0, {one}),
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.split() == ["1", "1", "1"], done.stderr
    # and the same counts, unrestricted, are this process's cores
    done = subprocess.run([sys.executable, "-c", COUNTS], env=env, capture_output=True, text=True, check=True)
    assert done.stdout.split() == [str(len(os.sched_getaffinity(0)))] * 3, done.stderr


@pytest.mark.skipif(
    not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2, reason="needs 2 usable cores"
)
def test_seeing_fewer_cores_lasts_only_while_open() -> None:
    """What a library sizes its pool from inside (Blender's import) sees the cores asked for; the process
    runs on all of its cores again after, even when the body raised."""
    cores = os.sched_getaffinity(0)
    with seeing_cores(1):
        assert len(os.sched_getaffinity(0)) == 1
    assert os.sched_getaffinity(0) == cores
    with pytest.raises(RuntimeError), seeing_cores(1):
        raise RuntimeError
    assert os.sched_getaffinity(0) == cores
    with seeing_cores(None), seeing_cores(len(cores)):
        assert os.sched_getaffinity(0) == cores
