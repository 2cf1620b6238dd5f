"""Identification folded into a QR factor (logs of any length in bounded memory), and of many logs at once.

A log is read in chunks (:mod:`kindyngen.measured.log_formats`), each chunk preprocessed
together with ``overlap`` samples of its neighbours on either side (:func:`overlap_rows`: long
enough that the zero-phase filter's and the differences' edge effects have decayed below 1e-15
of the signal where the chunk's own samples begin), turned into regressor rows by a per-chunk
callable; with a low-pass (the default) the regressor columns, the description's declared
effect columns and the unfiltered torque then pass through the same zero-phase filter and
decimation (parallel filtering, :func:`kindyngen.measured.log_preparing.parallel_filter`), again chunk by
chunk with overlap (:class:`ChunkedParallelFilter`: chunks aligned to the decimation, so the
kept samples are exactly the whole recording's, their values equal to rounding); the kept rows
are folded into the triangular factor of the stacked regressor
(:class:`kindyngen.measured.ls_factor.LSFactor`).  Memory is the factor (O(columns^2)) plus a
few chunks, whatever the log length; the fit (ordinary or weighted least squares, or the
semidefinite program) is solved from the factor.  Validation is folded the same way: the
validation RMS of any parameters is exact from the validation factor, so one pass over the data
suffices; the validation figure shows a decimated subset of the samples.

Each file is folded on its own (:func:`fold_file`), so files run in parallel: in this process
(``workers=1``), a local process pool, or a ``dask.distributed`` client.  The per-file factors
are combined in the order the files were given (left to right), and each file's chunks in time
order, so the result is the same bit for bit for any number of workers (BLAS is held to one
thread inside a file's fold for that reason).

Each file is its own experiment, as in :func:`kindyngen.measured.identify.identify`: with a
split, the first fraction of the file's own time span trains and the rest validates, and each
side is filtered as a recording of its own (what ``identify()`` does to the parts
:func:`kindyngen.measured.log_preparing.split_time` cuts).

Streaming needs a log whose chunks preprocess like the whole: one gap-free piece, no repeated
rows, on its own clock (no ``rate_hz`` resampling).  Any other log is preprocessed whole, in
memory, with a note saying so (its parallel filtering and folding still go chunk by chunk).

Example:

>>> request = IdentificationRequest("robots/panda.yaml", ("hour.parquet",), split=0.8)  # doctest: +SKIP
>>> result = identify_streamed(request, workers=2)                                  # doctest: +SKIP
"""
from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
import yaml

from ..model.inertial_parameters import parameter_vector
from ..algorithms.effect_torques import effect_parameter_values
from ..readers.yaml_description import load_robot, parse_robot
from .consistent import identify_consistent_factor, links_from_barycentric
from .effect_columns import coulomb_eps, effect_columns, effect_names
from .estimation import IdentificationDataError
from .identify import Identification, IdentificationRequest, check_consistency
from .log_checks import log_bounds
from .log_formats import CHUNK_ROWS, joint_names_of, read_any
from .log_reading import LogError
from .log_streaming import (ChunkedParallelFilter, NotStreamable, overlap_rows, segment_chunks, segment_pieces,
                            segment_rows, time_span)
from .log_preparing import Preprocessing, Segment, preprocess
from .ls_factor import LSFactor, combine_in_order, condition_number, least_squares_factor
from .identified_model import ModelWriteError, model_yaml
from .regressor_rows import torque_regressor

#: Validation samples the figure keeps per run (every k-th sample, k a power of two).
FIGURE_SAMPLES = 4000


@dataclass(frozen=True)
class FitLimits:
    """When a fit is refused: fewer than ``min_samples_per_column`` training samples per
    regressor column (each sample gives n equations, but neighbouring samples of a 1 kHz log
    are nearly copies: 10 per column, 430 samples for the Panda's 43 base columns, is a floor,
    not a target), or a condition number of the stacked regressor above ``max_condition``
    (1e6: parameters then move by up to a million times the relative torque error).
    ``override``: fit anyway, the report saying which limit was overridden."""

    min_samples_per_column: float = 10.0
    max_condition: float = 1e6
    override: bool = False


# --------------------------------------------------------------------------- one file's fold

