"""Robot motion logs prepared for dynamic identification: cleaned, resampled, filtered, differentiated.

Identification fits ``tau = Y(q, qd, qdd) @ p`` by least squares, so it needs, on one time
base, joint positions, velocities, accelerations and torques that went through the *same*
filter.  Real logs are uneven: the time step jitters, some loggers re-send their last sample
when no new one arrived, samples go missing, velocities are given or not, accelerations
almost never.  This module turns such a log into :class:`Segment` objects: uniformly
sampled, low-pass filtered with zero phase, every derivative present, each one carrying
``notes`` that say exactly what was done to it.

The steps, each a stated and overridable choice (:class:`Preprocessing`):

1. :func:`read_log` reads and checks the file (:class:`RawLog`); every bad input is a
   :class:`LogError` naming the file, the column (or key) and the reason.
2. :func:`preprocess` drops repeated rows, splits the log at gaps, puts each piece on a
   uniform time grid, low-passes it (4th-order Butterworth, forwards and backwards),
   differentiates what the log does not give, and trims the filter's edge transients.
3. :func:`split_time` and :func:`concatenate_rows` prepare training/validation sets and the
   stacked rows for least squares.
4. :func:`parallel_filter` (via :func:`filtered_rows`): the columns of a model, computed from
   the filtered motion, and the *unfiltered* torque pass through the same linear filter and
   decimation, so that a law that is nonlinear in the motion (``sign(qd)``, ``exp``) is kept
   exact: filtering does not commute with it, but it commutes with the linear parameters.

Example (a short synthetic log; real ones are read with :func:`load_segments`):

>>> import numpy as np
>>> t = np.arange(0.0, 3.0, 0.001)
>>> q = np.column_stack([np.sin(2 * np.pi * 0.5 * t), 0.1 * t])
>>> raw = RawLog("demo", t, q, tau=np.cos(q))
>>> (segment,) = preprocess(raw)
>>> segment.n, round(segment.dt, 6), round(segment.duration, 3)
(2, 0.001, 2.199)
>>> for note in segment.notes:
...     print(note)
no repeated rows among 3000
whole log, t = 0 .. 2.999 s
q, tau low-pass 5 Hz (4th-order Butterworth, zero phase)
qd by central differences of the filtered q; qdd by central differences of that qd
trimmed 0.4 s (400 samples) at each end
>>> segment.low_pass
LowPass(rate_hz=1000.0, cutoff_hz=5.0, order=4, decimate=25)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt

from .log_reading import (CHANNELS, MIN_SAMPLES, LogError, RawLog, as_float_array, number_text, read_log, repeated_rows,
                          rounded_text)

__all__ = [
    "Preprocessing", "Segment", "LowPass", "preprocess", "load_segments", "split_time",
    "concatenate_rows", "parallel_filter", "filtered_rows", "noise_gain",
]


@dataclass(frozen=True)
class Preprocessing:
    """The choices :func:`preprocess` makes, each stated and overridable.

    ``cutoff_hz`` = 5.0
        Low-pass cutoff (Hz) of the zero-phase Butterworth filter applied to q, tau (and to
        the given qd, qdd if ``filter_given``), built with ``scipy.signal.butter(...,
        output="sos")`` and run forwards and backwards (``sosfiltfilt``), so no channel is
        delayed.  5 Hz keeps the motion of typical excitation trajectories (fundamentals
        below ~1 Hz, harmonics to a few Hz) and removes encoder and torque-sensor noise,
        which twice differentiation would amplify.  ``None``: no filtering, the data as
        stored (for logs filtered before saving).
    ``order`` = 4
        Butterworth order; forwards-backwards filtering doubles it in effect (magnitude
        ``1 / (1 + (f/fc)^(2 order))``, -6 dB at the cutoff).
    ``rate_hz`` = None
        Rate of the uniform grid.  None: the log's own rate, 1 / (median time step) rounded
        to 2 significant digits when that is within 1 %, else 3 (1000 Hz, 200 Hz, 125 Hz);
        for a log whose stamps only jitter
        around a uniform clock (see ``jitter_tolerance``) that clock's exact rate.
    ``gap_factor`` = 5.0
        A time step longer than ``gap_factor`` x median step is a gap: the log is split
        there, and nothing is interpolated, filtered or differentiated across it.
    ``trim_s`` = None
        Seconds dropped at both ends of each segment after filtering, where the
        forwards-backwards filter's edge transients live.  None: ``2 / cutoff_hz`` (0.4 s at
        5 Hz; on sines the qdd error there is ~0.4 % of the amplitude, and it falls by about
        3x per further 0.1 s), 0 when ``cutoff_hz`` is None.
    ``filter_given`` = True
        Low-pass the qd / qdd the log provides as well.  All channels of the identification
        equation then see the same filter.  False for logs whose qd / qdd were filtered
        before saving (only q and tau are then filtered here).
    ``jitter_tolerance`` = 0.5
        Time stamps that all lie within this fraction of a step of a uniform clock are
        taken as a uniform clock read with jitter (e.g. stamps taken on reception by a
        non-real-time PC): the samples stay on that clock, not interpolated.  0: always
        interpolate at the stamps as given.
    ``decimate`` = None
        After parallel filtering (:func:`parallel_filter`) keep every ``decimate``-th
        sample.  None: ``floor(rate / (8 cutoff))`` (at least 1): 8 samples per period of the
        cutoff keep everything the filter passed (25 at 1000 Hz and 5 Hz, 5 at 200 Hz), and
        fewer, less correlated rows make the fit cheaper.

    >>> Preprocessing().cutoff_hz, Preprocessing().effective_trim_s
    (5.0, 0.4)
    >>> Preprocessing(cutoff_hz=None).effective_trim_s
    0.0
    """

    cutoff_hz: float | None = 5.0
    order: int = 4
    rate_hz: float | None = None
    gap_factor: float = 5.0
    trim_s: float | None = None
    filter_given: bool = True
    jitter_tolerance: float = 0.5
    decimate: int | None = None

    def __post_init__(self):
        def positive(name, value, allow_none):
            if value is None and allow_none:
                return
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"Preprocessing.{name} must be a positive number"
                                 f"{' or None' if allow_none else ''}, got {value!r}")
        positive("cutoff_hz", self.cutoff_hz, True)
        positive("rate_hz", self.rate_hz, True)
        positive("gap_factor", self.gap_factor, False)
        if isinstance(self.order, bool) or not isinstance(self.order, int) or self.order < 1:
            raise ValueError(f"Preprocessing.order must be a positive integer, got {self.order!r}")
        if self.gap_factor <= 1:
            raise ValueError(f"Preprocessing.gap_factor must exceed 1 (a multiple of the median "
                             f"step), got {self.gap_factor!r}")
        if self.trim_s is not None and (not isinstance(self.trim_s, (int, float))
                                        or not math.isfinite(self.trim_s) or self.trim_s < 0):
            raise ValueError(f"Preprocessing.trim_s must be >= 0 or None, got {self.trim_s!r}")
        if not isinstance(self.jitter_tolerance, (int, float)) or not 0 <= self.jitter_tolerance < 1:
            raise ValueError(f"Preprocessing.jitter_tolerance must be in [0, 1), "
                             f"got {self.jitter_tolerance!r}")
        if self.decimate is not None and (isinstance(self.decimate, bool) or not isinstance(self.decimate, int)
                                          or self.decimate < 1):
            raise ValueError(f"Preprocessing.decimate must be a positive integer or None, got {self.decimate!r}")

    @property
    def effective_trim_s(self) -> float:
        """The trim actually applied: ``trim_s``, or its stated default."""
        if self.trim_s is not None:
            return float(self.trim_s)
        return 0.0 if self.cutoff_hz is None else 2.0 / self.cutoff_hz


@dataclass(frozen=True)
class LowPass:
    """The linear filter of :func:`parallel_filter`: zero-phase Butterworth of ``order`` at
    ``cutoff_hz`` on samples at ``rate_hz``, then every ``decimate``-th sample kept.

    >>> LowPass(200.0, 5.0, 4, 5).rate_after_hz
    40.0
    """

    rate_hz: float
    cutoff_hz: float
    order: int
    decimate: int

    @property
    def rate_after_hz(self) -> float:
        """Sample rate after decimation."""
        return self.rate_hz / self.decimate

    def describe(self) -> str:
        return (f"{rounded_text(self.cutoff_hz)} Hz {_ordinal(self.order)}-order Butterworth, zero phase, at "
                f"{rounded_text(self.rate_hz)} Hz, then every {self.decimate}th sample "
                f"({rounded_text(self.rate_after_hz)} Hz)")


@dataclass(frozen=True, eq=False)   # eq=False: arrays have no single truth value
class Segment:
    """A uniformly sampled piece of a log, ready for identification: time ``t`` (N,) with
    step ``dt``; ``q``, ``qd``, ``qdd``, ``tau`` (N, n), all present and all through the
    same filter; ``notes`` say what was done, in order.  ``tau_unfiltered`` (N, n): the
    torque on the same grid and rows before any low-pass, and ``low_pass`` the filter that
    ``tau`` went through (both None for a log not filtered here): :func:`filtered_rows`
    filters model columns computed from the motion together with it (parallel filtering).

    >>> import numpy as np
    >>> z = np.zeros((3, 1))
    >>> s = Segment("demo", np.array([0.0, 0.1, 0.2]), 0.1, z, z, z, z, ("as stored",))
    >>> s.n, round(s.duration, 12)
    (1, 0.2)
    """

    source: str
    t: np.ndarray
    dt: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    notes: tuple[str, ...] = field(default=())
    tau_unfiltered: np.ndarray | None = None
    low_pass: LowPass | None = None

    def __post_init__(self):
        for name in ("t", "q", "qd", "qdd", "tau"):
            object.__setattr__(self, name, as_float_array(self.source, name, getattr(self, name)))
        if self.tau_unfiltered is not None:
            object.__setattr__(self, "tau_unfiltered", as_float_array(self.source, "tau", self.tau_unfiltered))
            if self.tau_unfiltered.shape != self.tau.shape:
                raise LogError(self.source, "tau", f"unfiltered torque of shape {self.tau_unfiltered.shape} "
                                                   f"beside {self.tau.shape}")
        if (self.tau_unfiltered is None) != (self.low_pass is None):
            raise LogError(self.source, "tau", "tau_unfiltered and low_pass go together")
        object.__setattr__(self, "dt", float(self.dt))
        object.__setattr__(self, "notes", tuple(self.notes))
        if self.t.ndim != 1 or len(self.t) < 1:
            raise LogError(self.source, "t", f"expected a non-empty 1-D array, got shape {self.t.shape}")
        for name in ("q", "qd", "qdd", "tau"):
            a = getattr(self, name)
            if a.ndim != 2 or a.shape != (len(self.t), self.q.shape[1] if self.q.ndim == 2 else -1):
                raise LogError(self.source, name, f"expected shape ({len(self.t)}, n) like q, got {a.shape}")

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.q.shape[1]

    @property
    def duration(self) -> float:
        """Time from the first to the last sample (s)."""
        return float(self.t[-1] - self.t[0])

    def __repr__(self) -> str:
        rate = f"{rounded_text(1 / self.dt)} Hz" if self.dt > 0 else "one sample"
        return (f"Segment({self.source!r}, {len(self.t)} samples at {rate}, {self.n} joints, "
                f"{rounded_text(self.duration)} s from t = {number_text(self.t[0])} s)")

    def _part(self, rows: slice, note: str) -> "Segment":
        return Segment(self.source, self.t[rows], self.dt, self.q[rows], self.qd[rows],
                       self.qdd[rows], self.tau[rows], self.notes + (note,),
                       None if self.tau_unfiltered is None else self.tau_unfiltered[rows], self.low_pass)


def _round_rate(rate: float) -> float:
    """A logger's nominal rate from its median step: 2 significant digits when within 1 % of
    them (1/0.001002 s -> 1000 Hz, 1/0.0049991 s -> 200 Hz; a sampled median wanders by a
    fraction of a percent), else 3 (125 Hz stays 125 Hz)."""
    two = float(f"{rate:.2g}")
    return two if abs(two - rate) <= 0.01 * rate else float(f"{rate:.3g}")


def _uniform_clock(t: np.ndarray, tolerance: float) -> tuple[float, float] | None:
    """(step, largest stamp deviation) of the least-squares uniform clock through the stamps,
    if every stamp lies within ``tolerance`` steps of it; else None.

    Stamps read off a fixed-rate clock with reception jitter scatter around such a line and
    successive steps are anti-correlated; stamps of a genuinely uneven sampler wander away
    from any line (a random walk), which this test catches on any log of useful length."""
    k = np.arange(len(t), dtype=float)
    rel = t - t[0]             # relative time: Unix stamps would cost digits in the fit
    step, offset = np.polyfit(k, rel, 1)
    if not step > 0:
        return None
    deviation = float(np.max(np.abs(rel - (offset + step * k))))
    return (float(step), deviation) if deviation <= tolerance * step else None


def _linear(x: np.ndarray, y: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of every column of y at the grid (inside x's range)."""
    i = np.clip(np.searchsorted(x, grid, side="right") - 1, 0, len(x) - 2)
    w = ((grid - x[i]) / (x[i + 1] - x[i]))[:, None]
    return y[i] * (1.0 - w) + y[i + 1] * w


