"""Logs as robots record them, read in chunks: CSV and npz (the layouts of
:mod:`kindyngen.measured.log_preparing`), Parquet with the CSV's column names, and ROS bags of
``sensor_msgs/msg/JointState`` (rosbag2 directories with MCAP or SQLite storage, ROS 1 ``.bag``
files) read with the pure-Python ``rosbags`` package, so no ROS installation is needed.

``iter_chunks(path, n, joint_names)`` yields :class:`RawChunk` objects of at most
``chunk_rows`` samples each, in time order, so a log of any length is read in bounded memory;
``read_any`` returns the whole log as a :class:`kindyngen.measured.log_reading.RawLog`.  Every bad
input is a :class:`kindyngen.measured.log_reading.LogError` naming the file, the field and the reason
(for a bag: a joint name the description lacks, or a description joint the messages lack).

A JointState's ``position`` (rad or m), ``velocity`` and ``effort`` (N m) are matched to the
description's joints by name, in any order; the time is the header stamp (the bag's receive
time when the stamp is zero).  Velocities are used when every message has them for every joint.

Example:

>>> import numpy as np, tempfile, pathlib
>>> from kindyngen.measured.log_preparing import RawLog
>>> t = np.arange(100) * 0.01
>>> raw = RawLog("demo", t, np.sin(t)[:, None], np.cos(t)[:, None])
>>> path = pathlib.Path(tempfile.mkdtemp()) / "demo.parquet"
>>> write_parquet(path, raw)
>>> [len(c.t) for c in iter_chunks(path, 1, chunk_rows=64)]
[64, 36]
"""
from __future__ import annotations

import difflib
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from .log_checks import LogBounds, check_raw_log, check_samples
from .log_reading import CHANNELS, LogError, RawLog, read_log
from .log_reading import csv_layout   # the CSV's column rules, shared by Parquet (one spelling of them)

#: Samples per chunk: the regressor of one chunk of the Panda (7 x 43 columns) is 48 MB.
CHUNK_ROWS = 20000
#: CSV files up to this size are read whole by :func:`kindyngen.measured.log_reading.read_log` (its
#: messages name the file line of a bad cell); larger ones stream through pyarrow's reader.
SMALL_CSV_BYTES = 64 << 20


@dataclass(frozen=True, eq=False)
class RawChunk:
    """Consecutive samples of a log: ``t`` (m,), ``q``, ``tau`` (m, n), ``qd``/``qdd`` or None;
    ``first_row``: the 0-based row of the first sample in the whole log; ``notes``: what the
    reader left out (on the first chunk)."""

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    qd: np.ndarray | None
    qdd: np.ndarray | None
    first_row: int
    notes: tuple[str, ...] = ()


def log_kind(path) -> str:
    """'csv', 'npz', 'parquet', 'rosbag2' (a directory with metadata.yaml, or a .mcap/.db3
    file inside one) or 'rosbag1' (a .bag file); a LogError otherwise."""
    path = Path(path)
    suffix = path.suffix.lower()
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return "rosbag2"
        raise LogError(str(path), "<file>", "a folder without metadata.yaml: not a rosbag2 recording")
    if suffix in (".mcap", ".db3") and (path.parent / "metadata.yaml").exists():
        return "rosbag2"
    if suffix in (".mcap", ".db3"):
        raise LogError(str(path), "<file>", f"a {suffix} file without the metadata.yaml of its rosbag2 folder "
                                            f"beside it; give the recording's folder")
    kinds = {".csv": "csv", ".npz": "npz", ".parquet": "parquet", ".pq": "parquet", ".bag": "rosbag1"}
    if suffix not in kinds:
        raise LogError(str(path), "<file>", f"unknown extension {path.suffix!r}; expected .csv, .npz, .parquet, "
                                            f"a rosbag2 folder (MCAP or SQLite) or a ROS 1 .bag")
    if not path.exists():
        raise LogError(str(path), "<file>", "cannot read: No such file or directory")
    return kinds[suffix]


