"""Output folders replaced whole: a run's files are written into a staging folder beside the
target and swapped in at the end, so a killed, interrupted or failed run leaves the previous
output byte for byte, and a finished one leaves exactly its own files (plus the user's).

Used by every command that writes a folder (``generate``'s ``OUT/<robot>/`` through
:func:`kindyngen.codegen.pipeline.generate`; ``identify``, ``discover``, ``excite``,
``reproduce-identification``) and by the benchmarks' results writers. It belongs to no stage:
it knows folders and files, nothing of robots.

How :func:`replace_folder` replaces ``out``:

1. Left-overs of killed runs beside ``out`` are tidied first (:func:`tidy_leftovers`): only
   folders named like ours (``.<name>.kdg-staging.<host>.<pid>.<random>``, or ``kdg-previous``)
   whose process, on this host, is gone.
2. ``write(staging)`` writes the new output into a fresh staging folder beside ``out`` (same
   file system). If it raises (an error, ``KeyboardInterrupt``), the staging folder is removed
   and ``out`` was never touched.
3. The user's files are carried over: every file of the previous ``out`` that its manifest (the
   ``previous_files(out)`` callback: the files the generator wrote last time) does not list is
   hard-linked (copied where links fail) into the staging folder, at the same relative path,
   unless the new run wrote that path. Files the previous manifest lists and the new run did not
   write are thereby dropped. A previous folder without a manifest keeps every file the new run
   does not overwrite (nothing is removed that is not known to be ours).
4. The swap, with SIGINT and SIGTERM held back until it is done: on Linux one
   ``renameat2(RENAME_EXCHANGE)`` call exchanges the two folders atomically (the old one then
   sits under the staging name and is removed). Where that call does not exist or the file
   system refuses it, the fallback renames ``out`` aside (``kdg-previous``), renames the staging
   folder in, and removes the aside folder: a kill between the two renames leaves no ``out``
   and the aside folder, which the next run into the same place renames back (the previous
   output, whole). No ``fsync``: a killed process is covered, a power cut is not.

Several files of one run into a folder that holds other runs' files too (benchmarks/results/):
:func:`replace_files`, all or none (a kill while they are moved in is finished by the next
run). One file: :func:`replace_file`.

Example (the second run drops ``b.txt``, which the first run's manifest lists, and keeps the
user's ``notes.txt``):

>>> import tempfile
>>> out = Path(tempfile.mkdtemp()) / "run"
>>> def run(*names):
...     def write(folder):
...         for name in names:
...             (folder / name).write_text(name)
...     return replace_folder(out, write, lambda folder: {"a.txt", "b.txt"})
>>> run("a.txt", "b.txt")
>>> (out / "notes.txt").write_text("mine")
4
>>> run("a.txt")
>>> sorted(p.name for p in out.iterdir()), sorted(p.name for p in out.parent.iterdir())
(['a.txt', 'notes.txt'], ['run'])
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import secrets
import shutil
import signal
import socket
import sys
import threading
from pathlib import Path
from typing import Callable, Iterable

STAGING, PREVIOUS, FILES = "kdg-staging", "kdg-previous", "kdg-files"
#: in a replace_files staging folder: its files are complete and are being moved in
MOVING_MARK = ".kdg-moving"
#: test hooks (environment): stop the process (SIGSTOP) at a named point of the commit (staged,
#: aside, swapped, moving: see _pause's callers), so that a test can kill it exactly there; and
#: use the fallback swap instead of renameat2
PAUSE_VARIABLE = "KINDYNGEN_PAUSE_AT"
NO_EXCHANGE_VARIABLE = "KINDYNGEN_NO_RENAME_EXCHANGE"


class OutputFolderError(OSError):
    """An output folder that cannot be written, or a file in the way of one."""


def _host() -> str:
    """This host's name as it may appear in a folder name (letters, digits, - and _)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname())[:40] or "host"


def _leftover_pattern(name: str) -> re.Pattern:
    """Names of the staging and aside folders of ``name``.

    >>> m = _leftover_pattern("lwr4").match(".lwr4.kdg-staging.box-1.4242.9f3a01bc")
    >>> m["kind"], m["host"], m["pid"]
    ('kdg-staging', 'box-1', '4242')
    >>> _leftover_pattern("lwr4").match(".panda.kdg-staging.box-1.4242.9f3a01bc") is None
    True
    """
    return re.compile(rf"^\.{re.escape(name)}\.(?P<kind>{STAGING}|{PREVIOUS}|{FILES})\.(?P<host>[A-Za-z0-9_-]+)"
                      rf"\.(?P<pid>\d+)\.[0-9a-f]+$")


