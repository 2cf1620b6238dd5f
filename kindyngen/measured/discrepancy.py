"""The discrepancy workflow, end to end: where a nominal model and a log disagree, which
effect is missing, the model with it, and the gap before and after on data held out.

``run_discrepancy(request, progress)`` returns a :class:`DiscrepancyResult`;
``write_outputs(result, out)`` writes ``discovery.json``, ``report.md`` with its figures, and
``model.yaml``.  The steps:

1. logs -> segments (:mod:`kindyngen.measured.log_preparing`); every file is its own experiment
   (its own clock, filtering and trimming), and the last ``holdout`` fraction of *each*
   file's time span is held out and never seen by the selection; the files are taken in the
   order of their names, so the outcome does not depend on the order they are given in;
2. on the first part, :func:`kindyngen.measured.discovery.discover` names effects (greedy,
   time-blocked cross-validation, an effective-sample-size criterion, confusable candidates
   reported rather than guessed);
3. the named effects that the robot-description schema holds (friction, offset, armature,
   payload, base tilt as gravity) are written into ``model.yaml``; ``rms_after`` is that
   model's torque error on the held-out part (so generating code from ``model.yaml`` and
   running its ``tau`` there, with the description's joint sensing applied, reproduces it);
   named effects the schema cannot hold yet (Stribeck, ripple, load-dependent friction) are
   reported, and their fitted gap too.  Every comparison is made after parallel filtering:
   predictions from the motion estimate and the unfiltered torque through the same filter.

Example:

>>> result = run_discrepancy(DiscrepancyRequest("robots/lwr4.yaml", ("log.csv",)))   # doctest: +SKIP
>>> result.discovery.effects                                                        # doctest: +SKIP
('viscous_friction',)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from ..json_text import strict_json
from ..readers.yaml_description import load_robot, parse_robot
from ..model.user_text import markdown
from .consistent import links_from_barycentric
from .discovery import (CANDIDATES, CHUNK_ROWS, EXPLAINED_FACTOR, WINDOW_ROWS, Discovery, Recording, discover,
                        in_memory, piece_windows, predict_effects, spring_torque)
from .effect_columns import EFFECTS, coulomb_eps, effect_names
from .log_checks import log_bounds
from .log_formats import joint_names_of, read_any
from .log_preparing import Preprocessing, Segment, preprocess, split_time
from .log_streaming import ChunkedParallelFilter, NotStreamable, overlap_rows, segment_pieces
from .identified_model import model_yaml
from .regressor_rows import description_torques
from .identification_report import rms_table, torque_figure

SENSING_EFFECTS = ("motor_side_elasticity", "encoder_offset", "torque_sensor_gain")
SCHEMA_EFFECTS = EFFECTS + ("payload", "base_tilt") + SENSING_EFFECTS   # what a robot description can hold
_SENSING_PREFIX = {"motor_side_elasticity": "ce", "encoder_offset": "dq", "torque_sensor_gain": "gt"}


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
    rms_before: np.ndarray            # held-out, nominal model
    rms_after: np.ndarray             # held-out, model.yaml (named effects the schema holds)
    rms_after_fit: np.ndarray         # held-out, every fitted effect (incl. stand-ins, non-schema)
    model_yaml: str | None
    not_written: tuple[str, ...]
    phases: dict                      # residual RMS per joint by motion phase (held-out, nominal)
    heldout_t: np.ndarray
    heldout_tau: np.ndarray
    heldout_nominal: np.ndarray
    heldout_after: np.ndarray
    heldout_motion: tuple             # q, qd, qdd on the held-out part
    preprocessing_notes: tuple[str, ...]
    samples: dict
    phases_fitted: dict = field(default_factory=dict)   # the same, with every fitted effect
    written_values: dict = field(default_factory=dict)  # joint coefficients written to model.yaml


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


def _model_text(request, model, d: Discovery) -> tuple[str | None, tuple[str, ...], dict]:
    """model.yaml with the named effects the schema holds, and what could not be written:
    named effects outside the schema, and a payload whose fitted inertia is not physical
    (dropped, the rest written)."""
    writable = [e for e in d.effects if e in SCHEMA_EFFECTS]
    not_written = tuple(e for e in d.effects if e not in SCHEMA_EFFECTS)
    joint_effects = [e for e in writable if e in EFFECTS]
    names = list(effect_names(joint_effects, model.n)) if joint_effects else []
    names += [f"{_SENSING_PREFIX[e]}{i + 1}" for e in writable if e in SENSING_EFFECTS for i in range(model.n)]
    # a coefficient the data does not determine is not written as a value: the joint keeps the
    # description's default (no friction, a rigid joint, an ideal sensor), and the report says why
    values = {name: d.values[name] for name in names if name not in d.undetermined}
    skipped = [f"{name} ({d.undetermined[name]})" for name in names if name in d.undetermined]
    if skipped:
        not_written += ("not determined by the data, so not written: " + "; ".join(skipped),)
    payload = None
    if "payload" in writable:
        try:
            payload = links_from_barycentric(d.payload, 1)[0]
        except ValueError as exc:
            not_written += (f"payload ({exc})",)
    gravity = d.gravity if "base_tilt" in writable else None
    header = (f"Nominal model {request.robot} with the effects KinDynGen's discrepancy workflow named "
              f"from {', '.join(map(str, request.data))}: {', '.join(d.effects) or 'none'}.")
    for with_payload in ((True, False) if payload is not None else (False,)):
        text = model_yaml(request.robot, None, values, header=header, name=f"{model.name}_discovered", model=model,
                          payload=payload if with_payload else None, gravity=gravity)
        try:
            parse_robot(yaml.safe_load(text), "model.yaml")   # the loader must take what we write
            return text, not_written, values
        except ValueError as exc:
            if with_payload:
                not_written += (f"payload: the fitted flange body is not physical ({exc.reason if hasattr(exc, 'reason') else exc})",)
                continue
            return None, not_written + (f"model.yaml refused by the loader: {exc}",), {}
    return None, not_written, {}


def measured_prediction(model, segment) -> np.ndarray:
    """What ``model`` predicts the torque sensors read along ``segment`` (N, n), unfiltered:
    its joints' sensing (``stiffness``, ``encoder_offset``, ``torque_gain``) undone on the
    logged motion (``q = q_logged - encoder_offset - tau / stiffness``, with the low-passed
    measured torque, undone of the gain, for ``tau`` and its derivatives for those of ``q``),
    then the description's torques there, times the gain."""
    q, qd, qdd = segment.q, segment.qd, segment.qdd
    joints = model.joints
    offset = np.array([float(j.encoder_offset or 0) for j in joints])
    gain = np.array([float(j.torque_gain or 1) for j in joints])
    compliance = np.array([0.0 if j.stiffness is None else 1.0 / float(j.stiffness) for j in joints])
    if np.any(compliance):
        # the spring torque: the low-passed measured torque (as discover uses), undone of the gain
        s, sd, sdd = spring_torque(segment.tau / gain, segment.dt)
        q, qd, qdd = q - compliance * s, qd - compliance * sd, qdd - compliance * sdd
    q = q - offset
    return gain * description_torques(model, q, qd, qdd)


