"""``discover``'s passes over the data: candidate columns computed window by window at a
linearisation point (:mod:`kindyngen.measured.measurement_model`), parallel-filtered with the
unfiltered torque and folded into moments, so memory does not grow with the log.

**Columns, compactly.**  A candidate is a :class:`Block` of columns: *dense* (payload, base
tilt, the rigid bodies' base parameters, encoder offsets and compliances: every column on every
joint's row) or *per joint* (friction, offset, armature, Stribeck, ripple, load-dependent
friction, torque gain: coefficient c of joint i acts on row i only).  Joint j's row therefore
depends on the same number ``w`` of columns for every j (the dense ones and one per per-joint
coefficient), its *support*; the pass computes, filters and folds those ``w`` values per joint
and row, never the zeros of the full ``n x p`` layout.

**Moments** (:class:`Moments`): per cross-validation fold and joint, the triangular factor of
``[A_j | r_j]`` over the joint's support (exact residual sums for any coefficients); for the
final pass also the lagged products of ``[A_j | r_j]`` (the residual's autocorrelation, for the
effective sample size) and the Gram matrix of ``[A_j | r_j | signals | 1]`` (what the rest
correlates with).  Folds: each recording cut into K contiguous time blocks, fold k the k-th
block of every recording.

**Parallel filtering.**  The columns and the predicted reading are computed from each
recording's motion estimate, then filtered with the recording's *unfiltered* torque by the same
linear filter and decimated (:class:`kindyngen.measured.log_streaming.ChunkedParallelFilter`):
a linear filter applied to both sides keeps every linear-in-parameters relation exact.
"""
from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

from .log_preparing import Preprocessing, Segment, filtered_rows, noise_gain, zero_phase_low_pass
from .log_streaming import ChunkedParallelFilter, overlap_rows
from .ls_factor import fold_rows
from .measurement_model import (DENSE, Point, RigidBodies, dense_columns, joint_columns, parameter_names, reading,
                                state)

#: signals filtered alongside the columns in the final pass, for the "what the rest correlates
#: with" verdict
SIGNALS = ("q", "qd", "qdd", "sign(qd)", "nominal torque")
#: lags of the residual's autocorrelation folded for the effective sample count
MAX_LAG = 32
#: rows of lagged products formed at once
LAG_ROWS = 1024
#: samples per chunk of the parallel filter's output
CHUNK_ROWS = 20000
#: samples whose columns are computed at once
WINDOW_ROWS = 4096


# ---------------------------------------------------------------------------------------------
# recordings

@dataclass(frozen=True)
class Recording:
    """One segment of a recording as a pass reads it: ``rows`` samples, given by ``pieces()``
    (a fresh iterator of consecutive preprocessed pieces at each call: every pass reads the
    recording again), each a :class:`kindyngen.measured.log_preparing.Segment` with its
    unfiltered torque and ``low_pass``.  ``index``: the recording's place among all (the seed of
    its noise for :func:`elastic_noise_bias`)."""

    rows: int
    pieces: Callable[[], Iterable[Segment]]
    index: int = 0


def in_memory(segments: Sequence[Segment]) -> tuple[Recording, ...]:
    """Recordings of segments already in memory (each piece the whole segment)."""
    return tuple(Recording(len(seg.t), (lambda seg=seg: iter((seg,))), i) for i, seg in enumerate(segments))


def piece_windows(pieces, chunk: int, halo: int):
    """Windows of a segment fed in consecutive pieces: ``(first, context, s, e)`` with
    ``context`` the arrays (t, q, qd, qdd, tau, raw torque) of rows ``[first, first + len)``, the
    window's own rows ``[s, e)`` (global indices) and up to ``halo`` rows of either
    neighbour; every row in exactly one window, in order."""
    buf, b0, s, first_piece = None, 0, 0, None
    names = ("t", "q", "qd", "qdd", "tau", "raw")
    for piece in pieces:
        if first_piece is None:
            first_piece = piece
        raw = piece.tau_unfiltered if piece.low_pass is not None else piece.tau
        new = dict(zip(names, (piece.t, piece.q, piece.qd, piece.qdd, piece.tau, raw)))
        buf = new if buf is None else {k: np.concatenate([buf[k], new[k]]) for k in names}
        while b0 + len(buf["q"]) >= s + chunk + halo:
            a, e = max(0, s - halo), s + chunk
            yield first_piece, a, {k: v[a - b0:e + halo - b0] for k, v in buf.items()}, s, e
            s = e
            drop = max(0, s - halo - b0)
            buf = {k: v[drop:] for k, v in buf.items()}
            b0 += drop
    if buf is None:
        return
    end = b0 + len(buf["q"])
    while s < end:
        a, e = max(0, s - halo), min(end, s + chunk)
        yield first_piece, a, {k: v[a - b0:min(end, e + halo) - b0] for k, v in buf.items()}, s, e
        s = e