def _leftover_name(name: str, kind: str) -> str:
    return f".{name}.{kind}.{_host()}.{os.getpid()}.{secrets.token_hex(4)}"


def _alive(pid: int) -> bool:
    """Whether a process of this id exists (a recycled id counts as alive: its folder then
    waits for a later run; nothing is removed on a guess)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:             # EPERM: someone else's process
        return True
    return True


def tidy_leftovers(out) -> list[str]:
    """Remove the staging folders that killed runs into ``out`` left beside it, and recover a
    folder that the fallback swap had renamed aside when it was killed (``out`` missing: the
    aside folder, the previous output, is renamed back). Only folders named like ours, of
    processes of this host that are gone, are touched. Returns what was done, one line each."""
    out = Path(out)
    if not out.parent.is_dir():
        return []
    pattern, host, done = _leftover_pattern(out.name), _host(), []
    for entry in sorted(out.parent.iterdir()):
        m = pattern.match(entry.name)
        if not m or m["kind"] == FILES or m["host"] != host or int(m["pid"]) == os.getpid() or _alive(int(m["pid"])):
            continue
        if m["kind"] == PREVIOUS and not os.path.lexists(out):
            os.rename(entry, out)
            done.append(f"recovered {out} from an interrupted run's {entry.name}")
        else:
            _remove(entry)
            done.append(f"removed {entry.name}, left by a killed run")
    return done


def _remove(path: Path) -> None:
    """A folder with its contents, or a file (a left-over of :func:`replace_file`)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()


