"""Which Mitsuba variant this process renders with, and the libLLVM behind it: decided once per process.

Dr.Jit loads libLLVM when it is imported (the file in DRJIT_LIBLLVM_PATH, else one it finds), and LLVM
aborts the whole process on a kernel that libLLVM cannot compile (15: `Cannot select: fminimum`), where
no `except` reaches. So before this process imports drjit, a child process renders a real sample with
the LLVM variant (scgen.render.probe). When drjit's own pick fails and DRJIT_LIBLLVM_PATH is not set,
the newer libLLVMs on the machine are tried, newest first, and the first that renders is set in
DRJIT_LIBLLVM_PATH; otherwise Mitsuba renders with scalar_rgb, after one line saying why and how to get
the fast path. The verdict is kept in the environment: worker processes started later take it over
instead of probing again. A libLLVM that rendered is also kept on disk (verdict_file, ~3 s saved per
run): the next process trusts it while nothing it depended on has changed (the versions of Dr.Jit and
Mitsuba, the libLLVM asked for, every libLLVM file on the machine, the loader's search path, scgen's
render code: machine_key).
"""

from __future__ import annotations

import functools
import glob
import hashlib
import importlib.metadata
import json
import os
import re
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from scgen.io import atomic_write_text
from scgen.io.machine_cache import cache_dir
from scgen.render.probe import probe

LIBLLVM_ENV = "DRJIT_LIBLLVM_PATH"  # Dr.Jit's own setting
VERDICT_ENV = "SCGEN_MITSUBA_VARIANT"  # the verdict, for the processes this one starts
RENDER_CODE = Path(__file__).resolve().parents[1]  # scgen/render: what the probe sample runs
VERDICTS_KEPT = 16  # the newest verdicts the file holds (one per libLLVM asked for and version of the code)
LLVM_VARIANT, SCALAR_VARIANT = "llvm_ad_rgb", "scalar_rgb"
# where Debian/Ubuntu (also the llvm-N trees), Fedora/RHEL and local builds install libLLVM
LIBLLVM_GLOBS = ("/usr/lib/*-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*",
                 "/usr/lib64/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*")  # fmt: skip
FAST_PATH = f"apt-get install libllvm19, or set {LIBLLVM_ENV} to a newer libLLVM"


@dataclass(frozen=True)
class Libllvm:
    """One libLLVM as a probe found it: its file and version (None: unknown), and why Mitsuba cannot
    render with it (None: it can); `tested` False when the probe failed before it reached Mitsuba, so
    its error is not the libLLVM's."""

    path: str | None
    version: str | None
    error: str | None
    tested: bool = True

    def __str__(self) -> str:
        if self.path is None:
            return "the libLLVM drjit looks for"
        return f"libLLVM {self.version} ({self.path})" if self.version else self.path


@dataclass(frozen=True)
class MitsubaSetup:
    """The variant to render with, the libLLVM it was decided on (the one in use, or the one that failed),
    the line to print when that is not what was asked for, and how to get the fast path without it."""

    variant: str
    libllvm: Libllvm
    notice: str | None = None
    fix: str | None = None


@functools.cache
def mitsuba_setup() -> MitsubaSetup:
    """This process's setup: the one of the process that started it when made for the same
    DRJIT_LIBLLVM_PATH, else checked here (its notice printed once) and passed on in the environment."""
    inherited = json.loads(os.environ.get(VERDICT_ENV) or "{}")
    if inherited and inherited.pop("for") == os.environ.get(LIBLLVM_ENV, ""):
        return MitsubaSetup(inherited.pop("variant"), Libllvm(**inherited))
    setup = check_mitsuba()
    if setup.notice:
        print(f"scgen: {setup.notice}", file=sys.stderr)
    verdict = {"for": os.environ.get(LIBLLVM_ENV, ""), "variant": setup.variant, **asdict(setup.libllvm)}
    os.environ[VERDICT_ENV] = json.dumps(verdict)
    return setup


def check_mitsuba(fresh: bool = False) -> MitsubaSetup:
    """Probe the libLLVM drjit would load, then newer ones; sets DRJIT_LIBLLVM_PATH to a newer one it picks.

    DRJIT_LIBLLVM_PATH, when set, is the user's choice and the only one tried. Once drjit is imported its
    libLLVM is fixed for this process, so then only that one is tried too. `fresh`: probe even where a
    verdict on disk says the libLLVM renders (`scgen doctor`).
    """
    forced = os.environ.get(LIBLLVM_ENV) or None
    first = probe_libllvm(forced, fresh)
    if first.error is None:
        return MitsubaSetup(LLVM_VARIANT, first)
    if not first.tested:  # nothing learnt of the libLLVM: keep drjit's own, say what failed instead
        return MitsubaSetup(LLVM_VARIANT, first, f"libLLVM not checked: its test render failed before "
                            f"Mitsuba started: {first.error}")  # fmt: skip
    cannot = f"Mitsuba cannot render with {first}: {first.error}"
    newer = newer_libllvms(first)
    search = forced is None and "drjit" not in sys.modules
    for path in newer if search else []:
        found = probe_libllvm(path, fresh)
        if found.error is None:
            os.environ[LIBLLVM_ENV] = path
            return MitsubaSetup(LLVM_VARIANT, found, f"{cannot}; using {found}, found on this machine")
    fix = FAST_PATH + (f" ({newer[0]} is on this machine)" if newer and not search else "")
    fallback = f"rendering with {SCALAR_VARIANT} (slower). For the fast LLVM variant: {fix}"
    return MitsubaSetup(SCALAR_VARIANT, first, f"{cannot}; {fallback}", fix)


