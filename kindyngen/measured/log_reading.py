"""Robot motion logs read: CSV and npz files checked and returned as a RawLog; every bad input a LogError naming file, field and reason."""

from __future__ import annotations

import csv
import difflib
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from . import MeasuredDataError

__all__ = [
    "MIN_SAMPLES", "LogError", "RawLog", "read_log", "repeated_rows",
]

#: Fewest samples a log (and a segment after trimming) may have.  Below this a
#: least-squares fit of even one joint's few parameters is not meaningful, and the
#: zero-phase filter's edge transients would cover the whole record.
MIN_SAMPLES = 50

#: CSV column groups: prefix -> required?  (``t`` is the time column.)
_CSV_GROUPS = {"q": True, "qd": False, "qdd": False, "tau": True}

_CSV_COLUMN = re.compile(r"(q|qd|qdd|tau)(\d+)")

#: npz keys -> the channel they hold; ``times``, ``positions``, ``torques`` are required.
_NPZ_KEYS = {"times": "t", "positions": "q", "velocities": "qd", "accelerations": "qdd",
             "torques": "tau"}

#: keys that real npz logs carry but identification does not use: the *commanded*
#: trajectory (the LWR4+ logs of the FloBaRoID project store it beside the measurements).
#: Identification must use what the robot did, not what it was asked to do.
_NPZ_IGNORED = ("target_positions", "target_velocities", "target_accelerations")

#: the measured channels of a log, besides the time stamps
CHANNELS = ("q", "qd", "qdd", "tau")


class LogError(MeasuredDataError):
    """A log that cannot be used, with the file, the field (column, key or row) and the
    reason; the same shape as :class:`kindyngen.model.robot_model.RobotDescriptionError`.

    >>> raise LogError("run1.csv", "q3", "not finite (nan) at data row 17 (file line 18)")
    Traceback (most recent call last):
    ...
    kindyngen.measured.log_reading.LogError: run1.csv: field 'q3': not finite (nan) at data row 17 (file line 18)
    """

    def __init__(self, source: str, field: str, reason: str):
        self.source, self.field, self.reason = source, field, reason
        super().__init__(f"{source}: field '{field}': {reason}")


def number_text(x) -> str:
    """A plain number for messages: ``1.5``, never ``np.float64(1.5)``; time stamps keep
    all their digits (Unix times have ten before the point)."""
    return repr(float(x))


def rounded_text(x) -> str:
    """A number for messages to six significant digits: ``rounded_text(0.0012345678)`` is ``0.00123457``."""
    return f"{float(x):g}"


def _readonly(a) -> np.ndarray:
    # frozen dataclasses hold arrays: a private read-only copy keeps the promise (neither
    # the caller's later edits nor the user's writes can change a log after the fact)
    a = np.array(a, dtype=float, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)   # eq=False: arrays have no single truth value
class RawLog:
    """A log as read: time stamps ``t`` (N,), positions ``q`` and torques ``tau`` (N, n),
    velocities ``qd`` and accelerations ``qdd`` (N, n) when the log has them, else None.
    ``notes`` says what the reader left out (e.g. commanded trajectories in an npz).

    Construction checks shapes, finiteness and time order (the same checks
    :func:`read_log` reports with the file's own column names), so a RawLog built by hand
    is as trustworthy as one read from a file.

    >>> import numpy as np
    >>> t = np.arange(60) * 0.01
    >>> raw = RawLog("demo", t, q=np.zeros((60, 2)), tau=np.ones((60, 2)))
    >>> raw.n, raw.qd is None
    (2, True)
    """

    source: str
    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    qd: np.ndarray | None = None
    qdd: np.ndarray | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self):
        arrays = {"t": self.t, "q": self.q, "tau": self.tau, "qd": self.qd, "qdd": self.qdd}
        for name, value in arrays.items():
            if value is None and name in ("t", "q", "tau"):
                raise LogError(self.source, name, "required (only qd and qdd may be None)")
            if value is not None:
                object.__setattr__(self, name, as_float_array(self.source, name, value))
        object.__setattr__(self, "notes", tuple(self.notes))
        _check_shapes(self.source, self.t, self._channels(), _canonical_names)
        _check_values(self.source, self.t, self._channels(), _canonical_names)

    def _channels(self) -> dict[str, np.ndarray | None]:
        return {"q": self.q, "qd": self.qd, "qdd": self.qdd, "tau": self.tau}

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.q.shape[1]

    def __repr__(self) -> str:
        given = [c for c in ("qd", "qdd") if getattr(self, c) is not None]
        return (f"RawLog({self.source!r}, {len(self.t)} samples, {self.n} joints, "
                f"{rounded_text(self.t[-1] - self.t[0])} s from t = {number_text(self.t[0])} s, given: q, tau"
                f"{''.join(', ' + c for c in given)})")


