"""Compile C/C++ into benchmarks/build/, cached by a hash of everything that decides the result.

The key covers the compiler's version line, the command line and the text of every source
(and of any extra files named, e.g. headers), so `make bench` rebuilds only what changed;
the slow header-only Pinocchio build in particular is done once per machine.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

BUILD = Path(__file__).resolve().parent / "build"


@lru_cache(maxsize=None)
def compiler_version(compiler: str) -> str:
    try:
        out = subprocess.run([compiler, "--version"], capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return "unavailable"
    return out.stdout.splitlines()[0].strip()


@dataclass(frozen=True)
class Built:
    path: Path
    seconds: float | None  # compile time of this binary (also when it came from the cache)
    cached: bool


def target(name: str, compiler: str, sources: list[Path], flags: list[str],
           libs: tuple[str, ...] = (), extra: tuple[Path, ...] = ()) -> Path:
    """The executable :func:`build` makes of these arguments (it exists once built)."""
    digest = hashlib.sha256()
    digest.update(compiler_version(compiler).encode())
    digest.update("\0".join(flags + list(libs)).encode())
    for path in list(sources) + list(extra):
        digest.update(Path(path).read_bytes())
    return BUILD / f"{name}-{digest.hexdigest()[:16]}"


def build(name: str, compiler: str, sources: list[Path], flags: list[str],
          libs: tuple[str, ...] = (), extra: tuple[Path, ...] = ()) -> Built:
    """Compile ``sources`` into an executable named after ``name`` and the hash."""
    out = target(name, compiler, sources, flags, libs, extra)
    record = Path(f"{out}.seconds")  # the compile time, kept beside the binary
    if out.exists():
        seconds = float(record.read_text()) if record.exists() else None
        return Built(out, seconds, True)
    BUILD.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f".{os.getpid()}.tmp")   # two processes building the same target do not share a file
    cmd = [compiler, *flags, *map(str, sources), "-o", str(tmp), *libs]
    start = time.perf_counter()
    result = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise RuntimeError(f"build of {name} failed ({' '.join(cmd)}):\n{result.stderr[-4000:]}")
    shutil.move(tmp, out)   # only a finished build ever carries the cache name
    record.write_text(f"{seconds:.2f}\n")
    for stale in BUILD.glob(f"{name}-*"):  # older builds of the same thing: never used again
        if not stale.name.startswith(out.name) and not stale.name.endswith(".tmp"):
            stale.unlink(missing_ok=True)
    return Built(out, seconds, False)