def regressor_rows(model, effects: tuple[str, ...]) -> Callable[[Segment], tuple[np.ndarray, np.ndarray]]:
    """The default per-chunk callable: a preprocessed piece -> (regressor rows (m, n, k): the
    rigid-body base columns then the effect columns, torques (m, n))."""
    R = torque_regressor(model)
    eps = coulomb_eps(model)

    def rows(seg: Segment):
        Y = R(seg.q, seg.qd, seg.qdd)
        if effects:
            Y = np.concatenate([Y, effect_columns(effects, seg.qd, seg.qdd, eps)], axis=2)
        return Y, seg.tau
    return rows


class _Reservoir:
    """Every ``stride``-th sample (stride doubling whenever more than 2 x ``limit`` are kept)."""

    def __init__(self, limit: int):
        self.limit, self.stride, self.seen = limit, 1, 0
        self.parts: list[tuple] = []

    def add(self, x, Y, tau, nominal):
        idx = np.flatnonzero((self.seen + np.arange(len(x))) % self.stride == 0)
        self.seen += len(x)
        self.parts.append((x[idx], Y[idx], tau[idx], nominal[idx]))
        if sum(len(p[0]) for p in self.parts) > 2 * self.limit:
            self.stride *= 2                # kept indices 0, s, 2s, ...: every other one is a multiple of 2s
            self.parts = [tuple(a[::2] for a in self.arrays())]

    def arrays(self):
        if not self.parts:
            return None
        return tuple(np.concatenate([p[i] for p in self.parts]) for i in range(4))


@dataclass(frozen=True)
class FoldTask:
    """One file's part of a run: ``role`` 'train', 'validate', or 'split' (the first ``split``
    fraction of the file's own time span trains, the rest validates)."""

    path: str
    role: str
    robot: str
    base: str | None
    tip: str | None
    snap_angles: bool
    effects: tuple[str, ...]
    settings: Preprocessing
    chunk_rows: int = CHUNK_ROWS
    #: with ``role`` 'split': the fraction of this file's own span that trains (as
    #: :func:`kindyngen.measured.identify.identify` splits each file)
    split: float | None = None
    #: ``rows_factory(model, effects)`` -> the per-chunk callable (preprocessed piece -> regressor
    #: rows, torques); a top-level function, so that Dask and process pools can send it
    rows_factory: Callable | None = None


@dataclass(frozen=True, eq=False)
class FileFold:
    """What one file contributes: the factors of its training and validation samples, per
    joint the sum of squared errors of the description's own prediction on its validation
    samples, a decimated set of validation samples for the figure ((time, Y, tau, nominal) or
    None), the preprocessing notes, chunk and sample counts and seconds spent."""

    path: str
    train: LSFactor
    validation: LSFactor
    nominal_sums: np.ndarray
    figure: tuple | None
    notes: tuple[str, ...]
    chunks: int
    samples: int
    seconds: float
    #: training samples before decimation (what the refusal limits count)
    train_samples_raw: int = 0


def fold_file(task: FoldTask, progress: Callable[[str], None] = lambda text: None) -> FileFold:
    """Read, preprocess, regress, parallel-filter and fold one file (runs in a worker for fleets)."""
    from threadpoolctl import threadpool_limits
    started = time.perf_counter()
    model = load_robot(task.robot, task.snap_angles, task.base, task.tip)
    n = model.n
    names = joint_names_of(model)
    bounds = log_bounds(model)
    folder = _Folder(task, model, started, progress)
    with threadpool_limits(1):      # the same arithmetic whatever the worker's thread count
        notes: list[str] = []
        spans: list = []
        raw_span = time_span(task.path, n, names, task.chunk_rows) if task.role == "split" else None
        try:
            parts = folder.run(segment_pieces(task.path, n, task.settings, names, task.chunk_rows, notes, spans,
                                              bounds), spans, raw_span)
        except NotStreamable as exc:
            notes = [f"preprocessed whole in memory ({exc})"]
            whole = preprocess(read_any(task.path, n, names, bounds), task.settings)
            notes += [note for s in whole for note in s.notes]
            folder = _Folder(task, model, started, progress)
            parts = folder.run(segment_chunks(whole, task.chunk_rows), [(float(whole[0].t[0]), float(whole[-1].t[-1]))],
                               raw_span)
    notes += folder.notes
    train, valid, nominal_sums, reservoir, chunks, samples, raw = parts
    if samples == 0:
        raise LogError(task.path, "t", "no samples after preprocessing")
    return FileFold(task.path, train, valid, nominal_sums, reservoir.arrays(), tuple(dict.fromkeys(notes)),
                    chunks, samples, time.perf_counter() - started, raw)