@dataclass(frozen=True)
class _Names:
    """How a log format names things in messages: the time field, a whole channel (for shape
    errors), one joint of a channel (field, extra words), and what a row is called."""

    time: str
    channel: Callable[[str], str]
    column: Callable[[str, int], tuple[str, str]]
    row: str

_NPZ_KEY_OF = {v: k for k, v in _NPZ_KEYS.items()}

_canonical_names = _Names("t", lambda ch: ch, lambda ch, j: (f"{ch}{j + 1}", ""), "row")

# CSV: the columns carry the canonical names; rows are counted as data rows from 1
_csv_names = _Names("t", lambda ch: f"{ch}1", lambda ch, j: (f"{ch}{j + 1}", ""), "data row")

_npz_names = _Names("times", lambda ch: _NPZ_KEY_OF[ch],
                    lambda ch, j: (_NPZ_KEY_OF[ch], f" (joint {j + 1})"), "sample")


def as_float_array(source: str, name: str, value) -> np.ndarray:
    """``value`` as a read-only float array, or a :class:`LogError` naming ``name`` if it holds no real numbers."""
    try:
        a = np.asarray(value)
    except Exception as exc:   # e.g. ragged nested lists
        raise LogError(source, name, f"not an array of numbers: {exc}") from exc
    if a.dtype.kind not in "fiu":   # bool, complex, strings, objects: not measurements
        raise LogError(source, name, f"expected real numbers, got dtype {a.dtype}")
    return _readonly(a)


def _check_shapes(source: str, t: np.ndarray, channels: dict, names: _Names) -> None:
    if t.ndim != 1:
        raise LogError(source, names.time, f"expected a 1-D array of time stamps, got shape {t.shape}")
    if len(t) < MIN_SAMPLES:
        raise LogError(source, names.time, f"only {len(t)} samples; at least MIN_SAMPLES = "
                                           f"{MIN_SAMPLES} are needed")
    n = channels["q"].shape[1] if channels["q"].ndim == 2 else None
    for ch, a in channels.items():
        if a is None:
            continue
        field_name = names.channel(ch)
        if a.ndim != 2 or a.shape[0] != len(t):
            raise LogError(source, field_name, f"expected shape (N, n) with N = {len(t)} "
                                               f"time stamps, got {a.shape}")
        if a.shape[1] != n:
            raise LogError(source, field_name, f"has {a.shape[1]} joints but q has {n}")
    if n is None or n < 1:
        raise LogError(source, "q", "no joint columns")


def _check_values(source: str, t: np.ndarray, channels: dict, names: _Names) -> None:
    """Non-finite values and time order, each named by field and 1-based row."""
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        raise LogError(source, names.time, f"not finite ({number_text(t[i])}) at {names.row} {i + 1} "
                                           f"(first bad {names.row})")
    for ch, a in channels.items():
        if a is None:
            continue
        bad = ~np.isfinite(a)
        if bad.any():
            # the first bad row over all columns; among its bad columns, the first
            i = int(np.argmax(bad.any(axis=1)))
            j = int(np.argmax(bad[i]))
            field_name, extra = names.column(ch, j)
            raise LogError(source, field_name, f"not finite ({number_text(a[i, j])}) at {names.row} "
                                               f"{i + 1}{extra} (first bad {names.row})")
    step = np.diff(t)
    back = np.flatnonzero(step < 0)
    if back.size:
        i = int(back[0]) + 1
        raise LogError(source, names.time, f"time goes backwards at {names.row} {i + 1}: "
                                           f"{number_text(t[i])} s after {number_text(t[i - 1])} s")
    same_time = np.flatnonzero(step == 0)
    if same_time.size:
        # an equal time stamp is allowed only for an exact repeat of the previous row (a
        # logger re-sending its sample); preprocess drops those rows
        given = [a for a in channels.values() if a is not None]
        stacked = np.concatenate(given, axis=1)
        for k in same_time:
            differ = np.flatnonzero(stacked[k + 1] != stacked[k])
            if differ.size:
                i = int(k) + 1
                raise LogError(source, names.time,
                               f"{names.row}s {i} and {i + 1} have the same time stamp "
                               f"{number_text(t[i])} s but different values; only an exact repeat "
                               f"of the previous {names.row} may share its time stamp")