# ---------------------------------------------------------------------------------------------
# the spring torque of an elastic joint, and what the torque noise alone makes of it

def spring_torque(tau, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint torque seen by a motor-side encoder's spring and its first two time
    derivatives, from a smooth torque estimate ``tau`` (N, n) sampled every ``dt`` s."""
    tau = np.asarray(tau, float)
    if len(tau) < 3:
        return tau, np.zeros_like(tau), np.zeros_like(tau)
    d = np.gradient(tau, dt, axis=0, edge_order=2)
    return tau, d, np.gradient(d, dt, axis=0, edge_order=2)


def spring_of(segment) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint torque of a motor-side encoder's spring along a segment and its first two
    time derivatives: the low-passed measured torque (the joint torque itself, whatever the
    model misses; divided by a torque sensor's gain where the model has one,
    :func:`kindyngen.measured.measurement_model.joint_spring`).  Its noise correlates with the
    residual's: :func:`elastic_noise_bias` says how large a compliance that noise alone
    produces."""
    smooth = segment.tau if segment.low_pass is not None or len(segment.t) < 60 else \
        zero_phase_low_pass(segment.tau, 1.0 / segment.dt, min(5.0, 0.2 / segment.dt))
    return spring_torque(smooth, segment.dt)


def _smoothing(rows: int, dt: float, low_pass):
    """(rate, cutoff, order) of the smoothing :func:`spring_of` applies to the torque (None:
    none: a segment filtered already, or too short) and the halo of rows it needs."""
    if low_pass is not None or rows < 60:
        return None, 2
    cutoff = min(5.0, 0.2 / dt)
    return (1.0 / dt, cutoff, 4), overlap_rows(Preprocessing(cutoff_hz=cutoff), dt) + 2


def _spring(context, dt, i0, i1, smoothing):
    """The spring torque and its derivatives (:func:`spring_of`) on rows ``i0:i1`` of a window."""
    tau = context["tau"]
    if smoothing is not None:
        tau = zero_phase_low_pass(tau, *smoothing)
    return tuple(x[i0:i1] for x in spring_torque(tau, dt))


def _directional(torques, q, qd, qdd, dq, dqd, dqdd) -> np.ndarray:
    """Derivative of ``torques(q, qd, qdd)`` along ``(dq, dqd, dqdd)`` by central differences."""
    size = float(np.max(np.abs(dq))) if np.any(dq) else float(np.max(np.abs(np.concatenate([dqd, dqdd]))))
    if size == 0:
        return np.zeros_like(q)
    h = 1e-5 / size
    plus = torques(q + h * dq, qd + h * dqd, qdd + h * dqdd)
    minus = torques(q - h * dq, qd - h * dqd, qdd - h * dqdd)
    return (plus - minus) / (2 * h)


def sensing_columns(name: str, torques, q, qd, qdd, spring=None) -> tuple[np.ndarray, tuple[str, ...]]:
    """(columns (N, n, n), parameter names) of an effect on the measurement, to first order,
    for the joint torques ``torques(q, qd, qdd)`` (N, n) of a model: ``encoder_offset``
    (``q_logged = q + dq_i``: ``-dtau/dq_i``), ``motor_side_elasticity`` (``q_logged = q +
    ce_i tau_i``: ``-D tau . (tau_i, taud_i, taudd_i) e_i``, ``spring`` the joint torque and
    its derivatives, :func:`spring_torque`), ``torque_sensor_gain`` (``tau_logged = (1 + gt_i)
    tau_i``: ``tau_i``).  Columns of joint i's coefficient in column i.  (``identify`` fits
    these with the rigid bodies; ``discover`` uses
    :func:`kindyngen.measured.measurement_model.dense_columns`, the same derivatives at any
    linearisation point.)"""
    n = q.shape[1]
    out = np.zeros((len(q), n, n))
    if name == "torque_sensor_gain":
        rows = np.arange(n)
        out[:, rows, rows] = torques(q, qd, qdd)
        return out, tuple(f"gt{i + 1}" for i in range(n))
    if name not in ("encoder_offset", "motor_side_elasticity"):
        raise ValueError(f"{name!r} is not an effect on the measurement")
    zero = np.zeros_like(q)
    for i in range(n):
        dq = zero.copy()
        if name == "encoder_offset":
            dq[:, i] = 1.0
            out[:, :, i] = -_directional(torques, q, qd, qdd, dq, zero, zero)
        else:
            s, sd, sdd = spring
            dqd, dqdd = zero.copy(), zero.copy()
            dq[:, i], dqd[:, i], dqdd[:, i] = s[:, i], sd[:, i], sdd[:, i]
            out[:, :, i] = -_directional(torques, q, qd, qdd, dq, dqd, dqdd)
    return out, tuple(f"{'dq' if name == 'encoder_offset' else 'ce'}{i + 1}" for i in range(n))


def _noise_spring(segment, residual, index):
    """(white noise of the residual's level (N, n), its spring torque): the torque sensor's
    noise alone, smoothed as :func:`spring_of` smooths the measured torque (a fixed seed per
    recording, so the outcome is a function of the input)."""
    sigma = noise_floor(residual, [len(residual)])
    noise = sigma * np.random.default_rng(24 + index).standard_normal(residual.shape)
    if segment.low_pass is not None:
        lp = segment.low_pass
        smooth = zero_phase_low_pass(noise, lp.rate_hz, lp.cutoff_hz, lp.order)
    elif len(segment.t) < 60:
        smooth = noise
    else:
        smooth = zero_phase_low_pass(noise, 1.0 / segment.dt, min(5.0, 0.2 / segment.dt))
    return noise, spring_torque(smooth, segment.dt)


def elastic_noise_bias(torques, segments, springs=None) -> np.ndarray:
    """Per joint, the compliance ``ce_i`` (rad per N m) that the torque sensor's noise alone
    gives an elastic-joint fit: the least-squares coefficient of joint i's spring column built
    from noise (of the level :func:`noise_floor` finds in the segment's residual against
    ``torques(q, qd, qdd)``), against that noise, both through the segment's parallel filter,
    over the squared norm of the column built from the measured torque (``springs``, default
    :func:`spring_of` of each segment).  A compliance not well above this is the noise's."""
    num = den = 0.0
    for index, seg in enumerate(segments):
        q, qd, qdd = seg.q, seg.qd, seg.qdd
        raw = seg.tau_unfiltered if seg.low_pass is not None else seg.tau
        noise, noise_spring = _noise_spring(seg, raw - torques(q, qd, qdd), index)
        spring = spring_of(seg) if springs is None else springs[index]
        measured, _ = sensing_columns("motor_side_elasticity", torques, q, qd, qdd, spring)
        alone, _ = sensing_columns("motor_side_elasticity", torques, q, qd, qdd, noise_spring)
        n = q.shape[1]
        F = filtered_rows(seg, np.concatenate([measured, alone, noise[:, :, None]], axis=2))[1]
        C, Cn, r = F[:, :, :n], F[:, :, n:2 * n], F[:, :, 2 * n]
        num = num + np.einsum("tji,tj->i", Cn, r)
        den = den + np.einsum("tji,tji->i", C, C)
    return np.abs(num) / np.where(den > 0, den, np.inf)


def elastic_noise_bias_pass(torques, recordings, raw_floors, chunk_rows) -> np.ndarray:
    """:func:`elastic_noise_bias` of the recordings, window by window: the noise of each
    recording drawn in order from its seed (the same numbers as drawn whole), smoothed and
    differentiated in windows with the smoothing's overlap, its columns and the measured
    torque's through the chunked parallel filter.  ``torques(q, qd, qdd)``: the joint torques
    of the model the compliance is fitted beside."""
    num = den = 0.0
    for rec, sigma in zip(recordings, raw_floors):
        first = next(iter(rec.pieces()), None)
        if first is None:
            continue
        lp, dt = first.low_pass, first.dt
        measured_smoothing, halo = _smoothing(rec.rows, dt, lp)
        if lp is not None:
            noise_smoothing = (lp.rate_hz, lp.cutoff_hz, lp.order)
            halo = overlap_rows(Preprocessing(cutoff_hz=lp.cutoff_hz, order=lp.order), dt) + 2
            filt = ChunkedParallelFilter(lp, halo - 2, chunk_rows)
        else:
            noise_smoothing, filt = measured_smoothing, None
        rng = np.random.default_rng(24 + rec.index)
        n = first.q.shape[1]
        noise, n0 = np.zeros((0, n)), 0           # drawn rows [n0, n0 + len)

        def add(F):
            nonlocal num, den
            C, Cn, r = F[:, :, :n], F[:, :, n:2 * n], F[:, :, 2 * n]
            num = num + np.einsum("tji,tj->i", Cn, r)
            den = den + np.einsum("tji,tji->i", C, C)
        for seg, a, context, s, e in piece_windows(rec.pieces(), min(chunk_rows, WINDOW_ROWS), halo):
            b = a + len(context["q"])
            if n0 + len(noise) < b:
                noise = np.concatenate([noise, sigma * rng.standard_normal((b - n0 - len(noise), n))])
            window = noise[a - n0:b - n0]
            i0, i1 = s - a, e - a
            smooth = window if noise_smoothing is None else zero_phase_low_pass(window, *noise_smoothing)
            noise_spring = tuple(x[i0:i1] for x in spring_torque(smooth, dt))
            spring = _spring(context, dt, i0, i1, measured_smoothing)
            q, qd, qdd = context["q"][i0:i1], context["qd"][i0:i1], context["qdd"][i0:i1]
            measured, _ = sensing_columns("motor_side_elasticity", torques, q, qd, qdd, spring)
            alone, _ = sensing_columns("motor_side_elasticity", torques, q, qd, qdd, noise_spring)
            stack = np.concatenate([measured, alone, window[i0:i1, :, None]], axis=2)
            if filt is None:
                add(stack)
            else:
                m = i1 - i0
                for out in filt.push(np.concatenate([stack.reshape(m, -1), np.zeros((m, 1))], axis=1)):
                    add(out[:, :-1].reshape(len(out), n, -1))
            drop = max(0, e - halo - n0)
            noise, n0 = noise[drop:], n0 + drop
        if filt is not None:
            for out in filt.finish():
                add(out[:, :-1].reshape(len(out), n, -1))
    return np.abs(num) / np.where(den > 0, den, np.inf)


# ---------------------------------------------------------------------------------------------
# statistics of the residual

def noise_floor(residual: np.ndarray, lengths: Sequence[int]) -> np.ndarray:
    """Per joint, the white-noise level of ``residual`` (N, n) from the robust scale of its
    second difference inside each segment (``lengths`` samples each, never across a seam).

    >>> rng = np.random.default_rng(0)
    >>> x = 0.1 * rng.standard_normal((20000, 1)) + np.sin(np.linspace(0, 20, 20000))[:, None]
    >>> round(float(noise_floor(x, [20000])[0]), 2)
    0.1
    """
    parts, start = [], 0
    for length in lengths:
        seg = residual[start:start + length]
        start += length
        if len(seg) >= 3:
            parts.append(np.diff(seg, 2, axis=0))
    d2 = np.concatenate(parts, axis=0)
    return 1.4826 * np.median(np.abs(d2), axis=0) / math.sqrt(6.0)


def effective_samples(residual: np.ndarray) -> np.ndarray:
    """Per joint, ``N / (1 + 2 sum rho_k)`` with the residual's autocorrelation summed up to
    the first non-positive lag (at least 1, at most N).

    >>> rng = np.random.default_rng(1)
    >>> white = rng.standard_normal((4000, 1))
    >>> bool(3000 < effective_samples(white)[0] <= 4000)
    True
    >>> smooth = np.convolve(white[:, 0], np.ones(20) / 20, "same")[:, None]
    >>> bool(effective_samples(smooth)[0] < 400)
    True
    """
    N, n = residual.shape
    out = np.empty(n)
    size = 1 << int(np.ceil(np.log2(2 * N)))
    for j in range(n):
        x = residual[:, j] - residual[:, j].mean()
        f = np.fft.rfft(x, size)
        acf = np.fft.irfft(f * np.conj(f), size)[:N]
        if acf[0] <= 0:
            out[j] = N
            continue
        rho = acf[1:] / acf[0]
        stop = np.flatnonzero(rho <= 0)
        s = rho[:stop[0]].sum() if len(stop) else rho.sum()
        out[j] = min(N, max(1.0, N / (1.0 + 2.0 * s)))
    return out


def noise_correlation(low_pass) -> float:
    """``N / N_eff`` of white noise after the parallel filter and its decimation (1 without a
    filter): how much the filtered rows' own correlation inflates a variance, from 40 000
    samples of white noise (a fixed seed) through the filter.

    >>> from kindyngen.measured.log_preparing import LowPass
    >>> round(noise_correlation(LowPass(200.0, 5.0, 4, 5)), 1), noise_correlation(None)
    (5.4, 1.0)
    """
    if low_pass is None:
        return 1.0
    x = np.random.default_rng(0).standard_normal((40000, 1))
    y = zero_phase_low_pass(x, low_pass.rate_hz, low_pass.cutoff_hz, low_pass.order)[1000:-1000:low_pass.decimate]
    return float(len(y) / effective_samples(y)[0])


#: bins of |second difference| for the noise floor's median: the top 16 bits of the IEEE double
#: (its exponent and 4 mantissa bits, 1/16 of an octave each; the bit pattern of a non-negative
#: double orders like its value)
MEDIAN_BINS = 1 << 15


def _bin_of(x: np.ndarray) -> np.ndarray:
    return (np.abs(np.ascontiguousarray(x, float)).view(np.int64) >> 48).astype(np.intp)


def _count_bins(bins: np.ndarray, d2: np.ndarray) -> None:
    """Add the |values| of ``d2`` (m, n) to the per-joint counts ``bins`` (n, MEDIAN_BINS)."""
    b = _bin_of(d2)
    for j in range(bins.shape[0]):
        bins[j] += np.bincount(b[:, j], minlength=MEDIAN_BINS)


def median_pass(torques, recordings, counts, chunk_rows) -> list[np.ndarray]:
    """Per recording, the noise floor ``1.4826 median|d2 r| / sqrt(6)`` of its unfiltered
    residual against ``torques(q, qd, qdd)`` (:func:`noise_floor`), exactly and in bounded
    memory: the data pass counted the values per bin, so the bins of the two middle ranks are
    known; this pass keeps only the values in those bins and picks the ranks among them."""
    out = []
    for rec, bins in zip(recordings, counts):
        n = bins.shape[0]
        total = int(bins[0].sum())
        if total == 0:
            out.append(np.zeros(n))
            continue
        ranks = ((total - 1) // 2, total // 2)
        cum = np.cumsum(bins, axis=1)
        wanted = [[int(np.searchsorted(cum[j], k, side="right")) for k in ranks] for j in range(n)]
        kept = [[] for _ in range(n)]
        for seg, a, context, s, e in piece_windows(rec.pieces(), min(chunk_rows, WINDOW_ROWS), 2):
            i0, i1 = s - a, e - a
            c0, c1 = max(0, i0 - 2), min(len(context["q"]), i1 + 2)
            tau_ctx = torques(context["q"][c0:c1], context["qd"][c0:c1], context["qdd"][c0:c1])
            d2 = np.diff(context["raw"][c0:c1] - tau_ctx, 2, axis=0)
            centre = a + c0 + 1 + np.arange(len(d2))
            d2 = np.abs(d2[(centre >= s) & (centre < e)])
            b = _bin_of(d2)
            for j in range(n):
                kept[j].append(d2[np.isin(b[:, j], wanted[j]), j])
        floor = np.empty(n)
        for j in range(n):
            values = np.sort(np.concatenate(kept[j]))
            first = int(cum[j][wanted[j][0] - 1]) if wanted[j][0] > 0 else 0     # values below the lower bin
            middle = [values[k - first] for k in ranks]
            floor[j] = 1.4826 * np.mean(middle) / math.sqrt(6.0)
        out.append(floor)
    return out


# ---------------------------------------------------------------------------------------------
# blocks of columns and their compact layout

@dataclass(frozen=True, eq=False)
class Block:
    """A candidate's columns in a pass: ``key`` (``coulomb_friction``, ``stribeck_friction@0.05``,
    ``position_ripple@6``, or a final block with per-joint hyperparameters), ``candidate``,
    ``names`` (its coefficients, :func:`parameter_names` order), ``stribeck_velocity`` /
    ``ripple_order`` per joint where the candidate has one."""

    key: str
    candidate: str
    names: tuple[str, ...]
    stribeck_velocity: np.ndarray | None = None
    ripple_order: np.ndarray | None = None

    @property
    def dense(self) -> bool:
        return self.candidate in DENSE

    @property
    def width(self) -> int:
        return len(self.names)


def make_block(candidate: str, n: int, base_names=(), stribeck_velocity=None, ripple_order=None,
               key: str | None = None) -> Block:
    """A block of a candidate (one velocity or order for every joint, or one per joint)."""
    vs = None if stribeck_velocity is None else np.broadcast_to(np.asarray(stribeck_velocity, float), (n,)).copy()
    k = None if ripple_order is None else np.broadcast_to(np.asarray(ripple_order, float), (n,)).copy()
    if key is None:
        key = candidate
        if vs is not None:
            key += "@" + ("%g" % vs[0] if np.all(vs == vs[0]) else ",".join("%g" % v for v in vs))
        if k is not None:
            key += "@" + ("%g" % k[0] if np.all(k == k[0]) else ",".join("%g" % v for v in k))
    return Block(key, candidate, parameter_names(candidate, n, base_names), vs, k)


@dataclass(frozen=True, eq=False)
class Layout:
    """Global column numbering of ``blocks`` (in order) and each joint's support: ``slices``
    key -> global columns; ``support`` (n, w): the global column of each compact column per
    joint; ``compact`` key -> compact columns (per joint) of the block."""

    blocks: tuple[Block, ...]
    slices: dict
    support: np.ndarray
    compact: dict
    p: int

    @property
    def w(self) -> int:
        return self.support.shape[1]


def layout_of(blocks: Sequence[Block], n: int) -> Layout:
    slices, compact, support = {}, {}, [[] for _ in range(n)]
    g = c = 0
    for b in blocks:
        slices[b.key] = np.arange(g, g + b.width)
        if b.dense:
            compact[b.key] = np.arange(c, c + b.width)
            for j in range(n):
                support[j] += list(range(g, g + b.width))
            c += b.width
        else:
            m = b.width // n
            compact[b.key] = np.arange(c, c + m)
            for j in range(n):
                support[j] += [g + k * n + j for k in range(m)]
            c += m
        g += b.width
    return Layout(tuple(blocks), slices, np.array(support, int).reshape(n, c), compact, g)


def block_values(block: Block, point: Point, rigid: RigidBodies, st) -> np.ndarray:
    """(m, n, compact width) of one block at a point along a window."""
    if block.dense:
        return dense_columns(block.candidate, point, rigid, st)
    return joint_columns(block.candidate, point, st, block.stribeck_velocity, block.ripple_order)


# ---------------------------------------------------------------------------------------------
# moments

class Moments:
    """What a pass keeps of the filtered compact rows ``A`` (m, n, w) and residual ``r`` (m, n):
    per fold and joint the triangular factor of ``[A_j | r_j]`` (``R`` (folds, n, w, w), ``c``,
    ``rss``), the rows per fold, and, when asked for (the final pass), per joint the lagged
    products of ``[A_j | r_j]`` for lags 1 .. ``lags`` with the first and last ``lags`` rows
    (the autocorrelation of any fit's residual, exactly) and the Gram matrix of ``[A_j | r_j |
    signals | 1]``.  Memory O(folds n w^2 + n lags w^2), whatever the log length."""

    def __init__(self, n: int, w: int, folds: int, lags: int = 0, signals: bool = False):
        self.n, self.w, self.folds, self.lags = n, w, folds, lags
        self.R = np.zeros((folds, n, w, w))
        self.c = np.zeros((folds, n, w))
        self.rss = np.zeros((folds, n))
        self.rows = np.zeros(folds, int)
        self.sum_tau2 = 0.0
        self.signals = np.zeros((n, w + 7, w + 7)) if signals else None
        self.lagged = np.zeros((n, lags, w + 1, w + 1)) if lags else None
        self.head = [np.zeros((0, w + 1)) for _ in range(n)]
        self.tail = [np.zeros((0, w + 1)) for _ in range(n)]

    def add(self, fold_of, A, r, tau, signals=None):
        """Fold filtered rows in time order: ``A`` (m, n, w), ``r`` (m, n), ``tau`` (m, n) the
        filtered torque, ``signals`` (m, n, 5) for the final pass; ``fold_of`` (m)."""
        m, n = r.shape
        for k in np.unique(fold_of):
            rows = fold_of == k
            Ak, rk = A[rows], r[rows]
            # the joints' factors on two threads (LAPACK releases the GIL; each joint's arithmetic
            # is the same whichever thread runs it)
            with ThreadPoolExecutor(max_workers=2) as pool:
                parts = list(pool.map(lambda j: fold_rows(self.R[k, j], self.c[k, j], Ak[:, j], rk[:, j]), range(n)))
            for j, (R, c, extra) in enumerate(parts):
                self.R[k, j], self.c[k, j] = R, c
                self.rss[k, j] += extra
            self.rows[k] += int(rows.sum())
        self.sum_tau2 += float(np.sum(tau ** 2))
        if self.signals is not None:
            Z = np.concatenate([A, r[:, :, None], signals, np.ones((m, n, 1))], axis=2).transpose(1, 0, 2)
            self.signals += Z.transpose(0, 2, 1) @ Z
        L = self.lags
        if not L:
            return
        for j in range(n):
            X = np.concatenate([A[:, j], r[:, j, None]], axis=1)
            Y = np.concatenate([self.tail[j], X])
            t0 = len(self.tail[j])
            if len(Y) > L:
                windows = np.lib.stride_tricks.sliding_window_view(Y, L + 1, axis=0)   # (rows, w, L + 1)
                for a in range(max(t0, L), len(Y), LAG_ROWS):
                    b = min(len(Y), a + LAG_ROWS)
                    past = windows[a - L:b - L, :, :L]            # y_{t-L} .. y_{t-1} for t in [a, b)
                    self.lagged[j] += np.tensordot(past, Y[a:b], axes=([0], [0]))[:, ::-1].transpose(1, 0, 2)
            for t in range(t0, min(L, len(Y))):                   # the first rows of the data: fewer lags
                for k in range(1, t + 1):
                    self.lagged[j][k - 1] += np.outer(Y[t - k], Y[t])
            if len(self.head[j]) < L:
                self.head[j] = np.concatenate([self.head[j], X[:L - len(self.head[j])]])
            self.tail[j] = Y[-L:]

    @property
    def samples(self) -> int:
        return int(self.rows.sum())


# ---------------------------------------------------------------------------------------------
# the pass

#: filtered rows within this many cutoff periods of either end of a recording are left out: the
#: zero-phase filter's start-up (its odd extension past the end) lets the end samples' noise
#: through with a larger gain there, decaying like the slowest pole (to 1 % in 2 periods at the
#: default 4th order); the relation between columns and torque stays exact, only noisier
EDGE_PERIODS = 2.0


def edge_rows(low_pass, filtered_rows: int) -> int:
    """Filtered rows left out at each end of a recording (0 without a low-pass, or when the
    recording is shorter than six times that).

    >>> from kindyngen.measured.log_preparing import LowPass
    >>> edge_rows(LowPass(1000.0, 5.0, 4, 25), 1000), edge_rows(None, 1000)
    (16, 0)
    """
    if low_pass is None:
        return 0
    edge = int(math.ceil(EDGE_PERIODS / low_pass.cutoff_hz * low_pass.rate_after_hz))
    return edge if filtered_rows >= 6 * edge else 0

@dataclass
class PassResult:
    moments: Moments | None
    layout: Layout
    peak: np.ndarray          # per joint, the largest |joint torque| (the spring's), 0 without elasticity
    floors: list              # per recording: (counts of |d2| per bin, noise gain, filtered rows)
    low_pass: tuple
    samples_read: int
    rms_qd: np.ndarray | None = None     # per joint, the RMS of the velocity estimate over the samples read


def data_pass(point: Point, rigid: RigidBodies, recordings, blocks: Sequence[Block], folds: int, chunk_rows: int,
              progress, lags: int = 0, signals: bool = False, need_spring: bool = False,
              count_floor: bool = False) -> PassResult:
    """One pass over the recordings at ``point``: every block's columns and the point's
    predicted reading computed window by window from the motion estimate, filtered with the
    unfiltered torque (chunked parallel filter) and folded into :class:`Moments` (the residual
    ``r = tau - reading``).  ``count_floor``: count the second differences of the unfiltered
    residual per recording in bins (the noise floor's median follows in :func:`median_pass`)."""
    n = point.n
    layout = layout_of(blocks, n)
    w = layout.w
    moments = None
    peak = np.zeros(n)
    floors, low_pass_text = [], []
    started, last, read = time.perf_counter(), time.perf_counter(), 0
    sum_qd2 = np.zeros(n)
    for rec in recordings:
        state_ = dict(emitted=0, m_total=None, filt=None, bins=np.zeros((n, MEDIAN_BINS), np.int64))

        def fold(F, tau):
            nonlocal moments
            if moments is None:
                moments = Moments(n, w, folds, lags, signals)
            i = state_["emitted"] + np.arange(len(tau))
            state_["emitted"] += len(tau)
            keep = (i >= state_["edge"]) & (i < state_["m_total"] - state_["edge"])
            if not keep.any():
                return
            F, tau, i = F[keep], tau[keep], i[keep]
            A, predicted, sig = F[:, :, :w], F[:, :, w], F[:, :, w + 1:]
            moments.add(np.minimum((i * folds) // state_["m_total"], folds - 1), A, tau - predicted, tau,
                        sig if signals else None)

        first = next(iter(rec.pieces()), None)
        if first is None:
            continue
        lp = first.low_pass
        smoothing, halo = _smoothing(rec.rows, first.dt, lp) if need_spring else (None, 2)
        state_["m_total"] = -(-rec.rows // lp.decimate) if lp is not None else rec.rows
        state_["edge"] = edge_rows(lp, state_["m_total"])
        if lp is not None:
            state_["filt"] = ChunkedParallelFilter(lp, overlap_rows(Preprocessing(cutoff_hz=lp.cutoff_hz,
                                                                                  order=lp.order), first.dt),
                                                   chunk_rows)
            low_pass_text.append(lp.describe())
        for seg, a, context, s, e in piece_windows(rec.pieces(), min(chunk_rows, WINDOW_ROWS), max(halo, 2)):
            i0, i1 = s - a, e - a
            spring = _spring(context, seg.dt, i0, i1, smoothing) if need_spring else None
            if spring is not None:
                peak = np.maximum(peak, np.max(np.abs(spring[0] / point.gain), axis=0))
            if count_floor:
                # the second differences of the unfiltered residual on the window's rows and 2 on either side
                c0, c1 = max(0, i0 - 2), min(len(context["q"]), i1 + 2)
                if np.any(point.compliance):
                    raise ValueError("the noise floor is counted at the nominal rigid-body model")
                predicted = reading(point, rigid, context["q"][c0:c1], context["qd"][c0:c1], context["qdd"][c0:c1])
                d2 = np.diff(context["raw"][c0:c1] - predicted, 2, axis=0)
                centre = a + c0 + 1 + np.arange(len(d2))
                _count_bins(state_["bins"], d2[(centre >= s) & (centre < e)])
            st = state(point, rigid, context["q"][i0:i1], context["qd"][i0:i1], context["qdd"][i0:i1], spring)
            m = i1 - i0
            sum_qd2 += np.sum(context["qd"][i0:i1] ** 2, axis=0)
            parts = [block_values(b, point, rigid, st) for b in blocks]
            parts.append(st.reading[:, :, None])
            if signals:
                parts.append(np.stack([st.q, st.qd, st.qdd, np.sign(st.qd), st.reading], axis=2))
            stack = np.concatenate(parts, axis=2) if parts else np.zeros((m, n, 0))
            read += m
            if state_["filt"] is None:
                fold(stack, context["tau"][i0:i1])
            else:
                flat = np.concatenate([stack.reshape(m, -1), context["raw"][i0:i1]], axis=1)
                for out in state_["filt"].push(flat):
                    fold(out[:, :-n].reshape(len(out), n, -1), out[:, -n:])
            now = time.perf_counter()
            if now - last > 5.0:
                progress(f"{read} samples read in {now - started:.0f} s")
                last = now
        if state_["filt"] is not None:
            for out in state_["filt"].finish():
                fold(out[:, :-n].reshape(len(out), n, -1), out[:, -n:])
        floors.append((state_["bins"], noise_gain(lp), state_["emitted"]))
    now = time.perf_counter()
    if moments is not None:
        progress(f"{read} samples read, {moments.samples} rows folded ({w} columns per joint) in "
                 f"{now - started:.1f} s")
    return PassResult(moments, layout, peak, floors, tuple(dict.fromkeys(low_pass_text)), read,
                      np.sqrt(sum_qd2 / max(read, 1)))