def iter_chunks(path, n: int, joint_names: Sequence[str] | None = None,
                chunk_rows: int = CHUNK_ROWS, bounds: LogBounds | None = None) -> Iterator[RawChunk]:
    """The samples of the log at ``path`` (any format of the module text) in chunks of at most
    ``chunk_rows``, checked as they come: finite values, time never going backwards (rows
    named from 1 over the whole log), and with the robot's ``bounds`` its limits and physical
    bounds (:func:`kindyngen.measured.log_checks.check_samples`).  ``joint_names``: the
    description's joints, in order (needed for bags)."""
    kind = log_kind(path)
    readers = {"csv": _csv_chunks, "npz": _npz_chunks, "parquet": _parquet_chunks,
               "rosbag2": _bag_chunks, "rosbag1": _bag_chunks}
    source = str(path)
    last_t, rows = None, 0
    for chunk in readers[kind](Path(path), n, chunk_rows, joint_names):
        _check_chunk(source, chunk, last_t, kind)
        if bounds is not None:
            check_samples(source, bounds, chunk.t, chunk.q, chunk.tau, chunk.qd, chunk.qdd, chunk.first_row,
                          _row_word(kind))
        last_t = float(chunk.t[-1])
        rows += len(chunk.t)
        yield chunk
    if rows == 0:
        raise LogError(source, "t", "no samples")


def read_any(path, n: int, joint_names: Sequence[str] | None = None, bounds: LogBounds | None = None) -> RawLog:
    """The whole log at ``path`` as a RawLog (CSV and npz by :func:`kindyngen.measured.log_reading.read_log`),
    checked against the robot's ``bounds`` when given (:func:`kindyngen.measured.log_checks.check_samples`)."""
    kind = log_kind(path)
    if kind in ("csv", "npz") and (kind == "npz" or Path(path).stat().st_size <= SMALL_CSV_BYTES):
        raw = read_log(path, n)
        if bounds is not None:
            check_raw_log(raw, bounds, _row_word(kind))
        return raw
    chunks = list(iter_chunks(path, n, joint_names, chunk_rows=1 << 62, bounds=bounds))
    parts = {ch: [getattr(c, ch) for c in chunks] for ch in ("t",) + CHANNELS}
    whole = {ch: (None if any(p is None for p in v) else np.concatenate(v)) for ch, v in parts.items()}
    return RawLog(str(path), whole["t"], whole["q"], whole["tau"], whole["qd"], whole["qdd"])


def time_span_of_file(path) -> tuple[float, float] | None:
    """(first, last) time stamp of a Parquet file (its first and last row groups' ``t``) or a
    CSV file (its ``t`` column streamed alone), or None if the file has no readable ``t``
    (the full reader then names what is wrong)."""
    import pyarrow as pa
    try:
        if log_kind(path) == "parquet":
            import pyarrow.parquet as pq
            handle = pq.ParquetFile(path)
            groups = handle.metadata.num_row_groups
            if groups == 0:
                return None
            first = handle.read_row_group(0, columns=["t"]).column("t").to_numpy()
            last = handle.read_row_group(groups - 1, columns=["t"]).column("t").to_numpy()
            return (float(first[0]), float(last[-1])) if len(first) and len(last) else None
        import pyarrow.csv as pacsv
        reader = pacsv.open_csv(path, read_options=pacsv.ReadOptions(block_size=8 << 20),
                                convert_options=pacsv.ConvertOptions(include_columns=["t"],
                                                                     column_types={"t": pa.float64()}))
        first = last = None
        for batch in reader:
            if batch.num_rows:
                t = batch.column(0).to_numpy()
                first = float(t[0]) if first is None else first
                last = float(t[-1])
        return None if first is None else (first, last)
    except (pa.ArrowInvalid, pa.ArrowTypeError, KeyError, OSError):
        return None


def _row_word(kind: str) -> str:
    """What a row of a log of this kind is called in messages."""
    return "sample" if kind.startswith("rosbag") else "data row"


def _check_chunk(source: str, chunk: RawChunk, last_t, kind: str) -> None:
    row = _row_word(kind)
    for name, a in (("t", chunk.t),) + tuple((ch, getattr(chunk, ch)) for ch in CHANNELS):
        if a is None:
            continue
        bad = ~np.isfinite(a)
        if bad.any():
            i = int(np.argmax(bad if a.ndim == 1 else bad.any(axis=1)))
            field = name if a.ndim == 1 else f"{name}{int(np.argmax(bad[i])) + 1}"
            raise LogError(source, field, f"not finite at {row} {chunk.first_row + i + 1} (first bad {row})")
    t = chunk.t if last_t is None else np.concatenate([[last_t], chunk.t])
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + (0 if last_t is None else -1) + 1
        raise LogError(source, "t", f"time goes backwards at {row} {chunk.first_row + i + 1}")