def read_log(path, n: int) -> RawLog:
    """Read a motion log of an ``n``-joint robot from a ``.csv`` or ``.npz`` file.

    CSV: a header row, then one row per sample.  Columns ``t`` (s), ``q1..qn`` (rad),
    ``tau1..taun`` (N m); optional groups ``qd1..qdn`` (rad/s) and ``qdd1..qddn``
    (rad/s^2), each complete or absent.  Column order is free.

    npz: arrays ``times`` (N,), ``positions`` and ``torques`` (N, n); optional
    ``velocities`` and ``accelerations`` (N, n).  Commanded trajectories
    (``target_positions`` ...) are skipped with a note; other keys are refused.

    Refused with a :class:`LogError` (file, column or key, reason): unknown or missing
    columns, a wrong joint count, non-finite values (column and first bad row), fewer than
    :data:`MIN_SAMPLES` rows, time going backwards, equal time stamps with different values,
    unreadable files, other extensions.

    >>> from pathlib import Path
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> rows = ["t,q1,tau1"] + [f"{0.01 * k},{0.1 * k},1.0" for k in range(60)]
    >>> _ = (folder / "run.csv").write_text("\\n".join(rows))
    >>> read_log(folder / "run.csv", 1).q.shape
    (60, 1)
    >>> _ = (folder / "bad.csv").write_text("t,q1,torque1\\n0,0,0\\n")
    >>> read_log(folder / "bad.csv", 1)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kindyngen.measured.log_reading.LogError: ...bad.csv: field 'torque1': unknown column; did you mean 'tau1'? ...
    """
    path = Path(path)
    source = str(path)
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1:
        raise ValueError(f"n must be a positive number of joints, got {n!r}")
    n = int(n)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _read_csv(path, n, source)
    if suffix == ".npz":
        return _read_npz(path, n, source)
    raise LogError(source, "<file>", f"unknown extension {path.suffix!r}; expected .csv or .npz")


def _expected_columns(n: int) -> str:
    return f"t, q1..q{n}, tau1..tau{n}; optional qd1..qd{n}, qdd1..qdd{n}"


def _read_csv(path: Path, n: int, source: str) -> RawLog:
    try:
        # utf-8-sig: a spreadsheet's byte-order mark must not become part of the name 't'
        with open(path, newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle)
            header = next(reader, None)
            rows, lines = [], []
            for row in reader:
                if row and any(cell.strip() for cell in row):   # blank lines carry nothing
                    rows.append(row)
                    lines.append(reader.line_num)
    except OSError as exc:
        raise LogError(source, "<file>", f"cannot read: {exc.strerror or exc}") from exc
    except (UnicodeDecodeError, csv.Error) as exc:
        raise LogError(source, "<file>", f"cannot read as CSV text: {exc}") from exc
    if not header or not any(cell.strip() for cell in header):
        raise LogError(source, "<file>", f"empty file; expected a header row ({_expected_columns(n)})")
    names = [cell.strip() for cell in header]
    if any("\0" in name for name in names):   # a binary file: echoing its bytes as a name helps nobody
        raise LogError(source, "<file>", "contains NUL bytes: a binary file, not CSV text")
    if all(_is_number(name) for name in names):
        raise LogError(source, "<file>", f"the first row holds numbers, not column names; a "
                                         f"header row is required ({_expected_columns(n)})")
    columns = csv_layout(names, n, source)

    data = _csv_numbers(rows, lines, names, source)
    t = data[:, columns["t"]]
    channels = {ch: (data[:, columns[ch]] if ch in columns else None) for ch in CHANNELS}
    _check_shapes(source, t, channels, _csv_names)
    # rows named as the user counts them: data rows from 1, plus the file line
    line_of = np.asarray(lines)
    try:
        _check_values(source, t, channels, _csv_names)
    except LogError as exc:
        raise LogError(source, exc.field, _with_line(exc.reason, line_of)) from None
    return RawLog(source, t, channels["q"], channels["tau"], channels["qd"], channels["qdd"])