def _heldout(model, written, d, recordings, chunk_rows=CHUNK_ROWS):
    """Per held-out recording, the measured torque and the nominal, fitted and model.yaml
    predictions through the recording's parallel filter (window by window, the chunked
    filter); stacked, with one time axis.  The filtered (decimated) rows are kept: they are
    what the figures and the motion phases show."""
    keys = ("nominal", "fitted", "after", "q", "qd", "qdd")
    out = {k: [] for k in ("t", "tau") + keys}
    start = 0.0
    n = model.n
    rigid = replace(model, joints=tuple(replace(j, friction=None, armature=None) for j in model.joints))
    for rec in recordings:
        filt, times = None, []

        def add(F, tau):
            out["tau"].append(tau)
            for k, key in enumerate(keys):
                out[key].append(F[:, :, k])
        for seg, a, context, s, e in piece_windows(rec.pieces(), min(chunk_rows, WINDOW_ROWS), 2):
            lp = seg.low_pass
            if filt is None and lp is not None:
                filt = ChunkedParallelFilter(lp, overlap_rows(Preprocessing(cutoff_hz=lp.cutoff_hz, order=lp.order),
                                                              seg.dt), chunk_rows)
            window = Segment(seg.source, context["t"], seg.dt, context["q"], context["qd"], context["qdd"],
                             context["tau"], (), context["raw"] if lp is not None else None, lp)
            i0, i1 = s - a, e - a
            nominal = measured_prediction(rigid, window)       # rigid bodies only, as discover assumes
            spring = spring_torque(window.tau, seg.dt)
            fitted = description_torques(model, window.q, window.qd, window.qdd, effects=False) + \
                predict_effects(d, model, window.q, window.qd, window.qdd, spring=spring)
            after = measured_prediction(written, window) if written is not None else nominal
            motion = np.stack([nominal, fitted, after, window.q, window.qd, window.qdd], axis=2)[i0:i1]
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
        out["t"].append(t - t[0] + start)
        start = out["t"][-1][-1] + (t[1] - t[0] if len(t) > 1 else seg.dt)
    return {k: np.concatenate(v) for k, v in out.items()}


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
    d = discover(model, train, request.candidates, request.folds, progress, eps, chunk_rows=request.chunk_rows)
    text, not_written, written_values = _model_text(request, model, d)
    written = parse_robot(yaml.safe_load(text), "model.yaml") if text is not None else None
    h = _heldout(model, written, d, heldout, request.chunk_rows)

    def rms(pred):
        return np.sqrt(np.mean((h["tau"] - pred) ** 2, axis=0))

    return DiscrepancyResult(
        request=request, discovery=d, rms_before=rms(h["nominal"]), rms_after=rms(h["after"]),
        rms_after_fit=rms(h["fitted"]), model_yaml=text, not_written=not_written,
        phases=motion_phases(h["tau"] - h["nominal"], h["qd"], h["qdd"]),
        heldout_t=h["t"], heldout_tau=h["tau"], heldout_nominal=h["nominal"], heldout_after=h["after"],
        heldout_motion=(h["q"], h["qd"], h["qdd"]),
        preprocessing_notes=tuple(dict.fromkeys(notes)),
        samples={"selection": int(d.samples), "held_out": int(len(h["tau"]))},
        phases_fitted=motion_phases(h["tau"] - h["fitted"], h["qd"], h["qdd"]), written_values=written_values)


