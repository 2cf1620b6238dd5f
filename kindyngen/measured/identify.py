"""Identification from logs, end to end: a robot description and logged motion in, identified
parameters, prediction errors, an identified robot description and a report out.

``identify(request, progress)`` runs it and returns an :class:`Identification`;
``write_outputs(result, out)`` writes ``identification.json``, ``model.yaml``, ``report.md``
and the figures.  The steps, each from its own module:

1. logs -> uniformly sampled, filtered segments (:mod:`kindyngen.measured.log_preparing`); several
   files are several experiments (each its own clock, filtering, trimming and, with
   ``split``, its own validation part), stacked but never differentiated across their seams;
2. the rigid-body base regressor along the motion (:mod:`kindyngen.measured.regressor_rows`)
   plus the chosen effects' columns (:mod:`kindyngen.measured.effect_columns`), computed from the
   filtered motion and then filtered with the unfiltered torque by the same filter
   (:func:`kindyngen.measured.log_preparing.filtered_rows`: parallel filtering and decimation);
3. least squares, ordinary or weighted, with standard deviations
   (:mod:`kindyngen.measured.estimation`), or the physically consistent semidefinite program
   (:mod:`kindyngen.measured.consistent`) with the description's parameters as the prior;
4. predictions on the training and validation data, RMS per joint;
5. the identified model as a robot description (:mod:`kindyngen.measured.identified_model`).

Example:

>>> result = identify(IdentificationRequest("robots/lwr4.yaml", ("run1.npz",)))   # doctest: +SKIP
>>> result.rms_train                                                               # doctest: +SKIP
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from ..algorithms.base_parameters import condition_number_2norm
from ..json_text import json_number, strict_json
from ..model.inertial_parameters import parameter_vector
from ..model.user_text import markdown
from ..readers.yaml_description import load_robot, parse_robot
from .consistent import identify_consistent, links_from_barycentric, min_pseudo_inertia_eigenvalues
from .discovery import NOISE_BIAS_FACTOR, REL_STD_MAX, effective_samples, elastic_noise_bias, sensing_columns, spring_of
from .effect_columns import EFFECTS, NONNEGATIVE, SENSING_EFFECTS, coulomb_eps, effect_columns, effect_names, effect_of
from .estimation import least_squares, rms_per_joint
from .log_checks import log_bounds
from .log_formats import joint_names_of, read_any
from .log_preparing import Preprocessing, filtered_rows, preprocess, split_time
from .identified_model import ModelWriteError, model_yaml
from .regressor_rows import description_torques, torque_regressor
from .identification_report import rms_table, torque_figure


@dataclass(frozen=True)
class IdentificationRequest:
    """What to identify from what. ``data``/``validate``: log files (CSV or npz), each one
    experiment; ``split``: when given, the time span of ``data`` is cut and its first
    ``split`` fraction trains, the rest validates (instead of, or besides, ``validate``);
    ``effects``: effect names of :data:`kindyngen.measured.effect_columns.EFFECTS` and
    :data:`~kindyngen.measured.effect_columns.SENSING_EFFECTS` (fitted to first order around the
    model, re-linearised at the identified parameters :data:`SENSING_ITERATIONS` times); ``consistent``:
    the semidefinite program instead of least squares; ``weighted``: weighted least squares."""

    robot: str | Path
    data: tuple[str | Path, ...]
    validate: tuple[str | Path, ...] = ()
    effects: tuple[str, ...] = ()
    consistent: bool = False
    weighted: bool = False
    split: float | None = None
    preprocessing: Preprocessing = field(default_factory=Preprocessing)
    base: str | None = None          # a URDF's chain: first and last link (kindyngen.readers.urdf)
    tip: str | None = None
    snap_angles: bool = True


@dataclass(frozen=True, eq=False)
class Identification:
    """The outcome of :func:`identify` (arrays per joint are in N m)."""

    request: IdentificationRequest
    method: str
    base_names: tuple[str, ...]
    base_values: np.ndarray
    base_std_percent: np.ndarray | None
    effect_names: tuple[str, ...]
    effect_values: np.ndarray
    effect_std_percent: np.ndarray | None
    condition_number: float
    rms_train: np.ndarray
    rms_validation: np.ndarray | None
    rms_validation_nominal: np.ndarray | None
    physically_consistent: bool
    consistency_notes: tuple[str, ...]
    model_yaml: str | None
    samples_train: int
    samples_validation: int
    preprocessing_notes: tuple[str, ...]
    validation_t: np.ndarray | None
    validation_tau: np.ndarray | None
    validation_predicted: np.ndarray | None
    validation_nominal: np.ndarray | None
    #: effect coefficients the data does not determine, name -> why (not in model.yaml)
    undetermined: dict = field(default_factory=dict)


#: fits of the effects on the measurement: their columns are linear in the coefficient around
#: the model's torques, so the fit is repeated with the columns re-linearised at the
#: identified base parameters until they change by less than SENSING_TOLERANCE (relative)
SENSING_ITERATIONS = 4
SENSING_TOLERANCE = 1e-3


def undetermined_sensing(names, values, std_percent, bias) -> dict:
    """Sensing coefficients (``ce``, ``dq``, ``gt``) the data does not determine, name -> why:
    zero or negative compliance (no finite stiffness), a relative standard error above
    :data:`kindyngen.measured.discovery.REL_STD_MAX`, or a compliance not
    :data:`~kindyngen.measured.discovery.NOISE_BIAS_FACTOR` times above the torque noise's
    own (``bias`` per joint, :func:`kindyngen.measured.discovery.elastic_noise_bias`).

    >>> undetermined_sensing(("ce1", "ce2"), [1e-3, -1e-4], [5.0, 20.0], [1e-6, 1e-6])
    {'ce2': 'compliance -0.0001 <= 0: no finite stiffness'}
    """
    out = {}
    for k, (name, v) in enumerate(zip(names, values)):
        if name[:2] not in ("ce", "dq", "gt"):
            continue
        reasons = []
        if name.startswith("ce") and not v > 0:
            reasons.append(f"compliance {v:.3g} <= 0: no finite stiffness")
        elif std_percent is not None and not math.isfinite(std_percent[k]):
            reasons.append("not separable from the rigid-body parameters on this data (the data alone does not fix it)")
        elif std_percent is not None and not std_percent[k] <= 100 * REL_STD_MAX:
            reasons.append(f"relative standard error {std_percent[k] / 100:.2g} > {REL_STD_MAX:.2g}")
        if name.startswith("ce") and bias is not None and v > 0 and v < NOISE_BIAS_FACTOR * bias[int(name[2:]) - 1]:
            reasons.append(f"the torque noise alone gives ce = {bias[int(name[2:]) - 1]:.3g} (needs "
                           f"{NOISE_BIAS_FACTOR:g} x that): the joint's torque is too small against the noise")
        if reasons:
            out[name] = "; ".join(reasons)
    return out


def _std_percent(Y, residual, values) -> np.ndarray:
    """``100 std / |value|`` of least squares on the rows ``Y`` (N, n, k) with ``residual``
    (N, n), from the SVD of the column-scaled rows; a coefficient with a part in their
    numerical null space gets infinity (the data alone does not fix it)."""
    A = Y.reshape(-1, Y.shape[2])
    scale = np.linalg.norm(A, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    _, sv, Vt = np.linalg.svd(A / scale, full_matrices=False)
    keep = sv > 1e-10 * sv[0]
    dof = max(A.shape[0] - int(keep.sum()), 1)
    sigma2 = float(np.sum(residual ** 2)) / dof
    var = sigma2 * np.sum((Vt[keep] / sv[keep, None]) ** 2, axis=0) / scale ** 2
    null = np.linalg.norm(Vt[~keep], axis=0) > 1e-6 if (~keep).any() else np.zeros(A.shape[1], bool)
    std = np.where(null, np.inf, np.sqrt(var))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(values) > 0, 100 * std / np.abs(values), np.inf)


def _segments(paths, model, settings, progress, what, split=None):
    """The segments of every file, each checked against the robot as it is read
    (:mod:`kindyngen.measured.log_checks`); with ``split``, (training, validation) cut file by
    file: each file is its own experiment, with its own time span."""
    train, held = [], []
    bounds = log_bounds(model)
    for path in paths:
        progress(f"reading {what} log {path}")
        segments = preprocess(read_any(path, model.n, joint_names_of(model), bounds), settings)
        if split is None:
            train.extend(segments)
        else:
            a, b = split_time(segments, split)
            train.extend(a)
            held.extend(b)
    return (tuple(train), tuple(held)) if split is not None else tuple(train)


def check_consistency(full: np.ndarray, n: int, names, values) -> tuple[bool, tuple[str, ...]]:
    """Whether a full parameter vector and effect coefficients are physical: every link's
    pseudo-inertia positive definite, non-negative friction and armature."""
    notes = []
    eig = min_pseudo_inertia_eigenvalues(full, n)
    for i, e in enumerate(eig):
        if not e > 0:
            notes.append(f"link {i + 1}: pseudo-inertia not positive definite (smallest eigenvalue {e:.3g})")
    for name, v in zip(names, values):
        if effect_of(name) in NONNEGATIVE and v < 0 and effect_of(name) not in SENSING_EFFECTS:
            notes.append(f"{name} = {v:.4g} is negative")
    return not notes, tuple(notes)


def identify(request: IdentificationRequest, progress: Callable[[str], None] = lambda text: None,
             check_fit: Callable | None = None) -> Identification:
    """Run the identification of ``request`` (see the module text); every log is checked
    against the robot as it is read (:mod:`kindyngen.measured.log_checks`). ``check_fit(samples,
    columns, condition)`` may refuse the first fit (raising; ``condition()`` is its stacked
    regressor's condition number) or return notes for the report (the command line passes the
    streamed identification's limits, :mod:`kindyngen.measured.streaming`)."""
    model = load_robot(request.robot, request.snap_angles, request.base, request.tip)
    n = model.n
    settings = request.preprocessing
    if request.split is not None:
        train, held_out = _segments(request.data, model, settings, progress, "training", request.split)
    else:
        train, held_out = _segments(request.data, model, settings, progress, "training"), ()
    validation = tuple(held_out) + _segments(request.validate, model, settings, progress, "validation")
    notes = tuple(dict.fromkeys(note for s in train + validation for note in s.notes))
    filters = tuple(dict.fromkeys(s.low_pass.describe() for s in train + validation if s.low_pass is not None))
    if filters:
        notes += ("parallel filtering: regressor and effect columns computed from the filtered motion, then "
                  "filtered together with the unfiltered torque (" + "; ".join(filters) + ")",)

    progress("building the regressor")
    regressor = torque_regressor(model)
    eps = coulomb_eps(model)
    enames = effect_names(request.effects, n)
    joint_effects = tuple(e for e in request.effects if e in EFFECTS)
    sensing = tuple(e for e in SENSING_EFFECTS if e in request.effects)

    def sensing_rows(segments, base):
        """The effects on the measurement, linearised at the base parameters ``base``,
        parallel-filtered segment by segment (rows, n, k)."""
        def torques(q, qd, qdd):
            return regressor(q, qd, qdd) @ base
        parts = []
        for seg in segments:
            spring = spring_of(seg) if "motor_side_elasticity" in sensing else None
            S = np.concatenate([sensing_columns(e, torques, seg.q, seg.qd, seg.qdd, spring)[0] for e in sensing],
                               axis=2)
            parts.append(filtered_rows(seg, S)[1])
        return np.concatenate(parts)

    def rows(segments, extra=None):
        """Regressor and effect columns and torque, parallel-filtered segment by segment;
        ``extra(segment)`` (N, n): a prediction filtered along (returned fourth)."""
        Ys, Es, taus, ts, extras, start = [], [], [], [], [], 0.0
        for seg in segments:
            Y = regressor(seg.q, seg.qd, seg.qdd)
            E = effect_columns(joint_effects, seg.qd, seg.qdd, eps) if joint_effects else np.zeros((len(seg.t), n, 0))
            parts = [Y, E] + ([extra(seg)[:, :, None]] if extra is not None else [])
            t, F, tau = filtered_rows(seg, np.concatenate(parts, axis=2))
            Ys.append(F[:, :, :Y.shape[2]])
            Es.append(F[:, :, Y.shape[2]:Y.shape[2] + E.shape[2]])
            extras.append(F[:, :, -1] if extra is not None else None)
            taus.append(tau)
            ts.append(t - t[0] + start)
            start = ts[-1][-1] + (t[1] - t[0] if len(t) > 1 else seg.dt)
        out = (np.concatenate(Ys), np.concatenate(Es), np.concatenate(taus))
        if extra is not None:
            out += (np.concatenate(extras), np.concatenate(ts))
        return out

    Yb, E_joint, tau = rows(train)
    k_base = Yb.shape[2]
    P = regressor.base_map
    prior = parameter_vector(model)
    linearised = P @ prior                    # the sensing columns' base parameters
    sensing_notes = ()
    overridden = ()
    if check_fit is not None:
        E_first = np.concatenate([E_joint, sensing_rows(train, linearised)], axis=2) if sensing else E_joint
        stacked = np.concatenate([Yb, E_first], axis=2).reshape(-1, k_base + E_first.shape[2])

        # samples counted at the log's own rate, before decimation, as the streamed fit counts them
        overridden = tuple(check_fit(sum(len(seg.t) for seg in train), stacked.shape[1],
                                     lambda: condition_number_2norm(stacked)))
    for iteration in range(SENSING_ITERATIONS if sensing else 1):
        used = linearised
        E = np.concatenate([E_joint, sensing_rows(train, used)], axis=2) if sensing else E_joint
        if request.consistent:
            progress(f"solving the semidefinite program ({len(tau)} samples, {10 * n + len(enames)} unknowns)")
            fit = identify_consistent(Yb @ P, E, tau, n, enames, prior=prior, base_map=P)
            full, evalues = fit.full_values, fit.effect_values
            base = P @ full
            base_std = effect_std = None
            Y_all = np.concatenate([Yb, E], axis=2)
            cond = condition_number_2norm(Y_all.reshape(-1, Y_all.shape[2]))
            method = "physically consistent (semidefinite program, CLARABEL)"
        else:
            progress(f"least squares ({len(tau)} samples, {k_base + len(enames)} columns)")
            Y_all = np.concatenate([Yb, E], axis=2)
            fit = least_squares(Y_all, tau, regressor.names + enames, weighted=request.weighted)
            base, evalues = fit.values[:k_base], fit.values[k_base:]
            base_std, effect_std = fit.std_percent[:k_base], fit.std_percent[k_base:]
            cond = fit.condition_number
            # the full parameters nearest the description's that reproduce the base values
            full = prior + np.linalg.pinv(P) @ (base - P @ prior)
            method = "weighted least squares" if request.weighted else "ordinary least squares"
        if not sensing:
            break
        change = float(np.linalg.norm(base - linearised) / max(np.linalg.norm(base), 1e-300))
        linearised = np.asarray(base, float)
        progress(f"effects on the measurement: fit {iteration + 1}, base parameters changed by {change:.3g} (relative)")
        if change < SENSING_TOLERANCE:
            break
    if sensing:
        sensing_notes = (f"effects on the measurement ({', '.join(sensing)}) fitted to first order, the columns "
                         f"linearised at the identified parameters ({iteration + 1} fits, last relative change "
                         f"{change:.2g})",)

    def predicted(Y, E_):
        return Y @ base + (E_ @ evalues if len(enames) else 0.0)

    rms_train = rms_per_joint(tau, predicted(Yb, E))
    consistent, consistency_notes = check_consistency(full, n, enames, evalues)
    consistency_notes = overridden + sensing_notes + consistency_notes
    bias = None
    if "motor_side_elasticity" in sensing:
        bias = elastic_noise_bias(lambda q, qd, qdd: regressor(q, qd, qdd) @ base, train)
    # the standard errors of least squares count every filtered sample as independent: judged
    # here with the effective sample size of the residual (as discover does), so a coefficient
    # is not called determined on autocorrelated samples
    residual = tau - predicted(Yb, E)
    inflation = math.sqrt(residual.size / float(np.sum(effective_samples(residual))))
    # the semidefinite program gives no standard errors: those of least squares on the same
    # columns, a coefficient with a part in their null space (not separable from the rigid
    # bodies, e.g. the common gain of all torque sensors) unbounded
    std = effect_std if effect_std is not None else \
        _std_percent(np.concatenate([Yb, E], axis=2), residual, np.concatenate([base, evalues]))[k_base:]
    judged_std = np.asarray(std, float) * inflation
    not_determined = undetermined_sensing(enames, evalues, judged_std, bias)
    # a sensing coefficient the data does not determine is not written: that joint keeps the
    # ideal sensor (rigid, no offset, unit gain) and the report says why
    written = {name: float(v) for name, v in zip(enames, evalues) if name not in not_determined}
    if not_determined:
        consistency_notes += ("not determined by the data, so not written to model.yaml: " + "; ".join(
            f"{name} = {float(evalues[enames.index(name)]):.3g} ({why})" for name, why in not_determined.items()),)

    text = None
    if consistent:
        try:
            header = (f"Identified by KinDynGen from {', '.join(map(str, request.data))} ({method}).\n"
                      f"Geometry from {request.robot}; link parameters and joint effects identified.")
            text = model_yaml(request.robot, links_from_barycentric(full, n), written, model=model,
                              header=header, name=f"{model.name}_identified")
            parse_robot(yaml.safe_load(text), "model.yaml")     # the loader must take what we write
        except (ModelWriteError, ValueError) as exc:
            consistency_notes += (f"model.yaml not written: {exc}",)
            text = None
    else:
        consistency_notes += ("model.yaml not written: the identified parameters are not physical "
                              "(use --consistent)",)

    rms_val = rms_nominal = None
    vt = vtau = vpred = vnom = None
    if validation:
        # the starting description's own prediction (rigid bodies and its declared effects)
        Yv, Ev, vtau, vnom, vt = rows(validation, lambda seg: description_torques(model, seg.q, seg.qd, seg.qdd))
        if sensing:
            Ev = np.concatenate([Ev, sensing_rows(validation, used)], axis=2)
        vpred = predicted(Yv, Ev)
        rms_val = rms_per_joint(vtau, vpred)
        rms_nominal = rms_per_joint(vtau, vnom)
    return Identification(
        request=request, method=method, base_names=regressor.names, base_values=np.asarray(base),
        base_std_percent=base_std, effect_names=enames, effect_values=np.asarray(evalues),
        effect_std_percent=effect_std, condition_number=cond, rms_train=rms_train, rms_validation=rms_val,
        rms_validation_nominal=rms_nominal, physically_consistent=consistent,
        consistency_notes=consistency_notes, model_yaml=text,
        samples_train=int(len(tau)), samples_validation=int(0 if vtau is None else len(vtau)),
        preprocessing_notes=notes, validation_t=vt, validation_tau=vtau, validation_predicted=vpred,
        validation_nominal=vnom, undetermined=not_determined)


def _numbers(values) -> list:
    """Floats for JSON; a non-finite one (the relative std of a zero value or of a coefficient
    the data does not determine) as the string of :mod:`kindyngen.json_text`'s rule."""
    return json_number(np.asarray(values, float).tolist())


def result_document(result: Identification) -> dict:
    """The content of ``identification.json``."""
    r = result.request
    doc = {
        "robot": str(r.robot), "data": [str(p) for p in r.data], "validate": [str(p) for p in r.validate],
        "split": r.split, "method": result.method, "effects_requested": list(r.effects),
        "preprocessing": list(result.preprocessing_notes),
        "samples": {"train": result.samples_train, "validation": result.samples_validation},
        "base_params": {"names": list(result.base_names), "values": _numbers(result.base_values),
                        "std_percent": None if result.base_std_percent is None else _numbers(result.base_std_percent)},
        "effects": {"names": list(result.effect_names), "values": _numbers(result.effect_values),
                    "std_percent": None if result.effect_std_percent is None else _numbers(result.effect_std_percent)},
        "condition_number": json_number(float(result.condition_number)),
        "rms_train": _numbers(result.rms_train),
        "rms_validation": None if result.rms_validation is None else _numbers(result.rms_validation),
        "rms_validation_description": None if result.rms_validation_nominal is None
        else _numbers(result.rms_validation_nominal),
        "physically_consistent": result.physically_consistent,
        "effects_not_determined": dict(result.undetermined),
        "notes": list(result.consistency_notes),
        "units": "torques and RMS in N m; std_percent = 100 std / |value|",
    }
    return doc


def write_outputs(result: Identification, out: str | Path) -> Path:
    """``identification.json``, ``model.yaml`` (when physical), ``report.md`` and
    ``validation_torques.png`` under ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "identification.json").write_text(strict_json(result_document(result), indent=1) + "\n")
    if result.model_yaml is not None:
        (out / "model.yaml").write_text(result.model_yaml)
    n = len(result.rms_train)
    # the description's file name and the preprocessing notes (which may name a log's keys) are
    # the user's text: literal Markdown
    lines = [f"# Identification of {markdown(Path(result.request.robot).name)}", "",
             f"Method: {result.method}. Effects: {', '.join(result.request.effects) or 'none'}. "
             f"Training samples: {result.samples_train}; validation samples: {result.samples_validation}. "
             f"Condition number of the stacked regressor: {result.condition_number:.4g}.", "",
             "Preprocessing: " + "; ".join(map(markdown, result.preprocessing_notes)) + ".", "",
             "## RMS torque error per joint (N m)", ""]
    rows = {"identified, training": list(result.rms_train)}
    if result.rms_validation is not None:
        rows["identified, validation"] = list(result.rms_validation)
        rows["starting description, validation"] = list(result.rms_validation_nominal)
    lines += [rms_table(rows, n), ""]
    if result.validation_t is not None:
        figure = torque_figure(out / "validation_torques.png", result.validation_t, result.validation_tau,
                               {"identified": result.validation_predicted,
                                "starting description": result.validation_nominal},
                               "validation: measured and predicted joint torques")
        lines += ["## Validation torques", "", f"![measured and predicted torques]({figure.name})", ""]
    lines += ["## Parameters", "", "| parameter | value | std (%) |", "|---|---|---|"]
    std = result.base_std_percent
    for k, (name, value) in enumerate(zip(result.base_names, result.base_values)):
        lines.append(f"| {name} | {value:.6g} | {'-' if std is None else f'{std[k]:.3g}'} |")
    estd = result.effect_std_percent
    for k, (name, value) in enumerate(zip(result.effect_names, result.effect_values)):
        lines.append(f"| {name} | {value:.6g} | {'-' if estd is None else f'{estd[k]:.3g}'} |")
    lines += ["", f"Physically consistent: {'yes' if result.physically_consistent else 'no'}."]
    lines += [f"- {note}" for note in result.consistency_notes]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return out