def _slices(raw: RawLog, chunk_rows: int) -> Iterator[RawChunk]:
    for a in range(0, len(raw.t), chunk_rows):
        s = slice(a, a + chunk_rows)
        yield RawChunk(raw.t[s], raw.q[s], raw.tau[s], None if raw.qd is None else raw.qd[s],
                       None if raw.qdd is None else raw.qdd[s], a, raw.notes if a == 0 else ())


def _columns_chunk(columns: dict, layout: dict, first_row: int) -> RawChunk:
    def group(ch):
        return None if ch not in layout else np.column_stack([columns[i] for i in layout[ch]])
    return RawChunk(np.asarray(columns[layout["t"]], float), group("q"), group("tau"), group("qd"), group("qdd"),
                    first_row)


def _header_names(path: Path, source: str) -> list[str]:
    with open(path, "rb") as handle:
        first = handle.readline(1 << 16)
    if b"\0" in first:
        raise LogError(source, "<file>", "contains NUL bytes: a binary file, not CSV text")
    try:
        text = first.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise LogError(source, "<file>", f"cannot read as CSV text: {exc}") from None
    return [cell.strip() for cell in text.strip().split(",")]


def _csv_chunks(path: Path, n: int, chunk_rows: int, joint_names) -> Iterator[RawChunk]:
    source = str(path)
    if path.stat().st_size <= SMALL_CSV_BYTES:
        yield from _slices(read_log(path, n), chunk_rows)
        return
    import pyarrow as pa
    import pyarrow.csv as pacsv
    names = _header_names(path, source)
    layout = csv_layout(names, n, source)
    convert = pacsv.ConvertOptions(column_types={name: pa.float64() for name in names})
    try:
        reader = pacsv.open_csv(path, read_options=pacsv.ReadOptions(block_size=8 << 20), convert_options=convert)
        rows = 0
        for batch in reader:
            columns = {i: batch.column(i).to_numpy(zero_copy_only=False) for i in range(batch.num_columns)}
            for a in range(0, batch.num_rows, chunk_rows):
                part = {i: v[a:a + chunk_rows] for i, v in columns.items()}
                yield _columns_chunk(part, layout, rows + a)
            rows += batch.num_rows
    except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
        raise LogError(source, "<file>", f"cannot read as CSV numbers: {str(exc).splitlines()[0]}") from None


def _npz_chunks(path: Path, n: int, chunk_rows: int, joint_names) -> Iterator[RawChunk]:
    """npz members streamed row block by row block (no member is loaded whole); archives that
    cannot be streamed (Fortran-ordered or object arrays, keys other than the five of a log,
    which read_log refuses or notes) are read by read_log."""
    raw_keys = {"times": "t", "positions": "q", "velocities": "qd", "accelerations": "qdd", "torques": "tau"}
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError):
        yield from _slices(read_log(path, n), chunk_rows)     # read_log names what is wrong
        return
    with archive:
        members = {name[:-4]: name for name in archive.namelist() if name.endswith(".npy")}
        if set(members) - set(raw_keys) or len(members) != len(archive.namelist()):
            yield from _slices(read_log(path, n), chunk_rows)
            return
        streams = {}
        try:
            for key, member in members.items():
                if key not in raw_keys:
                    continue
                handle = archive.open(member)
                version = np.lib.format.read_magic(handle)
                header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                          else np.lib.format.read_array_header_2_0)
                shape, fortran, dtype = header(handle)
                if fortran or dtype.hasobject or dtype.kind not in "fiu" or len(shape) not in (1, 2):
                    raise ValueError("not streamable")
                streams[raw_keys[key]] = (handle, dtype, shape)
        except ValueError:
            yield from _slices(read_log(path, n), chunk_rows)
            return
        if "t" not in streams or "q" not in streams or "tau" not in streams or \
                any(len(s[2]) != (1 if ch == "t" else 2) or (ch != "t" and s[2][1] != n) for ch, s in streams.items()):
            yield from _slices(read_log(path, n), chunk_rows)    # read_log names what is wrong
            return
        total = streams["t"][2][0]
        if any(s[2][0] != total for s in streams.values()):
            yield from _slices(read_log(path, n), chunk_rows)
            return
        for a in range(0, total, chunk_rows):
            m = min(chunk_rows, total - a)
            got = {}
            for ch, (handle, dtype, shape) in streams.items():
                width = 1 if len(shape) == 1 else shape[1]
                data = handle.read(m * width * dtype.itemsize)
                got[ch] = np.frombuffer(data, dtype).astype(float).reshape((m,) if width == 1 and len(shape) == 1
                                                                          else (m, width))
            yield RawChunk(got["t"], got["q"], got["tau"], got.get("qd"), got.get("qdd"), a)