def where_unexplained(result: DiscrepancyResult) -> tuple[str, ...]:
    """Sentences on where a residual above the stated factor x noise floor lives: from the
    selection's cross-validation (with what it correlates with) and from the held-out data
    (with the motion phase where it is largest)."""
    d = result.discovery
    out = list(d.unexplained)
    floor = d.noise_floor
    # the better of the two held-out predictions: every fitted effect (first order for the
    # sensing effects) and model.yaml (its sensing undone exactly)
    best = np.minimum(result.rms_after_fit, result.rms_after)
    for j in np.flatnonzero(best > EXPLAINED_FACTOR * floor):
        phases = {k: v[j] for k, v in result.phases_fitted.items() if math.isfinite(v[j])}
        phase = max(phases, key=phases.get) if phases else None
        out.append(f"joint {j + 1} on the held-out data: RMS {best[j]:.3g} N m with every fitted effect "
                   f"= {best[j] / max(floor[j], 1e-300):.3g} x its noise floor"
                   + (f"; largest in the phase '{phase}' ({phases[phase]:.3g} N m)" if phase else ""))
    return tuple(out)


def explained(result: DiscrepancyResult) -> bool:
    """The verdict: no joint's residual above the stated factor x its noise floor."""
    return not where_unexplained(result)


def model_values(result: DiscrepancyResult) -> dict:
    """The joint coefficients written to model.yaml (fitted jointly at the end), by name;
    ``ce`` compliances and ``gt`` gain errors as fitted (model.yaml holds 1 / ce and 1 + gt)."""
    return dict(result.written_values) if result.model_yaml is not None else {}


