"""A log read and low-pass filtered piece by piece, in bounded memory, with the same numbers as
the whole log: the readers' chunks preprocessed with overlapping windows
(:func:`segment_pieces`, :func:`overlap_rows`), and the parallel filter of regressor columns and
torque fed chunk by chunk (:class:`ChunkedParallelFilter`).  Used by identification
(:mod:`kindyngen.measured.streaming`) and by ``discover`` (:mod:`kindyngen.measured.discovery`,
:mod:`kindyngen.measured.discrepancy`); it knows nothing of either."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Iterator

import numpy as np

from .log_checks import LogBounds
from .log_formats import CHUNK_ROWS, SMALL_CSV_BYTES, RawChunk, iter_chunks, log_kind, read_any, time_span_of_file
from .log_preparing import Preprocessing, Segment, preprocess, zero_phase_low_pass
from .log_reading import MIN_SAMPLES, LogError, RawLog


def overlap_rows(settings: Preprocessing, dt: float) -> int:
    """Samples of overlap on each side of a chunk: the slowest pole of the Butterworth filter
    decays as ``exp(-a t)``, ``a = 2 pi f_c sin(pi / (2 order))`` (12.0 /s at 5 Hz, 4th order);
    40 / a seconds (3.3 s) bring an edge error to ``e^-40 = 4e-18`` of it, with one cutoff
    period for the reflection padding and two samples for the differences on top.

    >>> overlap_rows(Preprocessing(), 0.001)
    3530
    """
    if settings.cutoff_hz is None:
        return 2
    decay = 2 * math.pi * settings.cutoff_hz * math.sin(math.pi / (2 * settings.order))
    return int(math.ceil((40.0 / decay + 1.0 / settings.cutoff_hz) / dt)) + 2


class NotStreamable(Exception):
    """A window that does not preprocess like the whole log (gap, repeated row, resampling)."""


def _window_log(source: str, buf: dict, a: int, b: int) -> RawLog:
    def part(ch):
        return None if buf[ch] is None else buf[ch][a:b]
    return RawLog(source, buf["t"][a:b], part("q"), part("tau"), part("qd"), part("qdd"))


def stream_segments(path, n: int, settings: Preprocessing = Preprocessing(), joint_names=None,
                    chunk_rows: int = CHUNK_ROWS, notes: list | None = None,
                    bounds: LogBounds | None = None) -> Iterator[Segment]:
    """Preprocessed consecutive pieces of the log at ``path`` whose concatenation equals (to
    ~1e-15 relative) the segments of ``preprocess(read_any(path))``; at most about ``2 chunk_rows``
    samples each, each carrying its unfiltered torque and low-pass when filtered (as the whole
    log's segments do).  ``notes`` (a list) receives what was done; ``bounds``: the robot's, each
    chunk checked against them as it is read (:mod:`kindyngen.measured.log_checks`)."""
    for _, piece in segment_pieces(path, n, settings, joint_names, chunk_rows, notes, bounds=bounds):
        yield piece


def segment_pieces(path, n: int, settings: Preprocessing = Preprocessing(), joint_names=None,
                   chunk_rows: int = CHUNK_ROWS, notes: list | None = None,
                   spans: list | None = None, bounds: LogBounds | None = None) -> Iterator[tuple[int, Segment]]:
    """``(segment index, piece)`` of :func:`stream_segments`; raises :class:`NotStreamable` at
    the first window that would not preprocess like the whole log (then read it whole).
    ``notes`` (a list) receives what was done; when the log is preprocessed whole anyway
    (short, or resampled), ``spans`` (a list) receives the exact (first, last) time of its
    segments before the first piece, as :func:`kindyngen.measured.log_preparing.split_time`
    takes them.  ``bounds``: the robot's, every sample checked against them as it is read."""
    source = str(path)
    notes = notes if notes is not None else []
    spans = spans if spans is not None else []
    if settings.rate_hz is not None:
        notes.append("preprocessed whole in memory (resampling to --rate needs the whole log)")
        whole = preprocess(read_any(path, n, joint_names, bounds), settings)
        spans.append((float(whole[0].t[0]), float(whole[-1].t[-1])))
        yield from segment_chunks(whole, chunk_rows)
        return
    chunks = iter_chunks(path, n, joint_names, chunk_rows, bounds)
    buf = None           # arrays of global rows [b0, b1)
    b0 = 0
    exhausted = False
    window_settings = replace(settings, trim_s=0.0)
    cut = L = None
    s = None             # next output row

    def extend(chunk: RawChunk):
        nonlocal buf
        notes.extend(chunk.notes)
        new = {"t": chunk.t, "q": chunk.q, "tau": chunk.tau, "qd": chunk.qd, "qdd": chunk.qdd}
        if buf is None:
            buf = new
        else:
            buf = {ch: (None if buf[ch] is None or new[ch] is None else np.concatenate([buf[ch], new[ch]]))
                   for ch in buf}

    def rows_buffered():
        return 0 if buf is None else len(buf["t"])

    while True:
        if not exhausted and (L is None or b0 + rows_buffered() < s + 2 * chunk_rows + L):
            chunk = next(chunks, None)
            if chunk is None:
                exhausted = True
            else:
                extend(chunk)
                if L is None and rows_buffered() >= MIN_SAMPLES:
                    steps = np.diff(buf["t"])
                    dt = float(np.median(steps[steps > 0]))
                    L = overlap_rows(settings, dt)
                    cut = int(round(settings.effective_trim_s / dt))
                    s = cut
                continue
        if buf is None:
            raise LogError(source, "t", "no samples")
        b1 = b0 + rows_buffered()
        if exhausted and (L is None or b0 == 0 and b1 <= 2 * chunk_rows + 2 * L):
            # short enough to preprocess whole: exactly what the in-memory path does
            whole = preprocess(_window_log(source, buf, 0, b1), settings)
            notes.extend(note for seg in whole for note in seg.notes)
            spans.append((float(whole[0].t[0]), float(whole[-1].t[-1])))
            yield from segment_chunks(whole, chunk_rows)
            return
        end_out = b1 - cut if exhausted else None
        if exhausted and s >= end_out:
            return
        e = end_out if exhausted and end_out - s <= 2 * chunk_rows else s + chunk_rows
        w0, w1 = max(0, s - L), min(b1, e + L)
        try:
            pieces = preprocess(_window_log(source, buf, w0 - b0, w1 - b0), window_settings)
        except LogError:
            pieces = ()
        if len(pieces) != 1 or len(pieces[0].t) != w1 - w0:
            raise NotStreamable("gaps or repeated rows: chunks would not preprocess like the whole log")
        seg = pieces[0]
        a, b = s - w0, e - w0
        if s == cut and not any("streamed" in note for note in notes):
            kept = [note for note in seg.notes if "low-pass" in note or "central differences" in note
                    or "uniform" in note]
            notes.extend(kept)
            notes.append(f"streamed in chunks of {chunk_rows} samples with {L} samples of overlap on each side; "
                         f"trimmed {cut} samples at each end of the log")
        yield 0, segment_rows(seg, a, b)
        s = e
        drop = max(0, s - L - b0)        # rows no later window needs
        if drop:
            buf = {ch: (None if v is None else v[drop:]) for ch, v in buf.items()}
            b0 += drop


def segment_rows(seg: Segment, a: int, b: int) -> Segment:
    """Rows ``a:b`` of a segment, with its unfiltered torque and low-pass."""
    unfiltered = None if seg.tau_unfiltered is None else seg.tau_unfiltered[a:b]
    return Segment(seg.source, seg.t[a:b], seg.dt, seg.q[a:b], seg.qd[a:b], seg.qdd[a:b], seg.tau[a:b], (),
                   unfiltered, seg.low_pass)


def segment_chunks(segments, rows: int) -> Iterator[tuple[int, Segment]]:
    """``(segment index, piece)``: segments cut into pieces of at most ``rows`` samples (the
    regressor of one at a time)."""
    for index, seg in enumerate(segments):
        for a in range(0, len(seg.t), rows):
            yield index, segment_rows(seg, a, a + rows)


class ChunkedParallelFilter:
    """:func:`kindyngen.measured.log_preparing.parallel_filter` of one recording fed in consecutive
    pieces of rows, the kept (decimated) rows given back chunk by chunk in bounded memory.

    Output chunk ``[s, e)`` (``s`` and ``e - s = chunk`` multiples of ``decimate``) is filtered
    in the window ``[s - overlap, e + overlap]`` clipped to the recording, ``overlap`` rounded up
    to a multiple of ``decimate``, and rows ``s, s + decimate, ...`` of it are kept: exactly the
    rows ``parallel_filter`` keeps of the whole.  Where a window ends inside the recording, the
    forwards-backwards filter's start-up differs from the whole recording's; that difference
    decays like the filter's slowest pole, to ``e^-40`` (4e-18) of the signal over
    :func:`overlap_rows` samples, so the kept rows equal the whole recording's filter to
    rounding (tested to 1e-12 of the largest value).  A recording no longer than one window is
    filtered whole (the same bits as ``parallel_filter``).  Memory: ``chunk + 2 overlap`` rows
    plus one piece.

    >>> from kindyngen.measured.log_preparing import LowPass, parallel_filter
    >>> rng = np.random.default_rng(0); x = rng.normal(size=(30000, 2)); lp = LowPass(1000.0, 5.0, 4, 25)
    >>> f = ChunkedParallelFilter(lp, overlap=3530, chunk=5000)
    >>> kept = [out for a in range(0, 30000, 7000) for out in f.push(x[a:a + 7000])] + f.finish()
    >>> whole = parallel_filter(x[:, :1, None], x[:, 1:], lp)
    >>> chunked = np.concatenate(kept)
    >>> chunked.shape, bool(np.abs(chunked[:, 1:] - whole[1]).max() < 1e-12 * np.abs(whole[1]).max())
    ((1200, 2), True)
    """

    def __init__(self, low_pass, overlap: int, chunk: int):
        d = low_pass.decimate
        self.low_pass = low_pass
        self.overlap = -(-int(overlap) // d) * d
        self.chunk = max(d, int(chunk) // d * d)
        self.buffers = None        # two (width, capacity) arrays, rows [b0, b0 + used) in the first
        self.used = 0
        self.b0 = 0
        self.rows = 0              # rows pushed so far
        self.s = 0                 # first row of the next output chunk

    def push(self, rows: np.ndarray) -> list[np.ndarray]:
        """Append ``rows`` (m, width); the filtered, decimated rows that are now final."""
        rows = np.asarray(rows, float)
        m = len(rows)
        # held transposed, (width, rows) in C order, so that sosfiltfilt filters contiguous
        # signals; in two buffers allocated once and reused (shifting rows from one into the
        # other), because fresh arrays of tens of MB cost as much in page faults as the filter
        if self.buffers is None or self.used + m > self.buffers[0].shape[1]:
            capacity = max(2 * (self.used + m), self.chunk + 2 * self.overlap + m)
            grown = [np.empty((rows.shape[1], capacity)) for _ in range(2)]
            if self.buffers is not None:
                grown[0][:, :self.used] = self.buffers[0][:, :self.used]
            self.buffers = grown
        self.buffers[0][:, self.used:self.used + m] = rows.T
        self.used += m
        self.rows += m
        out = []
        while self.rows >= self.s + self.chunk + self.overlap:
            out.append(self._emit(self.s + self.chunk, self.s + self.chunk + self.overlap))
        return out

    def finish(self) -> list[np.ndarray]:
        """The rows after the last chunk (the recording ends here)."""
        return [self._emit(self.rows, self.rows)] if self.rows > self.s else []

    def _emit(self, e: int, w1: int) -> np.ndarray:
        lp = self.low_pass
        w0 = max(0, self.s - self.overlap)
        window = self.buffers[0][:, w0 - self.b0:w1 - self.b0]
        width = window.shape[0]
        kept = np.empty((len(range(self.s - w0, e - w0, lp.decimate)), width))
        # the columns are independent signals: filtered in groups, so that no temporary exceeds
        # glibc's 32 MB mmap limit (below it, freed memory is reused instead of faulted in anew)
        group = max(1, (16 << 20) // (8 * (w1 - w0 + 2 * int(round(lp.rate_hz / lp.cutoff_hz)))))
        for g in range(0, width, group):
            y = zero_phase_low_pass(window[g:g + group].T, lp.rate_hz, lp.cutoff_hz, lp.order)
            kept[:, g:g + group] = y[self.s - w0:e - w0:lp.decimate]
        self.s = e
        drop = max(0, self.s - self.overlap - self.b0)      # rows no later window needs
        if drop:
            keep = self.used - drop
            self.buffers[1][:, :keep] = self.buffers[0][:, drop:self.used]
            self.buffers.reverse()
            self.used = keep
            self.b0 += drop
        return kept


def time_span(path, n: int, joint_names=None, chunk_rows: int = CHUNK_ROWS) -> tuple[float, float]:
    """(first, last) time stamp of a log: Parquet and large CSV files read their ``t`` column
    alone; other formats take one pass over their chunks."""
    kind = log_kind(path)
    if kind == "parquet" or (kind == "csv" and Path(path).stat().st_size > SMALL_CSV_BYTES):
        span = time_span_of_file(path)
        if span is not None:
            return span
    first = last = None
    for chunk in iter_chunks(path, n, joint_names, chunk_rows):
        first = float(chunk.t[0]) if first is None else first
        last = float(chunk.t[-1])
    return first, last