#: rows whose regressor is evaluated at once: (4096, 7, 43) doubles are 10 MB, below glibc's
#: 32 MB mmap limit, so their memory is reused rather than faulted in for every piece
REGRESSOR_ROWS = 4096


def _sub_pieces(pieces) -> Iterator[tuple[int, Segment]]:
    for index, piece in pieces:
        if len(piece.t) <= REGRESSOR_ROWS:
            yield index, piece
        else:
            for a in range(0, len(piece.t), REGRESSOR_ROWS):
                yield index, segment_rows(piece, a, a + REGRESSOR_ROWS)


class _Folder:
    """One file's pieces -> training and validation factors.  The file's samples form parts:
    each segment, and with ``role`` 'split' its training side (before the cut) and validation
    side, split as :func:`kindyngen.measured.log_preparing.split_time` splits the file; each part's
    regressor columns, the description's declared effect columns and the unfiltered torque are
    parallel-filtered as one recording (:class:`ChunkedParallelFilter`), as
    :func:`kindyngen.measured.identify.identify` filters each segment it split, and folded."""

    def __init__(self, task: FoldTask, model, started: float, progress):
        self.task, self.model, self.started, self.progress = task, model, started, progress
        n = model.n
        self.rows_of = (task.rows_factory or regressor_rows)(model, task.effects)
        regressor = torque_regressor(model)
        self.k_base = len(regressor.names)
        self.k = self.k_base + len(effect_names(task.effects, n))
        self.nominal_p = regressor.base_map @ parameter_vector(model)
        self.declared = model.effects
        self.declared_values = (np.array([float(v) for v in effect_parameter_values(model)])
                                if self.declared else None)
        self.eps = coulomb_eps(model)
        self.train, self.valid = LSFactor.empty(n, self.k), LSFactor.empty(n, self.k)
        self.nominal_sums = np.zeros(n)
        self.reservoir = _Reservoir(FIGURE_SAMPLES)
        self.chunks = self.samples = self.raw = self.read = 0
        self.valid_time = 0.0
        self.notes: list[str] = []
        self.last = time.perf_counter()

    def run(self, pieces, spans: list, raw_span):
        """Fold ``(segment index, piece)`` in time order.  ``spans``: the exact (first, last)
        time of the file's segments when known before the first piece; else (streamed) the
        span is the raw time stamps' ``raw_span`` less the trim at each end."""
        task = self.task
        part = None                # (segment index, is validation, filter or None, step after filtering)
        cut_time = None
        for index, piece in _sub_pieces(pieces):
            if task.role == "split" and cut_time is None:
                if spans:
                    start, end = spans[0]
                else:
                    trim = int(round(task.settings.effective_trim_s / piece.dt)) * piece.dt
                    start = float(piece.t[0])
                    end = start + (raw_span[1] - raw_span[0]) - 2 * trim
                cut_time = start + task.split * (end - start)
                self.notes.append(f"split on its own: samples before t = {cut_time:.6g} s (the first "
                                  f"{100 * task.split:g} % of the span {start:.6g} .. {end:.6g} s) train, the rest "
                                  f"validate")
            Y, tau = self.rows_of(piece)
            columns = np.concatenate([Y] + ([effect_columns(self.declared, piece.qd, piece.qdd, self.eps)]
                                            if self.declared else []), axis=2)
            if piece.low_pass is not None:
                tau = piece.tau_unfiltered
            if task.role == "split":
                c = int(np.searchsorted(piece.t, cut_time, side="left"))
                ranges = [(0, c, False), (c, len(piece.t), True)]
            else:
                ranges = [(0, len(piece.t), task.role == "validate")]
            for a, b, is_valid in ranges:
                if a == b:
                    continue
                if part is None or part[:2] != (index, is_valid):
                    self._finish(part)
                    lp = piece.low_pass
                    if lp is None:
                        part = (index, is_valid, None, piece.dt)
                    else:
                        filt = ChunkedParallelFilter(lp, overlap_rows(task.settings, piece.dt), task.chunk_rows)
                        part = (index, is_valid, filt, piece.dt * lp.decimate)
                        self.notes.append(f"parallel filtering: regressor and effect columns computed from the "
                                          f"filtered motion, then filtered together with the unfiltered torque "
                                          f"({lp.describe()}), in chunks of {filt.chunk} samples with "
                                          f"{filt.overlap} of overlap on each side (the filter of each part "
                                          f"whole to rounding)")
                self.read += b - a
                if not is_valid:
                    self.raw += b - a
                if part[2] is None:
                    self._fold(is_valid, columns[a:b], tau[a:b], part[3])
                else:
                    m = b - a
                    flat = np.concatenate([columns[a:b].reshape(m, -1), tau[a:b]], axis=1)
                    for out in part[2].push(flat):
                        self._fold_flat(out, is_valid, part[3])
            self._progress()
        self._finish(part)
        return (self.train, self.valid, self.nominal_sums, self.reservoir, self.chunks, self.samples,
                self.raw)

    def _finish(self, part):
        if part is not None and part[2] is not None:
            for out in part[2].finish():
                self._fold_flat(out, part[1], part[3])

    def _fold_flat(self, out, is_valid, step):
        """Fold rows of the filter: (m, n * width) columns then (m, n) torques."""
        n = self.model.n
        width = (out.shape[1] - n) // n
        self._fold(is_valid, out[:, :-n].reshape(len(out), n, width), out[:, -n:], step)

    def _fold(self, is_valid, F, tau, step):
        """Fold filtered rows: ``F`` (m, n, k + declared effects), ``tau`` (m, n)."""
        k, k_base = self.k, self.k_base
        Yf = F[:, :, :k]
        if not is_valid:
            self.train = self.train.fold(Yf, tau)
        else:
            self.valid = self.valid.fold(Yf, tau)
            nominal = Yf[:, :, :k_base] @ self.nominal_p
            if self.declared:
                nominal = nominal + F[:, :, k:] @ self.declared_values
            self.nominal_sums += np.sum((tau - nominal) ** 2, axis=0)
            x = self.valid_time + step * np.arange(len(tau))
            self.valid_time += step * len(tau)
            self.reservoir.add(x, Yf, tau, nominal)
        self.chunks += 1
        self.samples += len(tau)

    def _progress(self):
        now = time.perf_counter()
        if now - self.last > 5.0:
            self.last = now
            rate = self.read / (now - self.started)
            self.progress(f"{self.task.path}: {self.read} samples read ({rate:,.0f} samples/s), {self.samples} rows "
                          f"folded in {self.chunks} chunks (after decimation)")