def _with_line(reason: str, line_of: np.ndarray) -> str:
    """Add the file line to the first 'data row K' of a message (the header is line 1)."""
    match = re.search(r"data rows? (\d+)", reason)
    if not match:
        return reason
    k = int(match.group(1))
    return reason.replace(match.group(0), f"{match.group(0)} (file line {line_of[k - 1]})", 1)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def csv_layout(names: list[str], n: int, source: str) -> dict[str, object]:
    """Column index of ``t`` and index arrays of each channel, from the header."""
    known = ["t"] + [f"{ch}{j}" for ch in _CSV_GROUPS for j in range(1, n + 1)]
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if not name:   # e.g. a trailing comma in the header
            raise LogError(source, f"<column {i + 1}>", "empty column name in the header row")
        if name in seen:
            raise LogError(source, name, f"column appears twice (columns {seen[name] + 1} and {i + 1})")
        seen[name] = i
    # unknown names first: a misspelt column explains everything that follows from it
    for name in names:
        if name != "t" and not _CSV_COLUMN.fullmatch(name):
            close = difflib.get_close_matches(name, known, n=1, cutoff=0.0)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise LogError(source, name, f"unknown column; {hint}(expected {_expected_columns(n)})")
    if "t" not in seen:
        raise LogError(source, "t", f"missing column (expected {_expected_columns(n)})")
    joints: dict[str, list[int]] = {ch: [] for ch in _CSV_GROUPS}
    for name in names:
        match = _CSV_COLUMN.fullmatch(name)
        if match:
            joints[match.group(1)].append(int(match.group(2)))
    # the joint count: more joints than the robot, or fewer in every group present
    for ch, idx in joints.items():
        wrong = [j for j in idx if j < 1 or j > n]
        if wrong:
            j = max(wrong) if max(wrong) > n else min(wrong)
            count = max(idx)
            reason = (f"the file has {_joints(count)} ({_span(ch, count)}) but the robot has {n}"
                      if j > n else f"joints are numbered from 1 (expected {ch}1..{ch}{n})")
            raise LogError(source, f"{ch}{j}", reason)
    present = {ch: sorted(idx) for ch, idx in joints.items() if idx}
    counts = {ch: max(idx) for ch, idx in present.items()}
    for ch, required in _CSV_GROUPS.items():
        idx = present.get(ch)
        if not idx:
            if required:
                raise LogError(source, f"{ch}1", f"missing column (expected {_expected_columns(n)})")
            continue
        missing = [j for j in range(1, n + 1) if j not in idx]
        if not missing:
            continue
        first = f"{ch}{missing[0]}"
        if missing == list(range(counts[ch] + 1, n + 1)) and len(set(counts.values())) == 1:
            # every group stops at the same joint: a log of a different robot
            listed = ", ".join(_span(c, counts[c]) for c in present)
            raise LogError(source, first, f"the file has {_joints(counts[ch])} ({listed}) "
                                          f"but the robot has {n}")
        if not required:
            listed = ", ".join(f"{ch}{j}" for j in missing)
            raise LogError(source, first, f"optional group {ch} is incomplete: {listed} missing "
                                          f"(give all of {ch}1..{ch}{n} or none)")
        raise LogError(source, first, f"missing column (expected {_expected_columns(n)})")
    layout: dict[str, object] = {"t": seen["t"]}
    for ch in present:
        layout[ch] = np.array([seen[f"{ch}{j}"] for j in range(1, n + 1)])
    return layout


def _span(ch: str, count: int) -> str:
    return f"{ch}1" if count == 1 else f"{ch}1..{ch}{count}"


def _joints(count: int) -> str:
    return "1 joint" if count == 1 else f"{count} joints"


