"""Build and import a robot's "python_c" extension: the generated C callable from Python at a
per-call overhead well under a microsecond (the numpy module pays tens of microseconds per call).

``load(robot_dir)`` compiles ``<robot_dir>/python_c/<robot>_ext.c`` (which includes
``<robot_dir>/c/<robot>.c``) with the running interpreter's compiler settings (sysconfig's
CC, CFLAGS and CCSHARED, then LDSHARED; plus EXTRA_FLAGS and the Python and numpy include
folders) into a cache folder, and imports it. The cache key is a hash of the three sources, the
compiler, the flags, the Python build and the numpy version, so a changed input rebuilds and
an unchanged one loads in milliseconds. Cache root: ``$KINDYNGEN_CACHE``, else
``$XDG_CACHE_HOME/kindyngen``, else ``~/.cache/kindyngen``. ``$CC`` overrides the compiler.

Without a C compiler ``load`` raises ``BuildError`` saying so: the pure-numpy module
``<robot_dir>/python/<robot>.py`` offers the same functions (and batches) without one.

Example (the functions take and return what the numpy module's do, one configuration each):

>>> import numpy as np
>>> from kindyngen.runtime import python_c
>>> lwr4 = python_c.load("generated/lwr4")          # compiles on first use   # doctest: +SKIP
>>> T = lwr4.fk_hom(np.zeros(7))                    # (4, 4) float64           # doctest: +SKIP
>>> float(T[2, 3])                                                              # doctest: +SKIP
0.79
>>> tau = lwr4.tau(np.zeros(7), np.zeros(7), np.zeros(7))   # = lwr4.g(q) here  # doctest: +SKIP
>>> q, status = lwr4.ik_hom(T, [0.3])               # a tuple, as in the numpy module  # doctest: +SKIP

From the shell: ``kindyngen build-python generated/lwr4`` builds and prints the module's path.
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import json
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

from ..model.user_text import is_identifier

# Modules imported in this process, by built file: a second load returns the same module.
_LOADED: dict = {}


class BuildError(RuntimeError):
    """The extension cannot be built or imported (no compiler, missing sources, compile error)."""


def cache_root() -> Path:
    if os.environ.get("KINDYNGEN_CACHE"):
        return Path(os.environ["KINDYNGEN_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "kindyngen"


def _sources(robot_dir: Path) -> tuple[str, list[Path]]:
    """The robot's identifier and [extension source, C source, C header]."""
    manifest = robot_dir / "functions.json"
    if not manifest.is_file():
        raise BuildError(f"{manifest}: not found (is {robot_dir} a generated robot folder?)")
    try:
        robot = json.loads(manifest.read_text())["robot"]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise BuildError(f"{manifest}: not a KinDynGen interface file ({exc})") from None
    if not isinstance(robot, str) or not is_identifier(robot):     # it names files and the module
        raise BuildError(f"{manifest}: robot {robot!r} is not an identifier (not a KinDynGen interface file, "
                         f"or one edited by hand)")
    files = [robot_dir / "python_c" / f"{robot}_ext.c", robot_dir / "c" / f"{robot}.c", robot_dir / "c" / f"{robot}.h"]
    for path, lang in zip(files, ("python_c", "c", "c")):
        if not path.is_file():
            raise BuildError(f"{path}: not found; generate the robot with --lang including {lang} "
                             f"(python_c needs c as well)")
    return robot, files


def _command(variable: str) -> list[str]:
    """A sysconfig compiler or linker command as a list, its program replaced by $CC's when set
    (as setuptools does), checked to exist."""
    words = shlex.split(sysconfig.get_config_var(variable) or "")
    if os.environ.get("CC"):
        cc = shlex.split(os.environ["CC"])
        words = cc + (words[1:] if words else [])
    if not words or shutil.which(words[0]) is None:
        where = f"$CC={os.environ['CC']!r}" if os.environ.get("CC") else f"sysconfig {variable}={words[:1]!r}"
        raise BuildError(f"no C compiler found ({where})")
    return words


# -O3 last so that it wins over CFLAGS' level; -ffp-contract=off keeps the generated C's
# roundings as written (GNU C modes may fuse a*b + c into an FMA on targets that have one, which
# would change results in the last bits and break the exact two-sum steps of the sin/cos kernel).
EXTRA_FLAGS = ("-O3", "-ffp-contract=off")


def build_commands(source: Path, obj: Path, target: Path) -> list[list[str]]:
    """Compile and link commands with the interpreter's own settings plus EXTRA_FLAGS."""
    import numpy
    cc, ld = _command("CC"), _command("LDSHARED")
    cflags = shlex.split(sysconfig.get_config_var("CFLAGS") or "") + shlex.split(sysconfig.get_config_var("CCSHARED") or "")
    includes = ["-I" + sysconfig.get_paths()["include"], "-I" + numpy.get_include()]
    return [cc + cflags + list(EXTRA_FLAGS) + includes + ["-c", str(source), "-o", str(obj)],
            ld + [str(obj), "-o", str(target), "-lm"]]


def build(robot_dir) -> Path:
    """Compile the extension of the generated robot in ``robot_dir`` (cached); its file."""
    import numpy
    robot_dir = Path(robot_dir)
    robot, files = _sources(robot_dir)
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    try:
        commands = build_commands(Path("SRC"), Path("OBJ"), Path("OUT"))   # as hashed: no paths
    except BuildError as exc:
        raise BuildError(f"{exc}: python_c needs one to build the extension; without one, use the pure-numpy "
                         f"module {robot_dir / 'python' / (robot + '.py')} (same functions and arguments, also "
                         f"for batches)") from None
    key = hashlib.sha256()
    for path in files:
        key.update(path.read_bytes())
    for cmd in commands:
        key.update("\0".join([shutil.which(cmd[0]) or cmd[0]] + cmd[1:]).encode())
    key.update(f"{sys.version}\0{suffix}\0{numpy.__version__}".encode())
    folder = cache_root() / "python_c" / f"{robot}-{key.hexdigest()[:20]}"
    target = folder / f"{robot}_ext{suffix}"
    if target.is_file():
        return target
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BuildError(f"cannot create the build cache {folder}: {exc.strerror} (set $KINDYNGEN_CACHE to a "
                         f"writable folder)") from None
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        obj, built = Path(tmp) / f"{robot}_ext.o", Path(tmp) / target.name
        for cmd in build_commands(files[0], obj, built):
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0:
                raise BuildError(f"building {files[0]} failed:\n$ {shlex.join(cmd)}\n{done.stderr.strip()}")
        os.replace(built, target)     # atomic: a concurrent build of the same key finds a whole file
    return target


def load(robot_dir):
    """The extension module of the generated robot in ``robot_dir``, built if needed."""
    target = build(robot_dir)
    if target in _LOADED:
        return _LOADED[target]
    name = target.name.split(".")[0]        # <robot>_ext: the PyInit_ symbol's name
    loader = importlib.machinery.ExtensionFileLoader(name, str(target))
    spec = importlib.util.spec_from_file_location(name, str(target), loader=loader)
    try:
        module = importlib.util.module_from_spec(spec)   # an extension is loaded and initialised here
        loader.exec_module(module)
    except ImportError as exc:
        raise BuildError(f"importing {target} failed: {exc}") from None
    _LOADED[target] = module
    return module