def run_folds(tasks, workers: int = 1, client=None, progress: Callable[[str], None] = lambda text: None):
    """``fold_file`` of every task, in this process (``workers=1``), a process pool of ``workers``,
    or on a ``dask.distributed`` ``client``; the results in task order."""
    tasks = list(tasks)
    if client is not None:
        futures = client.map(fold_file, tasks, pure=False)
        results = []
        for task, future in zip(tasks, futures):
            results.append(future.result())
            progress(f"folded {task.path} on the Dask cluster ({results[-1].samples} samples, "
                     f"{results[-1].chunks} chunks, {results[-1].seconds:.1f} s)")
        return results
    if workers > 1 and len(tasks) > 1:
        import multiprocessing
        import signal
        from concurrent.futures import ProcessPoolExecutor
        # a Ctrl-C in the terminal reaches the workers too: they are started with SIGINT blocked (a
        # mask survives fork and exec), so they never see it and print no traceback each; this
        # process gets it when the mask is lifted, and ends them instead of waiting for their files
        pool = ProcessPoolExecutor(min(workers, len(tasks)), mp_context=multiprocessing.get_context("spawn"))
        try:
            mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            try:
                folded = pool.map(fold_file, tasks)         # the workers are started here
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
            results = []
            for task, result in zip(tasks, folded):
                results.append(result)
                progress(f"folded {task.path} ({result.samples} samples, {result.chunks} chunks, "
                         f"{result.seconds:.1f} s)")
        except BaseException:
            workers_running = list(getattr(pool, "_processes", None) or ())   # their pids (no public API before 3.14)
            pool.shutdown(wait=False, cancel_futures=True)
            for pid in workers_running:
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGTERM)
            raise
        pool.shutdown()
        return results
    results = []
    for task in tasks:
        progress(f"reading and folding {task.path}")
        results.append(fold_file(task, progress))
        r = results[-1]
        progress(f"folded {task.path}: {r.samples} samples, {r.chunks} chunks in {r.seconds:.1f} s "
                 f"({r.samples / max(r.seconds, 1e-9):,.0f} samples/s)")
    return results