def nearest_existing(path) -> Path:
    """``path`` itself or its closest ancestor that exists.

    >>> nearest_existing("/proc/no/such/folder")
    PosixPath('/proc')
    """
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def check_writable(folder) -> None:
    """Raise :class:`OutputFolderError` unless files can be created in ``folder`` (or, where it
    does not exist yet, in its nearest existing ancestor, under which it would be created): a
    probe file is created there and removed. Nothing else is created.

    >>> import tempfile
    >>> a_file = Path(tempfile.mkdtemp()) / "notes.txt"
    >>> a_file.write_text("")
    0
    >>> try:
    ...     check_writable(a_file / "out")
    ... except OSError as exc:
    ...     print(exc.strerror.replace(str(a_file.parent), "TMP"))
    TMP/notes.txt is not a folder
    """
    base = nearest_existing(folder)
    if not base.is_dir():
        raise OutputFolderError(errno.ENOTDIR, f"{base} is not a folder", str(folder))
    probe = base / f".kdg-probe.{_host()}.{os.getpid()}.{secrets.token_hex(4)}"
    try:
        with signals_held():            # never a probe left behind by a Ctrl-C
            os.close(os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
            os.unlink(probe)
    except OSError as exc:
        raise OutputFolderError(exc.errno, f"cannot create files in {base}: {exc.strerror}", str(folder)) from None


def _files_and_empty_folders(root: Path) -> tuple[list[str], list[str]]:
    """Relative paths (with /) of everything in ``root`` that is not a folder (symbolic links
    included, not followed), and of its empty folders.

    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> (root / "c" / "build").mkdir(parents=True); (root / "c" / "x.c").write_text("")
    0
    >>> _files_and_empty_folders(root)
    (['c/x.c'], ['c/build'])
    """
    def fail(exc):          # an unreadable folder: better no run than a user's files lost
        raise exc
    files, empty = [], []
    for folder, subfolders, names in os.walk(root, onerror=fail):
        here = Path(folder)
        links = [d for d in subfolders if (here / d).is_symlink()]
        subfolders[:] = sorted(d for d in subfolders if d not in links)
        for name in sorted(names + links):
            files.append((here / name).relative_to(root).as_posix())
        if not subfolders and not names and not links and here != root:
            empty.append(here.relative_to(root).as_posix())
    return files, empty


def _carry(source: Path, target: Path) -> None:
    """``source`` (a file, link or other non-folder) at ``target``, the original untouched."""
    target.parent.mkdir(parents=True, exist_ok=True)
    if source.is_symlink():
        os.symlink(os.readlink(source), target)
        return
    try:
        os.link(source, target)
    except OSError:
        if not source.is_file():        # a FIFO or socket that cannot be linked: left behind
            raise
        shutil.copy2(source, target)


def carry_user_files(previous: Path, staging: Path, generated: Iterable[str] | None) -> list[str]:
    """Link (or copy) into ``staging`` every file of ``previous`` that is not in ``generated``
    (the previous run's manifest; None: not known, so every file is the user's) and that the new
    run did not write, and every empty folder. Returns the relative paths carried; raises
    OutputFolderError where a file cannot be carried (the caller then replaces nothing)."""
    generated = None if generated is None else set(generated)
    files, empty = _files_and_empty_folders(previous)
    carried = []
    for rel in files:
        if generated is not None and rel in generated:
            continue
        target = staging / rel
        if os.path.lexists(target) or any(p.exists() and not p.is_dir() for p in target.parents
                                           if staging in p.parents):
            if generated is not None:        # the user's file where the new run writes one
                print(f"note: {previous / rel}: the generated file of that name replaces it", file=sys.stderr)
            continue
        try:
            _carry(previous / rel, target)
        except OSError as exc:          # no run rather than a user's file lost with the old folder
            raise OutputFolderError(exc.errno, f"cannot carry this file over into the new output "
                                               f"({exc.strerror}); nothing was replaced", str(previous / rel)) from None
        carried.append(rel)
    for rel in empty:
        target = staging / rel
        if not os.path.lexists(target):
            with contextlib.suppress(OSError):
                target.mkdir(parents=True)
                shutil.copystat(previous / rel, target)
    return carried


@contextlib.contextmanager
def signals_held():
    """SIGINT and SIGTERM recorded instead of acted on inside the block, then delivered to the
    handlers that were there before (a Ctrl-C during a swap ends the run after the swap). Only
    the main thread can change handlers; elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if handler is not None:         # None: installed outside Python, left alone
            previous[signum] = signal.signal(signum, lambda s, frame: caught.append(s))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in dict.fromkeys(caught):
            signal.raise_signal(signum)


def _pause(point: str) -> None:
    """The test hook: stop here (SIGSTOP) when the environment names this point."""
    if os.environ.get(PAUSE_VARIABLE) == point:
        os.kill(os.getpid(), signal.SIGSTOP)


_AT_FDCWD, _RENAME_EXCHANGE = -100, 2


def _renameat2():
    """libc's renameat2 (glibc 2.28 and later) or None."""
    if not sys.platform.startswith("linux") or os.environ.get(NO_EXCHANGE_VARIABLE):
        return None
    try:
        function = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


def exchange(a, b) -> bool:
    """Swap the folders ``a`` and ``b`` atomically (renameat2 with RENAME_EXCHANGE); False where
    the system or the file system cannot (the caller then falls back), OSError on other errors.

    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> (root / "a").mkdir(); (root / "b").mkdir(); (root / "a" / "x").write_text("")
    0
    >>> exchange(root / "a", root / "b"), [p.name for p in (root / "b").iterdir()]
    (True, ['x'])
    """
    function = _renameat2()
    if function is None:
        return False
    if function(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def _swap_in(staging: Path, out: Path) -> Path | None:
    """Put ``staging`` at ``out``; returns where the previous ``out`` now is (to be removed),
    or None when there was none."""
    if not os.path.lexists(out):
        os.rename(staging, out)
        return None
    if exchange(staging, out):
        _pause("swapped")
        return staging
    aside = out.parent / _leftover_name(out.name, PREVIOUS)
    os.rename(out, aside)
    _pause("aside")
    try:
        os.rename(staging, out)
    except BaseException:
        os.rename(aside, out)
        raise
    return aside


def replace_folder(out, write: Callable[[Path], object],
                   previous_files: Callable[[Path], Iterable[str] | None]):
    """Write a new ``out`` with ``write(folder)`` and swap it in whole (see the module's
    docstring); ``previous_files(folder)``: the relative paths of the files in an existing
    ``out`` that the previous run wrote (None: not known). Returns what ``write`` returned.
    ``out`` and missing parents are created; ``out`` that is a file is refused untouched."""
    out = Path(os.path.realpath(out))           # a symbolic link's target is replaced, not the link
    if os.path.lexists(out) and not out.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder", str(out))
    out.parent.mkdir(parents=True, exist_ok=True)
    for line in tidy_leftovers(out):
        print(f"note: {line}", file=sys.stderr)
    staging = out.parent / _leftover_name(out.name, STAGING)
    try:
        staging.mkdir()
        result = write(staging)
        if out.is_dir():
            os.chmod(staging, os.stat(out).st_mode & 0o7777)
            carry_user_files(out, staging, previous_files(out))
        _pause("staged")
        with signals_held():
            previous = _swap_in(staging, out)
            if previous is not None:
                shutil.rmtree(previous, ignore_errors=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return result


def replace_outputs(out, write: Callable[[Path], object], known: Iterable[str]) -> tuple[str, ...]:
    """:func:`replace_folder` for a command whose outputs are a fixed set of names (identify,
    discover, excite): an earlier run's file of one of the ``known`` names that this run does not
    write is dropped, every other file kept. Returns the names written.

    >>> import tempfile
    >>> out = Path(tempfile.mkdtemp()) / "run"
    >>> replace_outputs(out, lambda d: (d / "a.json").write_text("{}"), ("a.json", "b.yaml"))
    ('a.json',)
    """
    known = tuple(known)

    def write_and_list(folder):
        write(folder)
        return tuple(_files_and_empty_folders(folder)[0])
    return replace_folder(out, write_and_list, lambda folder: known)


def _move_in(staging: Path, folder: Path) -> list[str]:
    """Every file of ``staging`` (but the mark) moved to the same place in ``folder``."""
    moved = []
    for rel in _files_and_empty_folders(staging)[0]:
        if rel != MOVING_MARK:
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging / rel, folder / rel)
            moved.append(rel)
    return moved


def finish_moves(folder) -> list[str]:
    """What killed :func:`replace_files` runs left in ``folder`` (their process, on this host,
    gone): a staging folder with the mark (the kill came while its files were being moved in)
    has the rest moved in; one without is removed. Returns what was done, one line each."""
    folder = Path(folder)
    pattern, host, done = _leftover_pattern(folder.name), _host(), []
    for entry in sorted(folder.iterdir()) if folder.is_dir() else ():
        m = pattern.match(entry.name)
        if not m or m["kind"] != FILES or m["host"] != host or _alive(int(m["pid"])):
            continue
        if (entry / MOVING_MARK).exists():
            done.append(f"moved in {', '.join(_move_in(entry, folder)) or 'nothing more'} from {entry.name}, "
                        f"which a killed run was moving in")
        else:
            done.append(f"removed {entry.name}, left by a killed run")
        _remove(entry)
    return done


def replace_files(folder, write: Callable[[Path], object]) -> list[str]:
    """Several files of one run into a folder shared with others (benchmarks/results/), all or
    none: ``write(staging)`` writes them into a staging folder inside ``folder``, then they are
    moved in with SIGINT and SIGTERM held; a failed run moves none. A run killed while moving
    (one rename per file) leaves a mark in its staging folder, and the next ``replace_files``
    into ``folder`` moves the rest in first (a killed run's unmarked staging folder is removed).
    Returns the relative paths written.

    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> replace_files(folder, lambda d: [(d / n).write_text(n) for n in ("run.json", "run.png")])
    ['run.json', 'run.png']
    >>> sorted(p.name for p in folder.iterdir())
    ['run.json', 'run.png']
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for line in finish_moves(folder):
        print(f"note: {line}", file=sys.stderr)
    staging = folder / _leftover_name(folder.name, FILES)
    try:
        staging.mkdir()
        write(staging)
        with signals_held():
            (staging / MOVING_MARK).touch()
            _pause("moving")
            written = _move_in(staging, folder)
            shutil.rmtree(staging)
    except BaseException:
        if not (staging / MOVING_MARK).exists():
            shutil.rmtree(staging, ignore_errors=True)
        raise
    return written


def replace_file(path, text: str | bytes) -> None:
    """Write one file whole: into a temporary file beside it, renamed over it (atomic).

    >>> import tempfile
    >>> path = Path(tempfile.mkdtemp()) / "robot.yaml"
    >>> replace_file(path, "name: x\\n"); path.read_text()
    'name: x\\n'
    """
    path = Path(path)
    for line in tidy_leftovers(path):
        print(f"note: {line}", file=sys.stderr)
    temporary = path.parent / _leftover_name(path.name, STAGING)
    try:
        if isinstance(text, bytes):
            temporary.write_bytes(text)
        else:
            temporary.write_text(text)
        if path.exists():
            os.chmod(temporary, os.stat(path).st_mode & 0o7777)
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            temporary.unlink()
        raise
