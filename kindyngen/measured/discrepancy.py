"""The discrepancy workflow, end to end: where a nominal model and a log disagree, which
effect is missing, the model with it, and the gap before and after on data held out.

``run_discrepancy(request, progress)`` returns a :class:`DiscrepancyResult`;
``write_outputs(result, out)`` writes ``discovery.json``, ``model.yaml``, ``report.md`` and
``report.html`` with their figures (:mod:`kindyngen.measured.discovery_report`).  The steps:

1. logs -> segments (:mod:`kindyngen.measured.log_preparing`); every file is its own experiment
   (its own clock, filtering and trimming), and the last ``holdout`` fraction of *each*
   file's time span is held out and never seen by the selection; the files are taken in the
   order of their names, so the outcome does not depend on the order they are given in;
2. on the first part, :func:`kindyngen.measured.discovery.discover` names effects and fits the
   model that holds them (every candidate is storable: model.yaml holds what was fitted);
3. ``rms_after`` is model.yaml's torque error on the held-out part: its reading
   (:func:`kindyngen.measured.measurement_model.reading`: the measurement effects undone on the
   logged motion, the joint effects on the torque), through the same parallel filter as the
   measured torque.  Code generated from model.yaml reproduces it.

Example:

>>> result = run_discrepancy(DiscrepancyRequest("robots/lwr4.yaml", ("log.csv",)))   # doctest: +SKIP
>>> result.discovery.effects                                                        # doctest: +SKIP
('viscous_friction',)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..json_text import strict_json
from ..readers.yaml_description import load_robot
from .discovery import CANDIDATES, EXPLAINED_FACTOR, Discovery, discover
from .discovery_data import (CHUNK_ROWS, WINDOW_ROWS, Recording, _smoothing, _spring, edge_rows, in_memory,
                             piece_windows)
from .effect_columns import coulomb_eps
from .log_checks import log_bounds
from .log_formats import joint_names_of, read_any
from .log_preparing import Preprocessing, Segment, preprocess, split_time
from .log_streaming import ChunkedParallelFilter, NotStreamable, overlap_rows, segment_pieces
from .measurement_model import RigidBodies, description_data, point_of, reading
from .regressor_rows import rigid_body_model


@dataclass(frozen=True)
class DiscrepancyRequest:
    robot: str | Path
    data: tuple[str | Path, ...]
    holdout: float = 0.3
    candidates: tuple[str, ...] = CANDIDATES
    folds: int = 5
    preprocessing: Preprocessing = field(default_factory=Preprocessing)
    base: str | None = None          # a URDF's chain: first and last link (kindyngen.readers.urdf)
    tip: str | None = None
    snap_angles: bool = True
    #: samples per chunk of the streamed reading and of the data passes (the result does not
    #: depend on it, to rounding)
    chunk_rows: int = CHUNK_ROWS


@dataclass(frozen=True, eq=False)
class DiscrepancyResult:
    request: DiscrepancyRequest
    discovery: Discovery
    rms_before: np.ndarray            # held-out data, nominal model
    rms_after: np.ndarray             # held-out data, model.yaml (the fitted model)
    model_yaml: str
    phases: dict                      # residual RMS per joint by motion phase (held-out, nominal)
    phases_after: dict                # the same with model.yaml
    heldout_t: np.ndarray
    heldout_tau: np.ndarray
    heldout_nominal: np.ndarray
    heldout_after: np.ndarray
    heldout_motion: tuple             # q, qd, qdd on the held-out part (filtered, decimated)
    preprocessing_notes: tuple[str, ...]
    samples: dict


def motion_phases(residual, qd, qdd, slow: float = 0.05) -> dict:
    """Residual RMS per joint (N m) in the phases of each joint's own motion: nearly at rest
    (``|qd| < slow`` rad/s), moving forwards, moving backwards, and the quarter of samples with
    the largest ``|qdd|``: where the gap lives says which effect to suspect.

    >>> motion_phases(np.ones((4, 1)), np.array([[0.0], [1.0], [-1.0], [1.0]]), np.zeros((4, 1)))["at rest"]
    [1.0]
    """
    out = {}
    big = np.abs(qdd) >= np.quantile(np.abs(qdd), 0.75, axis=0)
    masks = {"at rest": np.abs(qd) < slow, "moving +": qd >= slow, "moving -": qd <= -slow,
             "largest |qdd| (top 25 %)": big}
    for label, mask in masks.items():
        out[label] = [float(np.sqrt(np.mean(residual[mask[:, j], j] ** 2))) if mask[:, j].any() else float("nan")
                      for j in range(residual.shape[1])]
    return out


def model_text(request: DiscrepancyRequest, model, d: Discovery) -> str:
    """model.yaml: the nominal description with every coefficient of the final fit, in the
    units the schema defines (the same numbers as ``d.model``)."""
    nominal = rigid_body_model(model)
    stand = "; ".join(f"{k} stands in for {', '.join(v)}" for k, v in d.stand_ins.items())
    header = (f"Nominal model {request.robot} with the effects KinDynGen's discrepancy workflow fitted from "
              f"{', '.join(map(str, request.data))}: named {', '.join(d.effects) or 'none'}"
              + (f"; {stand} (the data cannot tell them apart)" if stand else "") + ".")
    from dataclasses import replace
    return description_data(replace(nominal, coulomb_smoothing=model.coulomb_smoothing), request.robot, d.values,
                            header=header, name=f"{model.name}_discovered")


def heldout_predictions(nominal, written, recordings, chunk_rows=CHUNK_ROWS) -> dict:
    """Per held-out recording, the measured torque and the nominal and written models' readings
    through the recording's parallel filter (window by window, the chunked filter), the rows at
    its ends left out as the selection leaves them out (:func:`discovery_data.edge_rows`);
    stacked, with one time axis."""
    keys = ("nominal", "after", "q", "qd", "qdd")
    out = {k: [] for k in ("t", "tau") + keys}
    start = 0.0
    n = nominal.n
    rigid = RigidBodies(nominal)
    p0, p1 = point_of(nominal), point_of(written)
    for rec in recordings:
        filt, times = None, []
        parts = len(out["tau"])          # this recording's arrays start here

        def add(F, tau):
            out["tau"].append(tau)
            for k, key in enumerate(keys):
                out[key].append(F[:, :, k])
        first = next(iter(rec.pieces()), None)
        if first is None:
            continue
        smoothing, halo = _smoothing(rec.rows, first.dt, first.low_pass)
        for seg, a, context, s, e in piece_windows(rec.pieces(), min(chunk_rows, WINDOW_ROWS), max(halo, 2)):
            lp = seg.low_pass
            if filt is None and lp is not None:
                filt = ChunkedParallelFilter(lp, overlap_rows(Preprocessing(cutoff_hz=lp.cutoff_hz, order=lp.order),
                                                              seg.dt), chunk_rows)
            i0, i1 = s - a, e - a
            q, qd, qdd = context["q"][i0:i1], context["qd"][i0:i1], context["qdd"][i0:i1]
            spring = _spring(context, seg.dt, i0, i1, smoothing)
            motion = np.stack([reading(p0, rigid, q, qd, qdd), reading(p1, rigid, q, qd, qdd, spring), q, qd, qdd],
                              axis=2)
            rows = np.arange(s, e)
            step = 1 if lp is None else lp.decimate
            times.append(context["t"][i0:i1][rows % step == 0])
            if filt is None:
                add(motion, context["tau"][i0:i1])
            else:
                m = i1 - i0
                for F in filt.push(np.concatenate([motion.reshape(m, -1), context["raw"][i0:i1]], axis=1)):
                    add(F[:, :-n].reshape(len(F), n, -1), F[:, -n:])
        if filt is not None:
            for F in filt.finish():
                add(F[:, :-n].reshape(len(F), n, -1), F[:, -n:])
        if not times:
            continue
        t = np.concatenate(times)
        edge = edge_rows(first.low_pass, len(t))
        if edge:
            for key in ("tau",) + keys:
                whole = np.concatenate(out[key][parts:])
                del out[key][parts:]
                out[key].append(whole[edge:len(whole) - edge])
            t = t[edge:len(t) - edge]
        out["t"].append(t - t[0] + start)
        start = out["t"][-1][-1] + (t[1] - t[0] if len(t) > 1 else first.dt)
    return {k: np.concatenate(v) if v else np.zeros((0, n)) for k, v in out.items()}


def _rows(seg: Segment, a: int, b: int) -> Segment:
    """Rows ``a:b`` of a piece, with its unfiltered torque and low-pass."""
    unfiltered = None if seg.tau_unfiltered is None else seg.tau_unfiltered[a:b]
    return Segment(seg.source, seg.t[a:b], seg.dt, seg.q[a:b], seg.qd[a:b], seg.qdd[a:b], seg.tau[a:b], (),
                   unfiltered, seg.low_pass)


def _part(path, model, settings, k0: int, k1: int, chunk_rows: int):
    """Rows ``[k0, k1)`` of the (single) segment of a streamed log, piece by piece (each pass
    checks the samples against the robot again: the file may have changed since the first)."""
    bounds = log_bounds(model)

    def pieces():
        row = 0
        for _, piece in segment_pieces(path, model.n, settings, joint_names_of(model), chunk_rows, bounds=bounds):
            m = len(piece.t)
            a, b = max(k0 - row, 0), min(k1 - row, m)
            if a < b:
                yield piece if (a, b) == (0, m) else _rows(piece, a, b)
            row += m
            if row >= k1:
                return
    return Recording(k1 - k0, pieces)


def _file_parts(path, model, request, progress):
    """(training recordings, held-out recordings, preprocessing notes) of one log: the last
    ``holdout`` fraction of its own time span held out (as
    :func:`kindyngen.measured.log_preparing.split_time` cuts).  A log whose chunks preprocess
    like the whole is streamed (a first pass reads its time stamps); any other log (gaps,
    repeated rows, ``--rate`` resampling, or short) is preprocessed whole in memory.  Every
    sample is checked against the robot as it is read (:mod:`kindyngen.measured.log_checks`)."""
    settings = request.preprocessing
    bounds = log_bounds(model)
    notes, spans, times = [], [], []
    try:
        for index, piece in segment_pieces(path, model.n, settings, joint_names_of(model), request.chunk_rows,
                                           notes=notes, spans=spans, bounds=bounds):
            if spans:                          # preprocessed whole anyway (short, or resampled)
                break
            times.append(piece.t)
    except NotStreamable as exc:
        notes, spans = [f"preprocessed whole in memory ({exc})"], [None]
    if spans:
        segments = preprocess(read_any(path, model.n, joint_names_of(model), bounds), settings)
        notes = [note for note in notes if note.startswith("preprocessed whole")] + \
            [note for s in segments for note in s.notes]
        a, b = split_time(segments, 1.0 - request.holdout)
        return in_memory(a), in_memory(b), notes
    t = np.concatenate(times)
    start, end = float(t[0]), float(t[-1])
    cut = int(np.searchsorted(t, start + (1.0 - request.holdout) * (end - start), side="left"))
    progress(f"{path}: {len(t)} samples, streamed (the first {cut} select, the rest is held out)")
    train = (_part(path, model, settings, 0, cut, request.chunk_rows),) if cut > 0 else ()
    held = (_part(path, model, settings, cut, len(t), request.chunk_rows),) if cut < len(t) else ()
    return train, held, notes


def run_discrepancy(request: DiscrepancyRequest,
                    progress: Callable[[str], None] = lambda text: None) -> DiscrepancyResult:
    model = load_robot(request.robot, request.snap_angles, request.base, request.tip)
    train, heldout, notes = [], [], []
    # each file its own experiment, held-out part taken from each; in the order of the names
    for path in sorted(request.data, key=str):
        progress(f"reading {path}")
        a, b, file_notes = _file_parts(path, model, request, progress)
        notes += file_notes
        train += a
        heldout += b
    eps = coulomb_eps(model)
    d = discover(model, train, request.candidates, request.folds, progress, eps, chunk_rows=request.chunk_rows,
                 source=request.robot)
    text = model_text(request, model, d)
    progress("the held-out part: nominal model and model.yaml (a pass over the data)")
    from dataclasses import replace
    nominal = replace(rigid_body_model(model), coulomb_smoothing=model.coulomb_smoothing)
    h = heldout_predictions(nominal, d.model, heldout, request.chunk_rows)

    def rms(pred):
        return np.sqrt(np.mean((h["tau"] - pred) ** 2, axis=0)) if len(pred) else np.full(model.n, math.nan)

    return DiscrepancyResult(
        request=request, discovery=d, rms_before=rms(h["nominal"]), rms_after=rms(h["after"]), model_yaml=text,
        phases=motion_phases(h["tau"] - h["nominal"], h["qd"], h["qdd"]),
        phases_after=motion_phases(h["tau"] - h["after"], h["qd"], h["qdd"]),
        heldout_t=h["t"], heldout_tau=h["tau"], heldout_nominal=h["nominal"], heldout_after=h["after"],
        heldout_motion=(h["q"], h["qd"], h["qdd"]), preprocessing_notes=tuple(dict.fromkeys(notes)),
        samples={"selection": int(d.samples), "held_out": int(len(h["tau"]))})


#: model.yaml's held-out RMS above this times the nominal's on a joint (and above the verdict's
#: factor x the noise floor: not a difference within the noise) is reported as worse
WORSE_FACTOR = 1.05


def where_unexplained(result: DiscrepancyResult) -> tuple[str, ...]:
    """Sentences on where a residual above the stated factor x noise floor lives: from the
    selection's cross-validation (with what it correlates with) and from the held-out data
    (with the motion phase where it is largest)."""
    d = result.discovery
    out = list(d.unexplained)
    floor = d.noise_floor
    for j in np.flatnonzero(result.rms_after > EXPLAINED_FACTOR * floor):
        phases = {k: v[j] for k, v in result.phases_after.items() if math.isfinite(v[j])}
        phase = max(phases, key=phases.get) if phases else None
        out.append(f"joint {j + 1} on the held-out data: RMS {result.rms_after[j]:.3g} N m with model.yaml "
                   f"= {result.rms_after[j] / max(floor[j], 1e-300):.3g} x its noise floor"
                   + (f"; largest in the phase '{phase}' ({phases[phase]:.3g} N m)" if phase else ""))
    worse = (result.rms_after > WORSE_FACTOR * result.rms_before) & (result.rms_after > EXPLAINED_FACTOR * floor)
    for j in np.flatnonzero(worse):
        # the fit was judged on the selection: said loudly where it does not carry over
        out.append(f"joint {j + 1}: model.yaml is worse than the nominal model on the held-out data "
                   f"({result.rms_after[j]:.3g} against {result.rms_before[j]:.3g} N m): what was fitted does not "
                   f"carry over beyond the selection; do not use this model.yaml for that joint")
    return tuple(out)


def explained(result: DiscrepancyResult) -> bool:
    """The verdict: no joint's residual above the stated factor x its noise floor."""
    return not where_unexplained(result)