def _floats(values):
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, float)]


def result_document(result: DiscrepancyResult) -> dict:
    """The content of ``discovery.json`` (RMS in N m, held-out data)."""
    d = result.discovery
    steps = []
    for s in d.steps:
        steps.append({
            "effect": s.effect, "named": not s.alternatives, "indistinguishable_from": list(s.alternatives),
            "parameters": {name: {"value": float(v), "std": float(e)}
                           for name, v, e in zip(s.parameter_names, s.values, s.std)},
            "evidence": {"cv_rms_before": _floats(s.rms_before), "cv_rms_after": _floats(s.rms_after),
                         "heldout_mse_improvement": float(s.improvement),
                         "bic_eff_before": float(s.criterion_before), "bic_eff_after": float(s.criterion_after),
                         "wald": float(s.wald[0]), "wald_threshold": float(s.wald[1])},
            "note": s.note})
    return {
        "robot": str(result.request.robot), "data": [str(p) for p in result.request.data],
        "holdout_fraction": result.request.holdout, "samples": result.samples,
        "effects": list(d.effects),
        "explained": explained(result),
        "unexplained": list(where_unexplained(result)),
        "explained_rule": f"every joint's RMS with the fitted effects within {EXPLAINED_FACTOR:g} x its noise floor, "
                          f"both cross-validated on the selection data and on the held-out data (there the better "
                          f"of all fitted effects and model.yaml)",
        "rms_before": _floats(result.rms_before), "rms_after": _floats(result.rms_after),
        "rms_after_all_fitted": _floats(result.rms_after_fit),
        "steps": steps,
        "noise_floor": {"per_joint": _floats(d.noise_floor), "method": d.noise_method},
        "indistinguishable": [{"candidates": list(g), "reason": r} for g, r in d.indistinguishable],
        "not_in_model_yaml": list(result.not_written),
        "payload_mass": d.payload_mass, "gravity": None if d.gravity is None else _floats(d.gravity),
        "tilt_deg": None if d.tilt_deg is None else list(d.tilt_deg),
        "residual_by_phase": {k: [None if not math.isfinite(v) else v for v in vals]
                              for k, vals in result.phases.items()},
        "notes": list(d.notes), "preprocessing": list(result.preprocessing_notes),
        "parallel_filtering": list(d.filtering),
        "model_yaml_values": model_values(result),
        "not_determined": {name: {"fitted": d.values[name], "reason": why} for name, why in d.undetermined.items()},
    }


def _group_of(name: str, d: Discovery) -> str:
    """The fitted candidate a parameter name belongs to."""
    from .discovery import CANDIDATES as _ALL
    prefixes = {"fv": "viscous_friction", "fc": "coulomb_friction", "f0": "torque_offset", "Ia": "armature",
                "fs": "stribeck_friction", "rs": "position_ripple", "rc": "position_ripple",
                "fl": "load_dependent_friction", "ce": "motor_side_elasticity", "dq": "encoder_offset",
                "gt": "torque_sensor_gain", "dg": "base_tilt", "pa": "payload"}
    effect = prefixes.get(name[:2], "")
    return effect if effect in _ALL else ""


