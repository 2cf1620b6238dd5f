"""Results written so that a reused output folder never mixes two runs and a failed run leaves
the earlier results whole: everything is written into a temporary folder beside ``--out``;
only when writing succeeded are the new files moved in (``os.replace``, atomic per file on one
file system) and the files an earlier run of the same command wrote but this one did not (a
``model.yaml`` not written this time) removed.  Other files in the folder are left alone.

Example:

>>> import tempfile, pathlib
>>> out = pathlib.Path(tempfile.mkdtemp()) / "run"
>>> replace_outputs(out, lambda d: (d / "a.json").write_text("{}"), ("a.json", "b.yaml"))
('a.json',)
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterable


def replace_outputs(out, write: Callable[[Path], object], known: Iterable[str]) -> tuple[str, ...]:
    """Run ``write(folder)`` on a fresh temporary folder, then move what it wrote into ``out``
    (created if missing) and delete the ``known`` output names it did not write.  Returns the
    names written.  If ``write`` raises, ``out`` is untouched and the temporary folder removed."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(20, "exists and is not a folder", str(out))
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        write(staging)
        written = tuple(sorted(p.name for p in staging.iterdir()))
        out.mkdir(exist_ok=True)
        for name in known:
            if name not in written and (out / name).is_file():
                (out / name).unlink()
        for name in written:
            os.replace(staging / name, out / name)
        return written
    finally:
        shutil.rmtree(staging, ignore_errors=True)