def _floats(values):
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, float)]


def per_joint(d: Discovery) -> dict:
    """Per fitted candidate, its coefficients in model.yaml per joint in the units the schema
    defines (None where model.yaml holds nothing for that joint), or the whole-body values."""
    n, v, out = d.model.n, d.values, {}

    def joint(name, i):
        return v.get(f"{name}{i + 1}")
    for c in d.fitted:
        if c in ("viscous_friction", "coulomb_friction", "torque_offset", "armature", "load_dependent_friction",
                 "encoder_offset"):
            prefix = {"viscous_friction": "fv", "coulomb_friction": "fc", "torque_offset": "f0", "armature": "Ia",
                      "load_dependent_friction": "fl", "encoder_offset": "dq"}[c]
            out[c] = [joint(prefix, i) for i in range(n)]
        elif c == "stribeck_friction":
            out[c] = [None if joint("fs", i) is None else {"stribeck": joint("fs", i),
                                                           "stribeck_velocity": joint("vs", i)} for i in range(n)]
        elif c == "position_ripple":
            out[c] = [None if joint("rs", i) is None and joint("rc", i) is None else
                      {"sin": joint("rs", i) or 0.0, "cos": joint("rc", i) or 0.0, "order": joint("rk", i)}
                      for i in range(n)]
        elif c == "motor_side_elasticity":
            out[c] = [None if not joint("ce", i) else {"stiffness": 1.0 / joint("ce", i)} for i in range(n)]
        elif c == "torque_sensor_gain":
            out[c] = [None if joint("gt", i) is None else {"torque_gain": 1.0 + joint("gt", i)} for i in range(n)]
        elif c == "payload":
            p = d.model.payload
            out[c] = None if p is None else {"mass": float(p.mass), "com": [float(x) for x in p.com],
                                             "inertia": [float(x) for x in p.inertia]}
        elif c == "base_tilt":
            out[c] = {"gravity": _floats(d.gravity), "tilt_deg": list(d.tilt_deg)}
        elif c == "rigid_bodies":
            out[c] = {"links": [{"mass": float(l.mass), "com": [float(x) for x in l.com],
                                 "inertia": [float(x) for x in l.inertia]} for l in d.model.links]}
    return out