def _csv_numbers(rows: list[list[str]], lines: list[int], names: list[str], source: str) -> np.ndarray:
    """All cells as floats; the first bad cell is reported by column and row."""
    width = len(names)
    for k, row in enumerate(rows):
        if len(row) != width:
            raise LogError(source, "<file>", f"data row {k + 1} (file line {lines[k]}) has "
                                             f"{len(row)} values, the header has {width}")
    if not rows:
        return np.empty((0, width))
    try:
        return np.array(rows, dtype=float)   # fast path: numpy parses the strings
    except ValueError:
        pass
    for k, row in enumerate(rows):            # slow path only to name the bad cell
        for i, cell in enumerate(row):
            try:
                float(cell)
            except ValueError:
                shown = repr(cell.strip()) if cell.strip() else "an empty cell"
                raise LogError(source, names[i], f"cannot read {shown} as a number at data row "
                                                 f"{k + 1} (file line {lines[k]})") from None
    raise LogError(source, "<file>", "cannot read the values as numbers")   # not reached


def _read_npz(path: Path, n: int, source: str) -> RawLog:
    if path.is_file() and not zipfile.is_zipfile(path):
        # np.load would try it as a pickle and call it "pickled data"
        raise LogError(source, "<file>", "cannot read as an .npz archive: no zip signature (np.savez writes zip "
                                         "archives of .npy arrays)")
    try:
        with np.load(path, allow_pickle=False) as archive:
            keys = list(archive.files)
            arrays = {}
            for key in keys:
                if key in _NPZ_IGNORED:
                    continue
                try:
                    arrays[key] = archive[key]
                except ValueError as exc:   # object arrays need pickle, which stays off
                    raise LogError(source, key, f"cannot read the array ({exc})") from None
    except LogError:
        raise
    except OSError as exc:
        raise LogError(source, "<file>", f"cannot read: {exc.strerror or exc}") from exc
    except (ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        # np.load on a non-zip file tries pickle, refused: the file is no npz archive
        raise LogError(source, "<file>", f"cannot read as an .npz archive of arrays ({exc})") from exc
    known = list(_NPZ_KEYS) + list(_NPZ_IGNORED)
    for key in keys:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1, cutoff=0.0)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise LogError(source, key, f"unknown key; {hint}(expected times, positions, torques; "
                                        f"optional velocities, accelerations)")
    for key in ("times", "positions", "torques"):
        if key not in arrays:
            raise LogError(source, key, "missing key")
    values = {key: as_float_array(source, key, arrays[key]) for key in arrays}
    t = values["times"]
    if t.ndim != 1:
        raise LogError(source, "times", f"expected shape (N,), got {t.shape}")
    for key in values:
        if key == "times":
            continue
        a = values[key]
        if a.ndim != 2 or a.shape[0] != len(t):
            raise LogError(source, key, f"expected shape (N, {n}) with N = {len(t)} time stamps, "
                                        f"got {a.shape}")
        if a.shape[1] != n:
            raise LogError(source, key, f"the file has {_joints(a.shape[1])} (shape {a.shape}) "
                                        f"but the robot has {n}")
    channels = {ch: values.get(key) for key, ch in _NPZ_KEYS.items() if ch != "t"}
    _check_shapes(source, t, channels, _npz_names)
    _check_values(source, t, channels, _npz_names)
    skipped = [key for key in keys if key in _NPZ_IGNORED]
    notes = (f"ignored {', '.join(skipped)} (commanded, not measured)",) if skipped else ()
    return RawLog(source, t, channels["q"], channels["tau"], channels["qd"], channels["qdd"], notes)


def repeated_rows(raw: RawLog) -> np.ndarray:
    """Boolean mask (N,) of the rows whose every measured channel (q and tau, and qd and
    qdd when given) equals the previous row's exactly: a logger that re-sent its last sample
    under a new time stamp.  The first row is never repeated.

    Exact equality is the right test: a real new measurement of seven joints' positions,
    velocities and torques never reproduces all of its digits, while a re-sent one always
    does.  (A robot at rest still moves its torques and velocities in the last digits.)

    >>> import numpy as np
    >>> q = np.arange(60.0)[:, None]; q[5] = q[4]
    >>> tau = np.zeros((60, 1))
    >>> np.flatnonzero(repeated_rows(RawLog("demo", np.arange(60.0), q, tau)))
    array([5])
    """
    given = [a for a in (raw.q, raw.tau, raw.qd, raw.qdd) if a is not None]
    stacked = np.concatenate(given, axis=1)
    mask = np.zeros(len(raw.t), dtype=bool)
    mask[1:] = np.all(stacked[1:] == stacked[:-1], axis=1)
    return mask