def _describe(channels: Sequence[str]) -> str:
    return ", ".join(channels)


def zero_phase_low_pass(y: np.ndarray, rate_hz: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Butterworth low-pass of ``order`` run forwards and backwards along axis 0 (no delay).

    The signal is padded (odd reflection) over one period of the cutoff, not scipy's default of
    a few samples: the filter's initial state then settles before the data begins, which cuts
    the edge error of a twice-differentiated signal about 3x.

    >>> t = np.arange(0, 4, 0.001)
    >>> y = zero_phase_low_pass(np.sin(2 * np.pi * 0.5 * t), 1000.0, 5.0)
    >>> float(np.abs(y - np.sin(2 * np.pi * 0.5 * t))[500:-500].max()) < 1e-3
    True
    """
    sos = butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
    padlen = min(len(y) - 1, int(round(rate_hz / cutoff_hz)))
    return sosfiltfilt(sos, y, axis=0, padlen=padlen)


def preprocess(raw: RawLog, settings: Preprocessing = Preprocessing()) -> tuple[Segment, ...]:
    """Turn a raw log into uniformly sampled, filtered segments with every derivative.

    In order:

    1. rows that repeat the previous row exactly (:func:`repeated_rows`) are dropped: they
       are a logger re-sending an old sample, and differentiating through them would make
       the velocity drop to zero and jump back;
    2. the log is split where a time step exceeds ``gap_factor`` x the median step (judged
       on the stamps as logged: a run of repeated rows shows the logger was alive, and the
       interval it covers is bridged like any other);
    3. each piece goes onto a uniform grid: a cubic spline for q (it is smooth, and it is
       differentiated twice), linear interpolation for tau and given qd, qdd (measured and
       noisy: a spline through noise at uneven steps overshoots, and the linear
       interpolation error on signals below the cutoff, ``A (2 pi f dt)^2 / 8``, is far
       below sensor noise); stamps that only jitter around a uniform clock stay on it;
    4. zero-phase low-pass of q, tau (and given qd, qdd with ``filter_given``);
    5. missing derivatives by central differences (``np.gradient``, uniform dt): qd from the
       filtered q, qdd from the filtered qd.  Not filtered again: the difference of a
       band-limited signal is band-limited, and a second pass would give qdd a different
       (squared) magnitude response than tau near the cutoff, breaking
       ``tau = Y(q, qd, qdd) p`` there;
    6. ``trim`` seconds dropped at each end (filter edge transients).

    Pieces too short to filter and trim are dropped with a note; if nothing remains, a
    :class:`LogError`.  With ``cutoff_hz=None``, a uniform (clock) log with qd and qdd given
    passes through unchanged apart from repeated-row removal (its time stamps are replaced
    by the clock's).

    >>> import numpy as np
    >>> t = np.arange(0.0, 2.0, 0.005)
    >>> q = np.sin(t)[:, None]; qd = np.cos(t)[:, None]; qdd = -q; tau = 2 * q
    >>> (s,) = preprocess(RawLog("demo", t, q, tau, qd, qdd), Preprocessing(cutoff_hz=None))
    >>> bool(np.array_equal(s.qdd, qdd)), len(s.t)
    (True, 400)
    """
    if not isinstance(raw, RawLog):
        raise TypeError(f"preprocess expects a RawLog, got {type(raw).__name__}")
    if not isinstance(settings, Preprocessing):
        raise TypeError(f"settings must be a Preprocessing, got {type(settings).__name__}")
    source = raw.source
    repeated = repeated_rows(raw)
    total = len(raw.t)
    log_notes = list(raw.notes)
    log_notes.append(f"dropped {int(repeated.sum())} repeated rows ({100 * repeated.sum() / total:.2f} %"
                     f" of {total})" if repeated.any() else f"no repeated rows among {total}")

    steps = np.diff(raw.t)
    positive = steps[steps > 0]
    median = float(np.median(positive))
    limit = settings.gap_factor * median
    gaps = np.flatnonzero(steps > limit)
    if gaps.size:
        listed = ", ".join(f"t = {rounded_text(raw.t[i] - raw.t[0])} s ({rounded_text(1000 * steps[i])} ms)"
                           for i in gaps[:8])
        more = f" and {gaps.size - 8} more" if gaps.size > 8 else ""
        log_notes.append(f"split at {gaps.size} gaps longer than {rounded_text(1000 * limit)} ms "
                         f"({rounded_text(settings.gap_factor)} x median step {rounded_text(1000 * median)} ms; "
                         f"times from the first sample): {listed}{more}")
    pieces = np.split(np.arange(total), gaps + 1)

    trim = settings.effective_trim_s
    results = []
    dropped: list[str] = []
    for idx in pieces:
        keep = idx[~repeated[idx]]
        span = float(raw.t[keep[-1]] - raw.t[keep[0]]) if keep.size else 0.0
        needed = 2 * trim + (MIN_SAMPLES - 1) * median
        where = f"t = {rounded_text(raw.t[idx[0]] - raw.t[0])} .. {rounded_text(raw.t[idx[-1]] - raw.t[0])} s"
        if keep.size < MIN_SAMPLES or span <= needed:
            dropped.append(f"dropped the piece {where} ({keep.size} samples, {rounded_text(span)} s): too short "
                           f"to filter and trim (needs more than {rounded_text(needed)} s and "
                           f"{MIN_SAMPLES} samples)")
            continue
        result = _process_piece(raw, keep, settings, median, trim)
        if isinstance(result, str):   # too short once on its grid and trimmed
            dropped.append(f"dropped the piece {where}: {result}")
            continue
        results.append(result + (where,))
    if not results:
        reasons = "; ".join(dropped) if dropped else "no samples"
        raise LogError(source, "t", f"nothing left after preprocessing: {reasons}")
    segments = []
    for k, (t, dt, channels, notes, where) in enumerate(results):
        label = (f"segment {k + 1} of {len(results)}: {where} of the log"
                 if len(results) > 1 or dropped or gaps.size else f"whole log, {where}")
        low_pass = None
        if "tau_unfiltered" in channels:
            rate = 1.0 / dt
            if abs(_round_rate(rate) - rate) <= 1e-9 * rate:   # a clock step's last-bit rounding
                rate = _round_rate(rate)
            decimate = settings.decimate or max(1, int(math.floor(rate / (8.0 * settings.cutoff_hz) + 1e-9)))
            low_pass = LowPass(rate, float(settings.cutoff_hz), settings.order, decimate)
        segments.append(Segment(source, t, dt, channels["q"], channels["qd"], channels["qdd"],
                                channels["tau"], tuple(log_notes + dropped + [label] + notes),
                                channels.get("tau_unfiltered"), low_pass))
    return tuple(segments)


def _process_piece(raw: RawLog, keep: np.ndarray, settings: Preprocessing, median: float,
                   trim: float) -> tuple[np.ndarray, float, dict, list[str]] | str:
    """One gap-free piece (rows ``keep`` of the log): grid, filter, derivatives, trim.
    Returns (t, dt, channels, notes), or the reason the piece is too short."""
    source = raw.source
    notes: list[str] = []
    t = raw.t[keep]
    given = {ch: getattr(raw, ch)[keep] for ch in CHANNELS if getattr(raw, ch) is not None}

    # --- onto a uniform grid
    clock = _uniform_clock(t, settings.jitter_tolerance)
    if clock is not None:
        step, deviation = clock
        x = t[0] + step * np.arange(len(t))          # the clock the stamps jitter around
        # stamps uniform up to floating-point rounding (Unix times: ~1e-7 s) need no note
        if deviation > max(1e-6 * step, 8 * np.spacing(np.abs(t).max())):
            notes.append(f"time stamps within {rounded_text(1000 * deviation)} ms ({deviation / step:.2f} of a "
                         f"step) of a uniform {rounded_text(1 / step)} Hz clock: samples placed on that clock")
    else:
        step, x = None, t
    resampled = not (clock is not None and settings.rate_hz is None)
    if not resampled:
        dt, grid, values = step, x, dict(given)
    else:
        rate = settings.rate_hz if settings.rate_hz is not None else _round_rate(1.0 / median)
        dt = 1.0 / rate
        rel = x - x[0]
        count = int(math.floor(rel[-1] / dt + 1e-9)) + 1
        grid_rel = dt * np.arange(count)
        values = {"q": CubicSpline(rel, given["q"], axis=0)(grid_rel)}
        for ch in ("qd", "qdd", "tau"):
            if ch in given:
                values[ch] = _linear(rel, given[ch], grid_rel)
        grid = x[0] + grid_rel
        others = [ch for ch in ("tau", "qd", "qdd") if ch in given]
        notes.append(f"resampled {len(t)} -> {count} samples at {rounded_text(rate)} Hz (cubic spline for q, "
                     f"linear for {_describe(others)})")
        native = 1.0 / (step if step is not None else median)
        if rate < 0.9 * native:
            # interpolation comes before the low-pass (which needs a uniform grid), so a
            # coarser grid than the log's folds everything above its Nyquist frequency in
            notes.append(f"warning: interpolated below the log's own rate ({rounded_text(native)} Hz) "
                         f"before any low-pass: content above {rounded_text(rate / 2)} Hz aliases")
    rate = 1.0 / dt

    # --- zero-phase low-pass
    if settings.cutoff_hz is not None:
        if settings.cutoff_hz >= rate / 2:
            raise LogError(source, "cutoff_hz", f"{rounded_text(settings.cutoff_hz)} Hz is not below the "
                                                f"Nyquist frequency {rounded_text(rate / 2)} Hz of the "
                                                f"{rounded_text(rate)} Hz grid")
        filtered = ["q"] + [ch for ch in ("qd", "qdd") if ch in values and settings.filter_given] + ["tau"]
        values["tau_unfiltered"] = values["tau"]
        for ch in filtered:
            values[ch] = zero_phase_low_pass(values[ch], rate, settings.cutoff_hz, settings.order)
        notes.append(f"{_describe(filtered)} low-pass {rounded_text(settings.cutoff_hz)} Hz "
                     f"({_ordinal(settings.order)}-order Butterworth, zero phase)")
        unfiltered = [ch for ch in ("qd", "qdd") if ch in values and ch not in filtered]
        if unfiltered:
            notes.append(f"{_describe(unfiltered)} as given, not filtered (filter_given=False)")
        how = "filtered"
    else:
        notes.append("no low-pass (cutoff_hz=None): " + ("interpolated values, not filtered"
                                                         if resampled else "values as stored"))
        how = "unfiltered"

    # --- derivatives the log does not give
    derived = []
    if "qd" not in values:
        values["qd"] = np.gradient(values["q"], dt, axis=0, edge_order=2)
        derived.append(f"qd by central differences of the {how} q")
    if "qdd" not in values:
        if "qd" not in given:
            source_qd = "that qd"
        elif settings.cutoff_hz is not None and not settings.filter_given:
            source_qd = "the given (unfiltered here) qd"
        else:
            source_qd = f"the {how} given qd"
        values["qdd"] = np.gradient(values["qd"], dt, axis=0, edge_order=2)
        derived.append(f"qdd by central differences of {source_qd}")
    if derived:
        notes.append("; ".join(derived))

    # --- trim the filter's edge transients
    cut = int(round(trim / dt))
    if len(grid) - 2 * cut < MIN_SAMPLES:
        return (f"{len(grid)} samples at {rounded_text(rate)} Hz leave fewer than MIN_SAMPLES = {MIN_SAMPLES} "
                f"after trimming {cut} at each end")
    if cut:
        grid = grid[cut:len(grid) - cut]
        values = {ch: v[cut:len(v) - cut] for ch, v in values.items()}
        notes.append(f"trimmed {rounded_text(trim)} s ({cut} samples) at each end")
    return grid, dt, values, notes


def _ordinal(k: int) -> str:
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def load_segments(path, n: int, settings: Preprocessing = Preprocessing()) -> tuple[Segment, ...]:
    """:func:`read_log` then :func:`preprocess`.

    >>> load_segments("run.txt", 7)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kindyngen.measured.log_reading.LogError: run.txt: field '<file>': unknown extension '.txt'; expected .csv or .npz
    """
    return preprocess(read_log(path, n), settings)


def split_time(segments: Sequence[Segment], fraction: float) -> tuple[tuple[Segment, ...], tuple[Segment, ...]]:
    """Split segments into (training, validation) by time: the first ``fraction`` of the
    span from the first segment's start to the last one's end trains, the rest validates.
    A segment straddling the cut is cut in two (samples before the cut time train), and
    both parts get a note saying where; no sample is lost or duplicated.

    Splitting by time, not by random rows, keeps validation honest: neighbouring samples of
    a filtered log are strongly correlated, so randomly drawn validation rows would be
    nearly copies of training rows.  The segments must be in time order and not overlap
    (one log's segments); split several logs one by one.

    >>> import numpy as np
    >>> t = np.arange(10) * 0.1; z = np.zeros((10, 1))
    >>> train, valid = split_time([Segment("demo", t, 0.1, z, z, z, z)], 0.5)
    >>> [len(s.t) for s in train], [len(s.t) for s in valid]
    ([5], [5])
    >>> valid[0].notes[-1]
    'cut at t = 0.45 s: after the first 50 % of the span 0 .. 0.9 s (validation part)'
    """
    segments = tuple(segments)
    if not segments:
        raise ValueError("split_time needs at least one segment")
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0 < fraction < 1:
        raise ValueError(f"fraction must be strictly between 0 and 1, got {fraction!r}")
    for before, after in zip(segments, segments[1:]):
        if after.t[0] <= before.t[-1]:
            raise LogError(after.source, "t", f"segments overlap or are out of time order "
                                              f"({rounded_text(after.t[0])} s starts before "
                                              f"{rounded_text(before.t[-1])} s ends); split each log separately")
    start, end = float(segments[0].t[0]), float(segments[-1].t[-1])
    cut_time = start + fraction * (end - start)
    train: list[Segment] = []
    valid: list[Segment] = []
    for s in segments:
        if s.t[-1] < cut_time:
            train.append(s)
        elif s.t[0] >= cut_time:
            valid.append(s)
        else:
            k = int(np.searchsorted(s.t, cut_time, side="left"))
            where = (f"cut at t = {rounded_text(cut_time)} s: after the first {rounded_text(100 * fraction)} % of the "
                     f"span {rounded_text(start)} .. {rounded_text(end)} s")
            train.append(s._part(slice(0, k), where + " (training part)"))
            valid.append(s._part(slice(k, None), where + " (validation part)"))
    return tuple(train), tuple(valid)


def concatenate_rows(segments: Sequence[Segment]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stack the samples of several segments: ``(q, qd, qdd, tau)``, each (sum N, n), for
    least squares.  Nothing is differentiated here: each segment's derivatives were taken
    within that segment, never across the joins.

    >>> import numpy as np
    >>> z = np.zeros((3, 2)); t = np.arange(3.0)
    >>> q, qd, qdd, tau = concatenate_rows([Segment("a", t, 1.0, z, z, z, z)] * 2)
    >>> q.shape
    (6, 2)
    """
    segments = tuple(segments)
    if not segments:
        raise ValueError("concatenate_rows needs at least one segment")
    n = segments[0].n
    for s in segments:
        if s.n != n:
            raise LogError(s.source, "q", f"has {s.n} joints, the first segment has {n}")
    return tuple(np.concatenate([getattr(s, ch) for s in segments], axis=0)
                 for ch in ("q", "qd", "qdd", "tau"))


def parallel_filter(columns: np.ndarray, tau: np.ndarray, low_pass: LowPass) -> tuple[np.ndarray, np.ndarray]:
    """The columns of a linear-in-parameters model and the measured torque, through one
    linear filter: zero-phase low-pass (:func:`zero_phase_low_pass`, the same padding for
    both) along axis 0, then every ``low_pass.decimate``-th sample from the first.

    Contract.  ``columns`` (N, ...) and ``tau`` (N, n) are samples of one recording (or one
    chunk of it) on its uniform grid, the columns computed from the best estimate of the
    motion (the low-passed q and its derivatives) and ``tau`` *unfiltered*.  The operator
    ``F`` applied is linear and the same for both, so whenever ``tau = columns @ p + noise``
    holds sample by sample, ``F(tau) = F(columns) @ p + F(noise)`` holds exactly, whatever
    nonlinear function of the motion the columns are (``sign(qd)``, ``exp(-(qd/vs)^2)``,
    ``|tau_nom|``): filtering the *signals* first and taking ``sign`` of a filtered velocity
    would not satisfy it.  The noise comes out with std ``noise_gain(low_pass)`` times its
    own.  Returns ``(F(columns), F(tau))`` with ``ceil(N / decimate)`` rows.

    Chunks: a chunk filtered alone differs from the whole recording filtered at once only
    within about ``rate_hz / cutoff_hz`` samples of the chunk's ends (the filter's reach);
    pass each chunk with that many extra samples of overlap on both sides, drop the overlap
    rows from the result, and start every chunk on a multiple of ``decimate`` so the kept
    samples are those of the whole recording.

    >>> rate = 200.0; t = np.arange(0, 20, 1 / rate)
    >>> qd = np.cos(2 * np.pi * 0.3 * t)[:, None]
    >>> columns = np.sign(qd)[:, :, None]; tau = 1.5 * np.sign(qd)
    >>> Fc, Ft = parallel_filter(columns, tau, LowPass(rate, 5.0, 4, 5))
    >>> Fc.shape, bool(np.allclose(Ft, 1.5 * Fc[:, :, 0]))
    ((800, 1, 1), True)
    """
    columns = np.asarray(columns, float)
    tau = np.asarray(tau, float)
    if len(columns) != len(tau):
        raise ValueError(f"{len(columns)} rows of columns beside {len(tau)} of torque")
    flat = np.concatenate([columns.reshape(len(columns), -1), tau.reshape(len(tau), -1)], axis=1)
    out = zero_phase_low_pass(flat, low_pass.rate_hz, low_pass.cutoff_hz, low_pass.order)[::low_pass.decimate]
    k = int(np.prod(columns.shape[1:]))
    return out[:, :k].reshape((len(out),) + columns.shape[1:]), out[:, k:].reshape((len(out),) + tau.shape[1:])


def noise_gain(low_pass: LowPass | None) -> float:
    """Std of white noise after :func:`parallel_filter` over its std before (1 for None): the
    root of the sum of the squared impulse response of the zero-phase filter.

    >>> round(noise_gain(LowPass(200.0, 5.0, 4, 5)), 3)
    0.212
    """
    if low_pass is None:
        return 1.0
    length = 2 * int(round(20 * low_pass.rate_hz / low_pass.cutoff_hz)) + 1
    impulse = np.zeros(length)
    impulse[length // 2] = 1.0
    h = zero_phase_low_pass(impulse, low_pass.rate_hz, low_pass.cutoff_hz, low_pass.order)
    return float(np.sqrt(np.sum(h ** 2)))


def filtered_rows(segment: Segment, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, columns, tau)`` of one segment ready for least squares: ``columns`` (N, ...)
    computed from the segment's motion (``q``, ``qd``, ``qdd``) and the segment's unfiltered
    torque through :func:`parallel_filter` with the segment's ``low_pass``; a segment not
    filtered here (``low_pass`` None) passes as it is.

    >>> z = np.zeros((3, 1)); s = Segment("demo", np.arange(3.0), 1.0, z, z, z, z + 2)
    >>> filtered_rows(s, z[:, :, None])[2][:, 0]
    array([2., 2., 2.])
    """
    columns = np.asarray(columns, float)
    if len(columns) != len(segment.t):
        raise ValueError(f"{len(columns)} rows of columns for a segment of {len(segment.t)} samples")
    if segment.low_pass is None:
        return segment.t, columns, segment.tau
    Fc, Ft = parallel_filter(columns, segment.tau_unfiltered, segment.low_pass)
    return segment.t[::segment.low_pass.decimate], Fc, Ft


def timeline(segments: Sequence[Segment]) -> np.ndarray:
    """One time axis through several segments for plotting, each segment continuing one step
    after the previous one ends (gaps and separate logs closed up).

    >>> import numpy as np
    >>> z = np.zeros((2, 1))
    >>> timeline([Segment("a", np.array([5.0, 6.0]), 1.0, z, z, z, z), Segment("b", np.array([0.0, 1.0]), 1.0, z, z, z, z)])
    array([0., 1., 2., 3.])
    """
    parts, start = [], 0.0
    for s in segments:
        parts.append(s.t - s.t[0] + start)
        start = parts[-1][-1] + s.dt
    return np.concatenate(parts)
