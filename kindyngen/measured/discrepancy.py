"""The discrepancy workflow, end to end: where a nominal model and a log disagree, which
effect is missing, the model with it, and the gap before and after on data held out.

``run_discrepancy(request, progress)`` returns a :class:`DiscrepancyResult`;
``write_outputs(result, out)`` writes ``discovery.json``, ``report.md`` with its figures, and
``model.yaml``.  The steps:

1. logs -> segments (:mod:`kindyngen.measured.logs`); the last ``holdout`` fraction of the
   time span is held out and never seen by the selection;
2. on the first part, :func:`kindyngen.measured.discovery.discover` names effects (greedy,
   time-blocked cross-validation, an effective-sample-size criterion, confusable candidates
   reported rather than guessed);
3. the named effects that the robot-description schema holds (friction, offset, armature,
   payload, base tilt as gravity) are written into ``model.yaml``; ``rms_after`` is that
   model's torque error on the held-out part (so generating code from ``model.yaml`` and
   running its ``tau`` there reproduces it); named effects the schema cannot hold yet
   (Stribeck, ripple, load-dependent friction) are reported, and their fitted gap too.

Example:

>>> result = run_discrepancy(DiscrepancyRequest("robots/lwr4.yaml", ("log.csv",)))   # doctest: +SKIP
>>> result.discovery.effects                                                        # doctest: +SKIP
('viscous_friction',)
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from ..robot import load_robot, parse_robot
from .consistent import links_from_barycentric
from .discovery import CANDIDATES, Discovery, discover, nominal_torques, predict_effects
from .effects import EFFECTS, coulomb_eps, effect_names
from .logs import Preprocessing, concatenate_rows, load_segments, split_time, timeline
from .model_writer import model_yaml
from .regressor_rows import description_torques
from .report import rms_table, torque_figure

SCHEMA_EFFECTS = EFFECTS + ("payload", "base_tilt")   # what a robot description can hold


@dataclass(frozen=True)
class DiscrepancyRequest:
    robot: str | Path
    data: tuple[str | Path, ...]
    holdout: float = 0.3
    candidates: tuple[str, ...] = CANDIDATES
    folds: int = 5
    preprocessing: Preprocessing = field(default_factory=Preprocessing)
    base: str | None = None          # a URDF's chain: first and last link (kindyngen.urdf)
    tip: str | None = None
    snap_angles: bool = True


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


def _model_text(request, model, d: Discovery) -> tuple[str | None, tuple[str, ...]]:
    """model.yaml with the named effects the schema holds, and what could not be written:
    named effects outside the schema, and a payload whose fitted inertia is not physical
    (dropped, the rest written)."""
    writable = [e for e in d.effects if e in SCHEMA_EFFECTS]
    not_written = tuple(e for e in d.effects if e not in SCHEMA_EFFECTS)
    joint_effects = [e for e in writable if e in EFFECTS]
    values = {name: d.values[name] for name in effect_names(joint_effects, model.n)} if joint_effects else {}
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
            return text, not_written
        except ValueError as exc:
            if with_payload:
                not_written += (f"payload: the fitted flange body is not physical ({exc.reason if hasattr(exc, 'reason') else exc})",)
                continue
            return None, not_written + (f"model.yaml refused by the loader: {exc}",)
    return None, not_written


def run_discrepancy(request: DiscrepancyRequest,
                    progress: Callable[[str], None] = lambda text: None) -> DiscrepancyResult:
    model = load_robot(request.robot, request.snap_angles, request.base, request.tip)
    segments = []
    for path in request.data:
        progress(f"reading {path}")
        segments.extend(load_segments(path, model.n, request.preprocessing))
    train, heldout = split_time(segments, 1.0 - request.holdout)
    eps = coulomb_eps(model)
    d = discover(model, train, request.candidates, request.folds, progress, eps)
    q, qd, qdd, tau = concatenate_rows(heldout)
    nominal = nominal_torques(model, q, qd, qdd)
    fitted = nominal + predict_effects(d, model, q, qd, qdd)
    text, not_written = _model_text(request, model, d)
    # the written description's own prediction: what code generated from model.yaml computes
    after = (description_torques(parse_robot(yaml.safe_load(text), "model.yaml"), q, qd, qdd)
             if text is not None else nominal)

    def rms(pred):
        return np.sqrt(np.mean((tau - pred) ** 2, axis=0))

    return DiscrepancyResult(
        request=request, discovery=d, rms_before=rms(nominal), rms_after=rms(after), rms_after_fit=rms(fitted),
        model_yaml=text, not_written=not_written, phases=motion_phases(tau - nominal, qd, qdd),
        heldout_t=timeline(heldout), heldout_tau=tau, heldout_nominal=nominal, heldout_after=after,
        heldout_motion=(q, qd, qdd),
        preprocessing_notes=tuple(dict.fromkeys(n for s in segments for n in s.notes)),
        samples={"selection": int(d.samples), "held_out": int(len(q))})


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
    }


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
    (out / "discovery.json").write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    if result.model_yaml is not None:
        (out / "model.yaml").write_text(result.model_yaml)
    d = result.discovery
    n = len(result.rms_before)
    diag = _diagnostic_figure(out / "residuals.png", result)
    gap = _gap_figure(out / "gap.png", result)
    torques = torque_figure(out / "heldout_torques.png", result.heldout_t, result.heldout_tau,
                            {"model.yaml": result.heldout_after, "nominal": result.heldout_nominal},
                            "held-out data: measured torques, nominal model and model.yaml")
    lines = [f"# Discrepancy between {Path(result.request.robot).name} and the data", "",
             f"Data: {', '.join(map(str, result.request.data))}; the last {100 * result.request.holdout:g} % of the "
             f"time span is held out ({result.samples['held_out']} samples); the selection saw "
             f"{result.samples['selection']} samples ({d.folds}-fold time-blocked cross-validation).", "",
             "Preprocessing: " + "; ".join(result.preprocessing_notes) + ".", "",
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
    if d.effects:
        lines.append(f"Named, in order: **{', '.join(d.effects)}**.")
    else:
        lines.append("Named: none (the data is explained within the stated rules).")
    for group, reason in d.indistinguishable:
        lines.append(f"- Cannot tell apart on this data: {', '.join(group)} ({reason}).")
    lines += ["", "| step | effect | CV held-out MSE fall | BIC_eff change | Wald (threshold) | note |",
              "|---|---|---|---|---|---|"]
    for k, s in enumerate(d.steps, start=1):
        lines.append(f"| {k} | {s.effect}{' (not named)' if s.alternatives else ''} | {100 * s.improvement:.3g} % | "
                     f"{s.criterion_after - s.criterion_before:.4g} | {s.wald[0]:.4g} ({s.wald[1]:.3g}) | {s.note} |")
    lines += ["", "Parameters of the named effects (value +- std):", ""]
    for s in d.steps:
        if s.alternatives:
            continue
        shown = ", ".join(f"{nm} = {v:.4g} +- {e:.2g}" for nm, v, e in zip(s.parameter_names, s.values, s.std))
        lines.append(f"- {s.effect}: {shown}")
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