# --------------------------------------------------------------------------- the whole run

def identify_streamed(request: IdentificationRequest, progress: Callable[[str], None] = lambda text: None,
                      workers: int = 1, client=None, chunk_rows: int = CHUNK_ROWS,
                      limits: FitLimits = FitLimits(), rows_factory: Callable | None = None) -> Identification:
    """:func:`kindyngen.measured.identify.identify` folded into a QR factor (same request, same
    :class:`~kindyngen.measured.identify.Identification`; the validation arrays for the figure
    are decimated to at most about 2 x FIGURE_SAMPLES samples).  ``rows_factory``: see
    :class:`FoldTask` (default :func:`regressor_rows`)."""
    model = load_robot(request.robot, request.snap_angles, request.base, request.tip)
    settings = request.preprocessing
    common = dict(robot=str(request.robot), base=request.base, tip=request.tip, snap_angles=request.snap_angles,
                  effects=tuple(request.effects), settings=settings, chunk_rows=chunk_rows,
                  rows_factory=rows_factory)
    if request.split is not None:
        # each file is its own experiment, split on its own time span (as identify() splits)
        tasks = [FoldTask(str(p), "split", split=request.split, **common) for p in request.data]
    else:
        tasks = [FoldTask(str(p), "train", **common) for p in request.data]
    tasks += [FoldTask(str(p), "validate", **common) for p in request.validate]

    started = time.perf_counter()
    folds = run_folds(tasks, workers, client, progress)
    total = sum(f.samples for f in folds)
    progress(f"{total} samples in {sum(f.chunks for f in folds)} chunks from {len(folds)} files folded in "
             f"{time.perf_counter() - started:.1f} s ({total / max(time.perf_counter() - started, 1e-9):,.0f} "
             f"samples/s)")
    train = combine_in_order([f.train for f in folds])
    valid = combine_in_order([f.validation for f in folds])
    return solve_folds(request, model, train, valid, folds, progress, limits)


def _check_fit(train: LSFactor, limits: FitLimits, raw_samples: int | None = None) -> tuple[str, ...]:
    """:func:`check_fit` of the training factor (samples counted before decimation when
    ``raw_samples`` is given: the limit is stated for samples of the log's own rate)."""
    return check_fit(train.samples if raw_samples is None else raw_samples, train.k,
                     lambda: condition_number(train), limits)


def check_fit(samples: int, columns: int, condition: Callable[[], float], limits: FitLimits) -> tuple[str, ...]:
    """Refuse (IdentificationDataError) a fit of ``columns`` unknowns on ``samples`` training
    samples below ``limits`` (``condition()``: the stacked regressor's condition number, asked
    only when the samples suffice); with ``override`` the reasons come back as notes for the
    report instead."""
    reasons = []
    per_column = samples / columns
    if per_column < limits.min_samples_per_column:
        reasons.append(f"{samples} training samples for {columns} regressor columns ({per_column:.3g} per "
                       f"column) is below the minimum of {limits.min_samples_per_column:g} per column "
                       f"(--min-samples-per-column): give more data or a larger --split")
    else:
        cond = condition()
        if cond > limits.max_condition:
            reasons.append(f"the condition number of the stacked training regressor is {cond:.3g}, above the "
                           f"limit {limits.max_condition:.3g} (--max-condition): the data do not excite every "
                           f"parameter (use an excitation trajectory, see 'kindyngen excite', or more data)")
    if reasons and not limits.override:
        raise IdentificationDataError(reasons[0] + "; --accept-poor-fit fits anyway, flagged in the report")
    return tuple(f"OVERRIDDEN REFUSAL (--accept-poor-fit): {reason}" for reason in reasons)