def probe_libllvm(path: str | None, fresh: bool = False) -> Libllvm:
    """Render the probe sample with libLLVM `path` (None: the one drjit picks itself) in a child process,
    unless (`fresh` False) the verdict file holds one that rendered on this machine as it is now."""
    if path is not None and not os.path.exists(path):
        return Libllvm(path, None, "no such file")
    key = machine_key(path)
    kept = {} if fresh else read_verdicts().get(key)
    if kept and os.path.exists(kept["path"] or "/"):
        return Libllvm(**kept)
    env = {k: v for k, v in os.environ.items() if k not in (LIBLLVM_ENV, VERDICT_ENV)}
    if path is not None:
        env[LIBLLVM_ENV] = path
    result = probe("mitsuba", env)
    loaded = result.facts.get("libllvm") or path
    major = libllvm_major(loaded) if loaded else None  # drjit reports no version for one it refuses
    version = result.facts.get("version") or (str(major) if major else None)
    found = Libllvm(loaded, version, result.error, result.error is None or result.reached_renderer)
    if found.error is None:  # only a success is kept: a failure may pass (a full disk, a killed child)
        remember_verdict(key, found)
    return found


def verdict_file() -> Path:
    """The libLLVMs that rendered, by machine_key, in scgen's cache folder (scgen.io.machine_cache)."""
    return cache_dir() / "libllvm.json"


def machine_key(path: str | None) -> str:
    """A digest of what a probe of libLLVM `path` depends on: Dr.Jit's and Mitsuba's versions, the path,
    every libLLVM file drjit may load (LIBLLVM_GLOBS and `path`: size and modification time), the dynamic
    loader's search path and scgen's render code (the kernels it has LLVM compile)."""
    files = sorted({p for pattern in LIBLLVM_GLOBS for p in glob.glob(pattern)} | ({path} if path else set()))
    stats = [(p, st.st_size, st.st_mtime_ns) for p in files if (st := _stat(p))]
    versions = [importlib.metadata.version(name) for name in ("drjit", "mitsuba")]
    digest = hashlib.sha256()
    for source in sorted(RENDER_CODE.rglob("*.py")):
        digest.update(source.read_bytes())
    facts = [versions, path, os.environ.get("LD_LIBRARY_PATH", ""), stats, digest.hexdigest()]
    return hashlib.sha256(json.dumps(facts).encode()).hexdigest()


def _stat(path: str) -> os.stat_result | None:
    try:
        return os.stat(path)
    except OSError:  # a dangling link
        return None


def read_verdicts() -> dict[str, dict]:
    """The verdict file's entries ({} where it is missing or unreadable: then each libLLVM is probed)."""
    try:
        return json.loads(verdict_file().read_text())
    except (OSError, ValueError, RuntimeError):  # RuntimeError: Path.home() with no home to find
        return {}


def remember_verdict(key: str, found: Libllvm) -> None:
    """Add `found` to the verdict file (its newest VERDICTS_KEPT entries stay); where it cannot be written
    (a read-only home) nothing is kept."""
    try:
        path = verdict_file()
        path.parent.mkdir(parents=True, exist_ok=True)
        kept = {k: v for k, v in read_verdicts().items() if k != key} | {key: asdict(found)}
        newest = dict(list(kept.items())[-VERDICTS_KEPT:])  # the file does not grow with every upgrade
        atomic_write_text(path, json.dumps(newest, indent=1) + "\n")
    except (OSError, RuntimeError):
        pass


def newer_libllvms(than: Libllvm) -> list[str]:
    """The libLLVM files on this machine newer than `than` (all of them when its version is unknown),
    newest first; one path per file."""
    floor = int(than.version.split(".")[0]) if than.version else 0
    files = {os.path.realpath(p) for pattern in LIBLLVM_GLOBS for p in glob.glob(pattern)}
    versions = [(libllvm_major(p) or 0, p) for p in files]
    return [p for v, p in sorted(versions, reverse=True) if v > floor]


def libllvm_major(path: str) -> int | None:
    """The LLVM major version in a libLLVM file name (libLLVM-15.so.1, libLLVM.so.19.1), or None."""
    m = re.search(r"libLLVM(?:-(\d+)|\.so\.(\d+))", os.path.basename(path))
    return int(m.group(1) or m.group(2)) if m else None