def _parquet_chunks(path: Path, n: int, chunk_rows: int, joint_names) -> Iterator[RawChunk]:
    import pyarrow as pa
    import pyarrow.parquet as pq
    source = str(path)
    try:
        handle = pq.ParquetFile(path)
    except (pa.ArrowInvalid, OSError) as exc:
        raise LogError(source, "<file>", f"cannot read as Parquet: {str(exc).splitlines()[0]}") from None
    names = list(handle.schema_arrow.names)
    layout = csv_layout(names, n, source)
    for name, kind in zip(names, handle.schema_arrow.types):
        if not (pa.types.is_floating(kind) or pa.types.is_integer(kind)):
            raise LogError(source, name, f"expected real numbers, got the Parquet type {kind}")
    rows = 0
    # one row group at a time: ParquetFile.iter_batches keeps every row group it has read (its
    # resident memory grew by one row group per group, 5 GB into a 10-hour log); read_row_group
    # does not.  Memory is then one row group (write them at most ~1M rows; pyarrow's default
    # is 1M) plus one chunk.
    for group in range(handle.metadata.num_row_groups):
        table = handle.read_row_group(group)
        columns = {i: table.column(i).to_numpy().astype(float) for i in range(table.num_columns)}
        del table
        for a in range(0, len(columns[0]) if columns else 0, chunk_rows):
            yield _columns_chunk({i: v[a:a + chunk_rows] for i, v in columns.items()}, layout, rows + a)
        rows += len(columns[0]) if columns else 0


def write_parquet(path, raw: RawLog) -> None:
    """``raw`` as a Parquet file with the CSV's column names (t, q1.., qd1.., qdd1.., tau1..)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    columns = {"t": raw.t}
    for ch in CHANNELS:
        a = getattr(raw, ch)
        if a is not None:
            columns.update({f"{ch}{j + 1}": a[:, j] for j in range(raw.n)})
    pq.write_table(pa.table(columns), path)


# --------------------------------------------------------------------------- ROS bags

JOINT_STATE = "sensor_msgs/msg/JointState"


def joint_names_of(model) -> list[str]:
    """The description's joint names, ``joint1 .. jointn`` for joints without one (DH tables)."""
    return [j.name or f"joint{i + 1}" for i, j in enumerate(model.joints)]


def _bag_path(path: Path) -> Path:
    return path.parent if path.suffix.lower() in (".mcap", ".db3") else path


def _bag_chunks(path: Path, n: int, chunk_rows: int, joint_names) -> Iterator[RawChunk]:
    from rosbags.highlevel import AnyReader
    source = str(path)
    if joint_names is None:
        raise LogError(source, "<file>", "reading a bag needs the description's joint names")
    joint_names = list(joint_names)
    try:
        reader = AnyReader([_bag_path(path)])
        reader.open()
    except Exception as exc:   # rosbags raises its own error types for unreadable recordings
        raise LogError(source, "<file>", f"cannot read as a ROS bag: {exc}") from None
    try:
        topics = sorted({c.topic for c in reader.connections if c.msgtype == JOINT_STATE})
        if not topics:
            listed = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})) or "none"
            raise LogError(source, "<topic>", f"no {JOINT_STATE} topic (topics: {listed})")
        if len(topics) > 1:
            chosen = [t for t in topics if t.endswith("joint_states")]
            if len(chosen) != 1:
                raise LogError(source, "<topic>", f"several {JOINT_STATE} topics ({', '.join(topics)}); keep one")
            topics = chosen
        connections = [c for c in reader.connections if c.topic == topics[0]]
        buffer: dict[str, list] = {"t": [], "q": [], "qd": [], "tau": []}
        order = None
        first_row = 0
        has_velocity = True
        for k, (connection, stamp, data) in enumerate(reader.messages(connections=connections)):
            msg = reader.deserialize(data, connection.msgtype)
            names = list(msg.name)
            if order is None or names != order[0]:
                order = (names, _joint_order(source, names, joint_names, k + 1))
            index = order[1]
            t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            position, effort = np.asarray(msg.position, float), np.asarray(msg.effort, float)
            if len(position) != len(names) or len(effort) != len(names):
                field = "position" if len(position) != len(names) else "effort"
                raise LogError(source, field, f"message {k + 1} has {len(names)} names but "
                                              f"{len(getattr(msg, field))} {field} values")
            velocity = np.asarray(msg.velocity, float)
            has_velocity = has_velocity and len(velocity) == len(names)
            buffer["t"].append(t if t > 0 else stamp * 1e-9)
            buffer["q"].append(position[index])
            buffer["tau"].append(effort[index])
            buffer["qd"].append(velocity[index] if has_velocity else None)
            if len(buffer["t"]) == chunk_rows:
                yield _bag_chunk(buffer, first_row, has_velocity)
                first_row += chunk_rows
                buffer = {key: [] for key in buffer}
        if buffer["t"]:
            yield _bag_chunk(buffer, first_row, has_velocity)
    finally:
        reader.close()