def solve_folds(request, model, train: LSFactor, valid: LSFactor, folds, progress,
                limits: FitLimits = FitLimits()) -> Identification:
    """The fit and its report from the combined factors (the part of :func:`identify_streamed`
    after the data are folded)."""
    n = model.n
    regressor = torque_regressor(model)
    k_base = len(regressor.names)
    enames = effect_names(request.effects, n)
    P = regressor.base_map
    prior = parameter_vector(model)
    if train.samples == 0:
        raise IdentificationDataError("no training samples")
    overridden = _check_fit(train, limits, sum(f.train_samples_raw for f in folds))
    if request.consistent:
        progress(f"solving the semidefinite program ({train.samples} samples, {10 * n + len(enames)} unknowns)")
        fit = identify_consistent_factor(train, P, enames, prior=prior)
        full, evalues = fit.full_values, fit.effect_values
        base = P @ full
        base_std = effect_std = None
        cond = condition_number(train)
        method = "physically consistent (semidefinite program, CLARABEL)"
    else:
        progress(f"least squares from the factor ({train.samples} samples, {k_base + len(enames)} columns)")
        fit = least_squares_factor(train, regressor.names + enames, weighted=request.weighted)
        base, evalues = fit.values[:k_base], fit.values[k_base:]
        base_std, effect_std = fit.std_percent[:k_base], fit.std_percent[k_base:]
        cond = fit.condition_number
        full = prior + np.linalg.pinv(P) @ (base - P @ prior)
        method = "weighted least squares" if request.weighted else "ordinary least squares"
    values = np.concatenate([base, evalues])
    rms_train = train.rms(values)
    consistent, consistency_notes = check_consistency(full, n, enames, evalues)
    consistency_notes = overridden + consistency_notes
    text = None
    if consistent:
        try:
            header = (f"Identified by KinDynGen from {', '.join(map(str, request.data))} ({method}).\n"
                      f"Geometry from {request.robot}; link parameters and joint effects identified.")
            text = model_yaml(request.robot, links_from_barycentric(full, n), dict(zip(enames, map(float, evalues))),
                              model=model, header=header, name=f"{model.name}_identified")
            parse_robot(yaml.safe_load(text), "model.yaml")
        except (ModelWriteError, ValueError) as exc:
            consistency_notes += (f"model.yaml not written: {exc}",)
            text = None
    else:
        consistency_notes += ("model.yaml not written: the identified parameters are not physical "
                              "(use --consistent)",)
    rms_val = rms_nominal = vt = vtau = vpred = vnom = None
    if valid.samples:
        rms_val = valid.rms(values)
        rms_nominal = np.sqrt(sum(f.nominal_sums for f in folds) / valid.samples)
        parts, offset = [], 0.0
        for f in folds:
            if f.figure is not None:
                x, Y, tau, nominal = f.figure
                parts.append((x + offset, Y @ values, tau, nominal))
                offset = float(x[-1] + offset) + (x[1] - x[0] if len(x) > 1 else 0.0)
        if parts:
            vt, vpred, vtau, vnom = (np.concatenate([p[i] for p in parts]) for i in range(4))
    notes = tuple(dict.fromkeys(note for f in folds for note in f.notes))
    return Identification(
        request=request, method=method, base_names=regressor.names, base_values=np.asarray(base),
        base_std_percent=base_std, effect_names=enames, effect_values=np.asarray(evalues),
        effect_std_percent=effect_std, condition_number=cond, rms_train=rms_train, rms_validation=rms_val,
        rms_validation_nominal=rms_nominal, physically_consistent=consistent,
        consistency_notes=consistency_notes, model_yaml=text,
        samples_train=int(train.samples), samples_validation=int(valid.samples),
        preprocessing_notes=notes, validation_t=vt, validation_tau=vtau, validation_predicted=vpred,
        validation_nominal=vnom)