def result_document(result: DiscrepancyResult) -> dict:
    """The content of ``discovery.json`` (RMS in N m; see docs/discovery.md, Outputs)."""
    d = result.discovery
    steps = []
    for s in d.steps:
        steps.append({
            "effect": s.effect, "detail": s.detail, "kept": s.kept,
            "parameters": {name: float(v) for name, v in zip(s.parameter_names, s.values)},
            "cv_rms_before": _floats(s.rms_before), "cv_rms_after": _floats(s.rms_after),
            "heldout_mse_improvement": float(s.improvement), "note": s.note})
    coefficients = {k: (int(v) if k.startswith("rk") else float(v)) for k, v in d.values.items()
                    if not k.startswith(("d_", "db_"))}
    return {
        "schema": "kindyngen.discovery/2",
        "robot": str(result.request.robot), "data": [str(p) for p in result.request.data],
        "holdout_fraction": result.request.holdout, "samples": result.samples,
        "candidates": list(d.candidates),
        "effects": list(d.effects),
        "stand_ins": {k: list(v) for k, v in d.stand_ins.items()},
        "fitted": list(d.fitted),
        "explained": explained(result),
        "unexplained": list(where_unexplained(result)),
        "rules": dict(d.rules),
        "rms_before": _floats(result.rms_before), "rms_after": _floats(result.rms_after),
        "cv_rms_before": _floats(d.rms_before), "cv_rms_after": _floats(d.rms_after),
        "noise_floor": {"per_joint": _floats(d.noise_floor), "method": d.noise_method},
        "per_joint": per_joint(d),
        "coefficients": coefficients,
        "std": {k: (float(v) if math.isfinite(v) else None) for k, v in d.std.items()},
        "not_determined": {name: {"fitted": d.fitted_values.get(name), "reason": why}
                           for name, why in d.undetermined.items()},
        "drift": {name: {"by_time_block": _floats(v), "std_by_time_block": _floats(e), "where": text}
                  for name, (v, e, text) in d.drift.items()},
        "steps": steps,
        "indistinguishable": [{"candidates": list(g), "reason": r} for g, r in d.indistinguishable],
        "payload_mass": d.payload_mass, "gravity": None if d.gravity is None else _floats(d.gravity),
        "tilt_deg": None if d.tilt_deg is None else list(d.tilt_deg),
        "residual_by_phase": {k: [None if not math.isfinite(v) else v for v in vals]
                              for k, vals in result.phases.items()},
        "residual_by_phase_after": {k: [None if not math.isfinite(v) else v for v in vals]
                                    for k, vals in result.phases_after.items()},
        "notes": list(d.notes), "preprocessing": list(result.preprocessing_notes),
        "parallel_filtering": list(d.filtering),
    }


def write_outputs(result: DiscrepancyResult, out: str | Path) -> Path:
    """discovery.json, model.yaml, report.md, report.html and the figures into ``out``."""
    from .discovery_report import write_reports
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = result_document(result)
    (out / "discovery.json").write_text(strict_json(doc, indent=1) + "\n")
    if result.model_yaml is not None:
        (out / "model.yaml").write_text(result.model_yaml)
    write_reports(result, doc, out)
    return out