def _diagnostic_figure(path: Path, result: DiscrepancyResult) -> Path:
    """Nominal residual per joint against time, position, velocity and acceleration."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    q, qd, qdd = result.heldout_motion
    r = result.heldout_tau - result.heldout_nominal
    n = r.shape[1]
    fig, axes = plt.subplots(n, 4, figsize=(14, 1.8 * n), squeeze=False)
    for j in range(n):
        for k, (x, label) in enumerate(((result.heldout_t, "t [s]"), (q[:, j], "q [rad]"),
                                        (qd[:, j], "qd [rad/s]"), (qdd[:, j], "qdd [rad/s^2]"))):
            ax = axes[j][k]
            ax.plot(x, r[:, j], "." if k else "-", ms=1, lw=0.6, color="C3")
            ax.axhline(0, color="grey", lw=0.5)
            if j == n - 1:
                ax.set_xlabel(label)
            if k == 0:
                ax.set_ylabel(f"r{j + 1} [N m]")
    axes[0][0].set_title("residual of the nominal model (held-out data) against time, q, qd, qdd", loc="left",
                         fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def _gap_figure(path: Path, result: DiscrepancyResult) -> Path:
    """Held-out RMS per joint: nominal, after each step (cross-validated), final model.yaml."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = result.discovery
    bars = [("nominal (held out)", result.rms_before)]
    bars += [(f"+ {s.effect}{' (stand-in, not named)' if s.alternatives else ''} (CV)", s.rms_after)
             for s in d.steps]
    bars.append(("model.yaml (held out)", result.rms_after))
    n = len(result.rms_before)
    width = 0.8 / len(bars)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for k, (label, values) in enumerate(bars):
        ax.bar(np.arange(n) + k * width, values, width, label=label)
    ax.plot(np.arange(n) + 0.4 - width / 2, d.noise_floor, "k_", ms=18, mew=2, label="noise floor")
    ax.set_xticks(np.arange(n) + 0.4 - width / 2, [f"joint {j + 1}" for j in range(n)])
    ax.set_ylabel("RMS torque error [N m]")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_outputs(result: DiscrepancyResult, out: str | Path) -> Path:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = result_document(result)
    (out / "discovery.json").write_text(strict_json(doc, indent=1) + "\n")
    if result.model_yaml is not None:
        (out / "model.yaml").write_text(result.model_yaml)
    d = result.discovery
    n = len(result.rms_before)
    diag = _diagnostic_figure(out / "residuals.png", result)
    gap = _gap_figure(out / "gap.png", result)
    torques = torque_figure(out / "heldout_torques.png", result.heldout_t, result.heldout_tau,
                            {"model.yaml": result.heldout_after, "nominal": result.heldout_nominal},
                            "held-out data: measured torques, nominal model and model.yaml")
    # the description's and the logs' names (and the preprocessing notes naming a log's keys) are
    # the user's: literal Markdown text
    lines = [f"# Discrepancy between {markdown(Path(result.request.robot).name)} and the data", "",
             f"Data: {', '.join(markdown(str(path)) for path in result.request.data)}; the last {100 * result.request.holdout:g} % of the "
             f"time span is held out ({result.samples['held_out']} samples); the selection saw "
             f"{result.samples['selection']} samples ({d.folds}-fold time-blocked cross-validation).", "",
             "Preprocessing: " + "; ".join(map(markdown, result.preprocessing_notes)) + ".", "",
             "Parallel filtering: every model column (rigid-body torques, effect columns) is computed from the "
             "filtered motion, then the columns and the *unfiltered* torque pass through the same linear filter "
             "and decimation: " + ("; ".join(d.filtering) if d.filtering else "none (the data as given)") + ".", "",
             "## Where model and measurement disagree", "",
             rms_table({"nominal, held out": list(result.rms_before), "noise floor": list(d.noise_floor)}, n), "",
             f"Noise floor: {d.noise_method}." + (
                 f" The torques were low-pass filtered at {result.request.preprocessing.cutoff_hz:g} Hz before this, "
                 f"so the estimate sees only what passed the filter: read it as a lower bound; the selection's "
                 f"stop then rests on the cross-validation and criterion rules."
                 if result.request.preprocessing.cutoff_hz is not None else ""), "",
             "Residual of the nominal model by motion phase (RMS, N m, held out):", "",
             rms_table({k: [0.0 if not math.isfinite(v) else v for v in vals] for k, vals in result.phases.items()},
                       n), "",
             f"![residuals]({diag.name})", "",
             "## Which effect is missing", ""]
    verdict = explained(result)
    if d.effects:
        lines.append(f"Named, in order: **{', '.join(d.effects)}**.")
    else:
        lines.append("Named: none.")
    if verdict:
        lines.append(f"Verdict: **explained**: every joint's held-out RMS with the fitted effects is within "
                     f"{EXPLAINED_FACTOR:g} x its noise floor.")
    else:
        lines += [f"Verdict: **not explained**: the residual left stays above {EXPLAINED_FACTOR:g} x the noise "
                  f"floor (an effect outside the candidate library, or a wrong nominal model):", ""]
        lines += [f"- {w}" for w in where_unexplained(result)]
        lines.append("")
    for group, reason in d.indistinguishable:
        lines.append(f"- Cannot tell apart on this data: {', '.join(group)} ({reason}).")
    lines += ["", "| step | effect | CV held-out MSE fall | BIC_eff change | Wald (threshold) | note |",
              "|---|---|---|---|---|---|"]
    for k, s in enumerate(d.steps, start=1):
        lines.append(f"| {k} | {s.effect}{' (not named)' if s.alternatives else ''} | {100 * s.improvement:.3g} % | "
                     f"{s.criterion_after - s.criterion_before:.4g} | {s.wald[0]:.4g} ({s.wald[1]:.3g}) | {s.note} |")
    lines += ["", "### The final joint fit (the values in model.yaml)", "",
              "Every fitted effect together, fitted once more at the end (value +- std):", ""]
    final_names = {}
    for name in d.values:
        final_names.setdefault(_group_of(name, d), []).append(name)
    for effect in d.fitted:
        shown = ", ".join(f"{nm} **not determined**" if nm in d.undetermined else
                          f"{nm} = {d.values[nm]:.4g} +- {d.std[nm]:.2g}" for nm in final_names.get(effect, []))
        where = "in model.yaml" if effect in d.effects and effect in SCHEMA_EFFECTS else \
            ("not named" if effect not in d.effects else "not in model.yaml (the schema cannot hold it)")
        lines.append(f"- {effect} ({where}): {shown}")
    if d.undetermined:
        lines += ["", "Not determined by the data (not written to model.yaml; the joint keeps the description's "
                  "default):", ""]
        lines += [f"- {nm} (fitted {d.values[nm]:.4g}, not a measurement): {why}" for nm, why in d.undetermined.items()]
    lines += ["", "### Each step's own fit (as fitted at that step, beside the effects chosen before it only)", ""]
    for k, s in enumerate(d.steps, start=1):
        shown = ", ".join(f"{nm} = {v:.4g} +- {e:.2g}" for nm, v, e in zip(s.parameter_names, s.values, s.std))
        lines.append(f"- step {k}, {s.effect}{' (not named)' if s.alternatives else ''}: {shown}")
    if d.payload_mass is not None and "payload" in d.effects:
        lines.append(f"- payload mass {d.payload_mass:.4g} kg")
    if d.tilt_deg is not None and "base_tilt" in d.effects:
        lines.append(f"- base tilt: roll {d.tilt_deg[0]:.3g} deg, pitch {d.tilt_deg[1]:.3g} deg")
    lines += ["", "## The gap shrinks", "",
              rms_table({"nominal, held out": list(result.rms_before), "model.yaml, held out": list(result.rms_after),
                         "all fitted effects, held out": list(result.rms_after_fit)}, n), "",
              f"![gap]({gap.name})", "", f"![held-out torques]({torques.name})", ""]
    if result.not_written:
        lines.append("Not in model.yaml (the description schema cannot hold them yet, or they are not physical): "
                     + "; ".join(result.not_written) + ".")
    lines += [f"- {note}" for note in d.notes]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return out