def _bag_chunk(buffer: dict, first_row: int, has_velocity: bool) -> RawChunk:
    qd = np.array(buffer["qd"], float) if has_velocity else None
    return RawChunk(np.array(buffer["t"], float), np.array(buffer["q"], float), np.array(buffer["tau"], float),
                    qd, None, first_row)


def _joint_order(source: str, names: list[str], joint_names: list[str], message: int) -> np.ndarray:
    """Indices into a message's arrays, in the description's joint order; a LogError for a
    missing or an extra name."""
    # "panda_joint3" is joint3 when the description's joints carry the default names
    suffixed = {j: [m for m in names if m.endswith("_" + j)] for j in joint_names if j not in names}
    if suffixed and all(len(v) == 1 for v in suffixed.values()):
        names = [next((j for j, v in suffixed.items() if v == [m]), m) for m in names]
    missing = [j for j in joint_names if j not in names]
    extra = [j for j in names if j not in joint_names]
    if missing:
        close = difflib.get_close_matches(missing[0], extra, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise LogError(source, "name", f"message {message} has no joint {missing[0]!r} of the description "
                                       f"(missing: {', '.join(missing)}; the message names {', '.join(names)}){hint}")
    if extra:
        raise LogError(source, "name", f"message {message} names joint(s) {', '.join(extra)} the description does "
                                       f"not have (its joints: {', '.join(joint_names)})")
    if len(set(names)) != len(names):
        raise LogError(source, "name", f"message {message} names a joint twice ({', '.join(names)})")
    return np.array([names.index(j) for j in joint_names])


def write_rosbag2(path, raw: RawLog, joint_names: Sequence[str], storage: str = "mcap",
                  topic: str = "/joint_states") -> None:
    """``raw`` as a rosbag2 recording (folder ``path``, ``storage`` 'mcap' or 'sqlite3') of
    ``sensor_msgs/msg/JointState`` messages stamped with ``raw.t`` (s)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    with Writer(Path(path), version=9, storage_plugin=plugin) as writer:
        connection = writer.add_connection(topic, JointState.__msgtype__, typestore=store)
        empty = np.zeros(0)
        for i, t in enumerate(raw.t):
            ns = int(round(float(t) * 1e9))
            msg = JointState(header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                             name=list(joint_names), position=np.asarray(raw.q[i], float),
                             velocity=empty if raw.qd is None else np.asarray(raw.qd[i], float),
                             effort=np.asarray(raw.tau[i], float))
            writer.write(connection, ns, store.serialize_cdr(msg, JointState.__msgtype__))


def write_rosbag1(path, raw: RawLog, joint_names: Sequence[str], topic: str = "/joint_states") -> None:
    """``raw`` as a ROS 1 ``.bag`` file of ``sensor_msgs/JointState`` messages stamped with ``raw.t`` (s)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS1_NOETIC)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    with Writer(Path(path)) as writer:
        connection = writer.add_connection(topic, JointState.__msgtype__, typestore=store)
        empty = np.zeros(0)
        for i, t in enumerate(raw.t):
            ns = int(round(float(t) * 1e9))
            msg = JointState(header=Header(seq=i, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                             name=list(joint_names), position=np.asarray(raw.q[i], float),
                             velocity=empty if raw.qd is None else np.asarray(raw.qd[i], float),
                             effort=np.asarray(raw.tau[i], float))
            writer.write(connection, ns, store.serialize_ros1(msg, JointState.__msgtype__))
