"""Where the test suite's CPU time goes: each Python process's own CPU seconds, by test module.

    python benchmarks/probes/suite_cpu.py [--out DIR] [-- PYTEST ARGS ...]

Runs pytest (by default `make test`'s suite command: two pytest-xdist processes, whole modules each) with a
`sitecustomize` module first on PYTHONPATH that makes every Python process the suite starts log, when it
exits, its argv, its own user + sys CPU seconds and the test that was running (PYTEST_CURRENT_TEST), to
DIR/processes.jsonl. Then prints the pytest processes' CPU, the child processes' by test module, and the
suite's wall and total CPU (this process's children, from the OS). Processes that end without Python's
exit hooks (forked loader or render processes ending in os._exit, killed ones) log nothing: the gap
between the total and the logged sum is theirs. On 2 cores the suite lasts about as long as its CPU work
divided by 2 (docs/install.md), so this is what a shorter suite must cut.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the harness
from harness import ROOT, parser, run_script

SUITE = ["-q", "-n", "2", "--dist", "loadfile", "--no-loadscope-reorder", "-p", "no:cacheprovider"]
HOOK = '''"""Written by benchmarks/probes/suite_cpu.py: log this process's CPU seconds at exit."""
import atexit, json, os, resource, sys


def _log() -> None:
    r = resource.getrusage(resource.RUSAGE_SELF)
    record = {"argv": sys.argv[:4], "cpu_s": r.ru_utime + r.ru_stime,
              "test": os.environ.get("PYTEST_CURRENT_TEST", "")}
    with open(LOG, "a") as f:
        f.write(json.dumps(record) + "\\n")


atexit.register(_log)
'''
PYTEST_PROCESS_S = 100.0  # a process this busy is one of pytest's own (the workers run the tests inside)


def parse_args() -> argparse.Namespace:
    ap = parser(__doc__)
    ap.add_argument("--out", type=Path, default=Path("suite_cpu"), help="Where the log goes [suite_cpu].")
    ap.add_argument("pytest_args", nargs="*", help="pytest's arguments after `--` [make test's suite].")
    return ap.parse_args()


def run(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    log = (args.out / "processes.jsonl").resolve()
    log.unlink(missing_ok=True)
    (args.out / "sitecustomize.py").write_text(f"LOG = {str(log)!r}\n" + HOOK)
    paths = [str(args.out.resolve()), str(ROOT), os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p), "OMP_WAIT_POLICY": "PASSIVE"}
    tic = time.perf_counter()
    command = [sys.executable, "-m", "pytest", *(args.pytest_args or SUITE)]
    subprocess.run(command, cwd=ROOT, env=env, check=True)
    wall = time.perf_counter() - tic
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    total = children.ru_utime + children.ru_stime
    records = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    own = [r for r in records if r["cpu_s"] >= PYTEST_PROCESS_S and not r["test"]]
    by_module: dict[str, float] = collections.Counter()
    count: dict[str, int] = collections.Counter()
    for r in records:
        if r in own:
            continue
        module = r["test"].split("::")[0].rsplit("/", 1)[-1] or "(no test running)"
        by_module[module] += r["cpu_s"]
        count[module] += 1
    logged = sum(r["cpu_s"] for r in records)
    print(f"suite: {wall:.0f} s wall, {total:.0f} s CPU (user + sys of every process it started)")
    busiest = ", ".join(f"{r['cpu_s']:.0f} s" for r in own) or "none this busy"
    print(f"pytest's own processes: {busiest}")
    print(f"child processes by the test that started them ({sum(count.values())} processes):")
    for module, seconds in sorted(by_module.items(), key=lambda kv: -kv[1]):
        print(f"  {seconds:8.1f} s  {count[module]:4d}  {module}")
    print(f"not logged (forked or killed processes): {max(0.0, total - logged):.0f} s")


if __name__ == "__main__":
    run_script(run, parse_args())
