"""Reproduction of the identification paper's experiments (Gaz, Flacco, De Luca, "Identifying
the Dynamic Model Used by the KUKA LWR: A Reverse Engineering Approach", ICRA 2014, Sect. VI)
against a data source that behaves like the robot's control interface
(:mod:`kindyngen.measured.fri_source`).

:func:`reproduce` runs, on the pipeline's base-parameter regressors
(:func:`kindyngen.algorithms.regressors.regressor`):

1. static identification: N random configurations uniform within the joint limits (1000 in
   the paper), the reported g and M at each; stacked ``Y_g`` rows (joint 1's row dropped, as
   the paper does: it is identically zero on a level base) -> ``pi_g``; stacked ``Y_m`` rows
   (the 28 lower-triangular elements of M) -> ``pi_m``; ordinary least squares (eqs. 24-25)
   with standard deviations and the stacked regressors' condition numbers;
2. the errors of Tables II and III: per joint the mean square and the maximum absolute error
   of g, and the same for every element of M, on the training set, on a validation set
   (200 configurations) and along the torque-validation motion (TVE);
3. the tip-mass experiment (eqs. 30-32): identify ``pi_g`` again with a point mass on the
   flange and recover it from the changes of the paper's entries 12 and 7 divided by d1 and
   d2 (our base parameters are matched to the paper's entries by their structure,
   :func:`paper_entry_map`);
4. the torque validation (eq. 33, Fig. 4): ``q_des(t) = pi/2 cos(pi t / 7)`` on all joints,
   t in [0, 14] s at 1 kHz; measured positions differentiated twice, q, qd, qdd and the
   measured torques filtered by a 4th-order zero-phase Butterworth at 1 Hz; predicted
   ``tau = M qdd + c + g`` from the identified ``pi_m``, ``pi_g`` (the torque regressor's base
   parameters are a linear function of them: c follows from M by the Christoffel symbols);
5. the paper's published ``pi_g`` (eq. 29) in our ``Y_g``: g_2 along the validation motion.

:func:`write_report` writes ``reproduction.json``, ``report.md`` (our figures beside the
paper's) and PNG plots.

Note on ``p_m``: the paper's trigonometric coefficient collection gave 74 inertia
coefficients (after eq. 27, which the real controller's M_76 = 0 forces); the barycentric
base of ``Y_m`` for this DH table has 39 (see ``docs``/README), so ``pi_m`` is not comparable
entry by entry (the paper did not print it either).

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> from kindyngen.measured.fri_source import FriSource
>>> robot = load_robot("robots/lwr4.yaml")                       # doctest: +SKIP
>>> result = reproduce(FriSource(robot), robot, n_train=300)     # doctest: +SKIP
>>> result.tip_mass                                              # doctest: +SKIP
{'from_entry_12': 0.25..., 'from_entry_7': 0.25...}
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np
import sympy

from ..algorithms.paper_parameters import base_expressions_in_paper, paper_symbols
from ..json_text import strict_json
from ..algorithms.regressors import base_parameters
from ..model.robot_model import RobotModel
from .estimation import Fit, least_squares
from .fri_source import DynamicsSource, Motion
from .log_preparing import zero_phase_low_pass
from .regressor_rows import BaseRegressor, TorqueRegressor, rigid_body_model

# ----------------------------------------------------------------------------- the paper's figures

# eq. 28: the structure of pi_g, entries 1..12 (d1, d2 the DH lengths of joints 3 and 5);
# the seed text repeats "c5x m5" as a 7th line (an extraction artefact: 13 lines for 12
# numbers); the list below is the 12-entry structure restated in /work/shared/reference.md
PAPER_PI_G_STRUCTURE = (
    "c7y*m7", "c7x*m7", "c6x*m6", "c6z*m6 + c7z*m7", "c5z*m5 - c6y*m6", "c5x*m5",
    "c5y*m5 + c4z*m4 + d2*(m5 + m6 + m7)", "c4x*m4", "c4y*m4 + c3z*m3", "c2x*m2", "c3x*m3",
    "c2z*m2 - c3y*m3 + d1*(m3 + m4 + m5 + m6 + m7)")
# eq. 29 (m kg), identified on the paper's arm
PAPER_PI_G = (9.5457e-4, -2.9826e-4, 8.3524e-4, 0.0286, -0.0407, -6.5637e-4, 1.334, -0.0035,
              -4.7258e-4, 0.0014, 9.4532e-4, 3.4568)
# eq. 30: a second arm with a 250 g symmetric steel tip on the flange
PAPER_PI_G_TIP = (9.5486e-4, -2.9823e-4, 8.3534e-4, 0.0507, -0.0407, -6.5618e-4, 1.4320, -0.0035,
                  -4.7317e-4, 0.0014, 9.4555e-4, 3.5580)
PAPER_TIP_MASS = 0.25            # kg, eqs. 31-32 ("~ 0.25 kg" from both entries)
PAPER_D1, PAPER_D2 = 0.40, 0.39  # m

# Tables II and III (gravity only; the paper does not report M errors, "lack of space").
# Legibility in the seed text (000_*.txt): every cell of both tables is legible; joint 1 is
# "-" in the paper (its g row is dropped from the estimation), kept here as None.  Columns:
# TS training set (N = 1000), VS validation set (N_v = 200), TVE torque validation experiment.
# Units: N^2 m^2 (Table II, mean square) and N m (Table III, max absolute).
PAPER_TABLE_II = {  # componentwise mean square error of g
    "TS": (None, 9.3e-9, 9.1e-10, 3.3e-9, 7.3e-12, 6.4e-12, 7.4e-13),
    "VS": (None, 4.2e-7, 3.9e-9, 3.1e-8, 7.3e-11, 2.3e-10, 6.02e-13),
    "TVE": (None, 2.1e-2, 2.4e-3, 3.3e-4, 2.9e-6, 5.8e-7, 6.9e-10),
}
PAPER_TABLE_III = {  # componentwise maximum absolute error of g
    "TS": (None, 6.2202e-4, 5.3553e-4, 5.6154e-4, 2.1393e-5, 1.2362e-5, 1.5917e-6),
    "VS": (None, 0.0019, 1.6959e-4, 4.7839e-4, 2.3266e-5, 3.2970e-5, 2.0801e-6),
    "TVE": (None, 0.3707, 0.1275, 0.0447, 0.0052, 0.0031, 1.0272e-4),
}
PAPER_TABLES_NOTE = ("Tables II and III of the paper give gravity errors only (joint 1 '-': its row is "
                     "dropped); all other cells were legible in the extracted text. The paper reports no "
                     "figures for the errors of M (only Fig. 6, M_11 along a motion, 'perfect agreement').")

SETS = ("TS", "VS", "TVE")
DURATION, RATE, CUTOFF, ORDER = 14.0, 1000.0, 1.0, 4     # eq. 33 and the filter of Sect. VI


def q_des(t):
    """Eq. 33: ``(pi/2) cos(pi t / 7)`` and its exact first and second derivatives (same for
    every joint): three arrays shaped like ``t``."""
    w = np.pi / 7
    return (np.pi / 2 * np.cos(w * t), -np.pi / 2 * w * np.sin(w * t), -np.pi / 2 * w * w * np.cos(w * t))


# ----------------------------------------------------------------------------- structure matching

@dataclass(frozen=True)
class EntryMap:
    """Paper entry k (0-based) of pi_g is ``sign * ours[column[k]]``; ``m7_coefficient[k]`` is
    the coefficient of m7 in that entry (d1 for entry 12, d2 for entry 7, 0 or 1 otherwise)."""

    column: tuple[int, ...]
    sign: tuple[int, ...]
    m7_coefficient: tuple[float, ...]
    names: tuple[str, ...]

    def ours_from_paper(self, paper_values) -> np.ndarray:
        out = np.full(len(self.column), np.nan)
        for k, (c, s) in enumerate(zip(self.column, self.sign)):
            out[c] = s * paper_values[k]
        return out

    def paper_from_ours(self, ours) -> np.ndarray:
        ours = np.asarray(ours, float)
        return np.array([s * ours[c] for c, s in zip(self.column, self.sign)])


@lru_cache(maxsize=None)
def paper_entry_map(model: RobotModel) -> EntryMap:
    """Match the base parameters of ``Y_g`` to the paper's eq. 28 entries by structure (equal
    as polynomials in the paper's parameters, up to sign, d1 and d2 the model's DH lengths of
    joints 3 and 5).  Raises when the structures differ (another robot or DH table)."""
    b = base_parameters(rigid_body_model(model), "Y_g")
    ours = base_expressions_in_paper(rigid_body_model(model), "Y_g")
    n = model.n
    if n != 7 or len(ours) != len(PAPER_PI_G_STRUCTURE):
        raise ValueError(f"the paper's pi_g has {len(PAPER_PI_G_STRUCTURE)} entries for a 7-joint arm; "
                         f"{model.name} has {n} joints and {len(ours)} gravity base parameters")
    names = {str(s): s for s in paper_symbols(n)}
    names.update(d1=sympy.sympify(model.joints[2].d), d2=sympy.sympify(model.joints[4].d))
    m7 = names["m7"]
    column, sign, coefficient = [], [], []
    for k, text in enumerate(PAPER_PI_G_STRUCTURE):
        expr = sympy.expand(sympy.sympify(text, locals=names))
        found = [(j, s) for j, e in enumerate(ours) for s in (1, -1) if sympy.expand(e - s * expr) == 0]
        if len(found) != 1:
            raise ValueError(f"paper entry {k + 1} ({text}) matches {len(found)} of our Y_g base parameters "
                             f"{b.names}: the structures differ")
        column.append(found[0][0])
        sign.append(found[0][1])
        zero = {s: 0 for s in expr.free_symbols if s != m7}
        coefficient.append(float(sympy.diff(expr, m7).subs(zero)))
    return EntryMap(tuple(column), tuple(sign), tuple(coefficient), b.names)


# ----------------------------------------------------------------------------- batch regressors

def lower_stack(M) -> np.ndarray:
    """(N, n, n) -> (N, n(n+1)/2): the lower triangle row by row (M00, M10, M11, M20, ...)."""
    n = M.shape[-1]
    i, j = np.tril_indices(n)
    return M[:, i, j]


def element_names(n: int) -> tuple[str, ...]:
    """The stacked elements with the paper's 1-based names: M_11, M_21, M_22, ..."""
    return tuple(f"M_{i + 1}{j + 1}" for i in range(n) for j in range(i + 1))


def errors(estimated, reported) -> dict:
    """Per column: mean square and maximum absolute error over the samples."""
    e = np.asarray(estimated, float) - np.asarray(reported, float)
    return {"mse": np.mean(e ** 2, axis=0), "max": np.max(np.abs(e), axis=0)}


def torque_parameter_map(model: RobotModel) -> np.ndarray:
    """A with ``pi_Y = A @ [pi_m; pi_g]``: the torque regressor's base parameters from the
    inertia and gravity ones (tau = M qdd + c(M) + g depends on the parameters only through
    M and g).  Verified: the residual of the map must be at rounding level."""
    model = rigid_body_model(model)
    P_Y = base_parameters(model, "Y").map_matrix()
    P_mg = np.vstack([base_parameters(model, "Y_m").map_matrix(), base_parameters(model, "Y_g").map_matrix()])
    At, *_ = np.linalg.lstsq(P_mg.T, P_Y.T, rcond=None)
    residual = np.abs(P_mg.T @ At - P_Y.T).max()
    if residual > 1e-9 * max(1.0, np.abs(P_Y).max()):
        raise ValueError(f"the torque base parameters are not a function of the inertia and gravity ones "
                         f"(residual {residual:.3g})")
    return At.T


@lru_cache(maxsize=8)
def _regressors(model: RobotModel):
    """Y_g, Y_m (batch), the torque regressor and the map to its parameters, built once."""
    return BaseRegressor(model, "Y_g"), BaseRegressor(model, "Y_m"), TorqueRegressor(model), torque_parameter_map(model)


# ----------------------------------------------------------------------------- the reproduction

@dataclass
class Identified:
    """One static identification: ``pi_g`` (fit on rows 2..n of g) and ``pi_m``."""

    g: Fit
    m: Fit | None


@dataclass
class Reproduction:
    """Everything :func:`reproduce` computed (arrays; :meth:`summary` is the JSON content)."""

    robot: str
    n_train: int
    n_val: int
    seed: int
    names_g: tuple[str, ...]
    names_m: tuple[str, ...]
    identified: Identified
    tip_identified: Identified | None
    entry_map: EntryMap
    g_errors: dict                   # set -> {"mse": (n,), "max": (n,)}
    m_errors: dict                   # set -> {"mse": (28,), "max": (28,)}
    tip_mass: dict                   # from_entry_12, from_entry_7 (kg), added (kg), distance
    torque: dict                     # t, q, qd, qdd, measured, predicted (filtered), rms, max
    published_g2: dict               # t, reported, ours, published (g_2 along the motion)
    motion_elements: dict            # t, reported M_11, estimated M_11, element-wise rms along the motion
    timings: dict = field(default_factory=dict)
    truth_g: np.ndarray | None = None   # base values of the source's truth, when it tells them
    truth_m: np.ndarray | None = None

    @property
    def pi_g(self) -> np.ndarray:
        return self.identified.g.values

    @property
    def pi_m(self) -> np.ndarray:
        return self.identified.m.values

    def pi_g_paper_order(self) -> np.ndarray:
        return self.entry_map.paper_from_ours(self.pi_g)

    def summary(self) -> dict:
        n = len(self.g_errors["TS"]["mse"])
        fit_g, fit_m = self.identified.g, self.identified.m

        def lst(a):
            return None if a is None else [float(x) for x in np.asarray(a).ravel()]

        out = {
            "paper": "Gaz, Flacco, De Luca, ICRA 2014: Identifying the Dynamic Model Used by the KUKA LWR",
            "robot": self.robot, "n_train": self.n_train, "n_val": self.n_val, "seed": self.seed,
            "pi_g": {
                "names": list(self.names_g), "values": lst(fit_g.values), "std": lst(fit_g.std),
                "condition_number": fit_g.condition_number,
                "condition_number_scaled": fit_g.condition_number_scaled,
                "paper_order": {
                    "structure": list(PAPER_PI_G_STRUCTURE),
                    "our_name": [self.names_g[c] for c in self.entry_map.column],
                    "sign": list(self.entry_map.sign),
                    "ours": lst(self.pi_g_paper_order()),
                    "paper_eq29": list(PAPER_PI_G),
                    "ours_with_tip": (lst(self.entry_map.paper_from_ours(self.tip_identified.g.values))
                                      if self.tip_identified else None),
                    "paper_eq30": list(PAPER_PI_G_TIP),
                },
                "truth": lst(self.truth_g),
            },
            "pi_m": None if fit_m is None else {
                "names": list(self.names_m), "values": lst(fit_m.values), "std": lst(fit_m.std),
                "condition_number": fit_m.condition_number,
                "condition_number_scaled": fit_m.condition_number_scaled,
                "count": len(self.names_m), "paper_count": 74, "truth": lst(self.truth_m),
            },
            "tip_mass": dict(self.tip_mass),
            "table_II_mse_g": {s: lst(self.g_errors[s]["mse"]) for s in self.g_errors},
            "table_III_max_g": {s: lst(self.g_errors[s]["max"]) for s in self.g_errors},
            "paper_table_II": {s: list(v) for s, v in PAPER_TABLE_II.items()},
            "paper_table_III": {s: list(v) for s, v in PAPER_TABLE_III.items()},
            "paper_tables_note": PAPER_TABLES_NOTE,
            "m_elements": list(element_names(n)),
            "mse_M": {s: lst(self.m_errors[s]["mse"]) for s in self.m_errors},
            "max_M": {s: lst(self.m_errors[s]["max"]) for s in self.m_errors},
            "torque_validation": {"rms": lst(self.torque["rms"]), "max": lst(self.torque["max"]),
                                  "rms_interior": lst(self.torque["rms_interior"]),
                                  "filter": f"{ORDER}th-order zero-phase Butterworth, {CUTOFF:g} Hz",
                                  "samples": int(len(self.torque["t"]))},
            "published_pi_g_g2": {"rms_vs_reported": float(self.published_g2["rms"]),
                                  "max_vs_reported": float(self.published_g2["max"])},
            "timings_s": {k: round(v, 3) for k, v in self.timings.items()},
        }
        return out


def _identify(source, q, Yg, Ym, names_g, names_m, with_m=True) -> tuple[Identified, np.ndarray, np.ndarray]:
    g = np.asarray(source.gravity(q), float)
    Y_g = Yg(q)
    fit_g = least_squares(Y_g[:, 1:, :], g[:, 1:], names_g)          # joint 1's row dropped (paper)
    fit_m, m = None, None
    if with_m:
        m = lower_stack(np.asarray(source.inertia(q), float))
        fit_m = least_squares(Ym(q), m, names_m)
    return Identified(fit_g, fit_m), g, m


def reproduce(source: DynamicsSource, model: RobotModel, n_train: int = 1000, n_val: int = 200,
              seed: int = 2014, tip_mass: float = 0.25, tip_distance: float = 0.0,
              motion: Motion | None = None, tip_source: DynamicsSource | None = None,
              progress: Callable[[str], None] | None = None) -> Reproduction:
    """Run the paper's experiments (see the module doc) on ``source`` with ``model``'s
    regressors.

    ``source``: the controller (g(q), M(q), torques; :class:`~.fri_source.FriSource` or
    logged data); ``model``: the robot description whose DH table the regressors use (its
    inertial values are not read); ``n_train``, ``n_val``: random static configurations
    (uniform within the joint limits, generator seeded by ``seed`` and ``seed + 1``);
    ``tip_mass`` (kg) at ``tip_distance`` (m) on the flange axis: the tip experiment, run on
    ``tip_source`` or, when None, ``source.with_tip(tip_mass, tip_distance)`` (skipped when
    ``tip_mass`` is 0 or neither is available); ``motion``: a measured torque-validation
    motion (default: ``source.track`` along eq. 33 at 1 kHz); ``progress``: called with a
    line of text per step."""
    say = progress or (lambda text: None)
    timings = {}
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        timings[name] = now - clock
        clock = now

    n = model.n
    say("regressors: Y_g, Y_m, Y on base parameters")
    Yg, Ym, Ytau, A = _regressors(model)
    entry_map = paper_entry_map(model)
    lap("regressors")

    rng = np.random.default_rng(seed)
    q_train = rng.uniform(model.lower, model.upper, size=(n_train, n))
    q_val = np.random.default_rng(seed + 1).uniform(model.lower, model.upper, size=(n_val, n))

    say(f"static identification on {n_train} configurations")
    ident, g_train, m_train = _identify(source, q_train, Yg, Ym, Yg.names, Ym.names)
    pi_g, pi_m = ident.g.values, ident.m.values
    lap("identification")

    say(f"validation on {n_val} configurations")
    g_val = np.asarray(source.gravity(q_val), float)
    m_val = lower_stack(np.asarray(source.inertia(q_val), float))
    g_err = {"TS": errors(Yg(q_train) @ pi_g, g_train), "VS": errors(Yg(q_val) @ pi_g, g_val)}
    m_err = {"TS": errors(Ym(q_train) @ pi_m, m_train), "VS": errors(Ym(q_val) @ pi_m, m_val)}
    lap("validation")

    # ---- torque validation experiment (eq. 33)
    say("torque validation: q_des = pi/2 cos(pi t / 7), 14 s at 1 kHz")
    if motion is None:
        t = np.arange(int(round(DURATION * RATE)) + 1) / RATE
        qs = [np.repeat(x[:, None], n, axis=1) for x in q_des(t)]
        motion = source.track(t, *qs)
    t = np.asarray(motion.t, float)
    rate = 1.0 / float(np.median(np.diff(t)))
    q_meas = np.asarray(motion.q, float)
    qd = np.gradient(q_meas, t, axis=0, edge_order=2)
    qdd = np.gradient(qd, t, axis=0, edge_order=2)
    qf, qdf, qddf = (zero_phase_low_pass(x, rate, CUTOFF, ORDER) for x in (q_meas, qd, qdd))
    tau_f = zero_phase_low_pass(np.asarray(motion.tau, float), rate, CUTOFF, ORDER)
    pi_tau = A @ np.concatenate([pi_m, pi_g])
    tau_hat = Ytau(qf, qdf, qddf) @ pi_tau
    e = tau_hat - tau_f
    edge = int(round(rate / CUTOFF))                      # one cutoff period at each end
    interior = slice(edge, len(t) - edge) if len(t) > 4 * edge else slice(None)
    torque = {"t": t, "q": qf, "qd": qdf, "qdd": qddf, "measured": tau_f, "predicted": tau_hat,
              "rms": np.sqrt(np.mean(e ** 2, axis=0)), "max": np.abs(e).max(axis=0),
              "rms_interior": np.sqrt(np.mean(e[interior] ** 2, axis=0))}
    lap("torque validation")

    # ---- g and M reported along the motion (TVE columns), published pi_g
    g_tve = motion.gravity if motion.gravity is not None else source.gravity(q_meas)
    M_tve = motion.inertia if motion.inertia is not None else source.inertia(q_meas)
    g_tve, m_tve = np.asarray(g_tve, float), lower_stack(np.asarray(M_tve, float))
    Yg_tve, Ym_tve = Yg(q_meas), Ym(q_meas)
    g_hat_tve, m_hat_tve = Yg_tve @ pi_g, Ym_tve @ pi_m
    g_err["TVE"], m_err["TVE"] = errors(g_hat_tve, g_tve), errors(m_hat_tve, m_tve)
    published = Yg_tve @ entry_map.ours_from_paper(PAPER_PI_G)
    published_g2 = {"t": t, "reported": g_tve[:, 1], "ours": g_hat_tve[:, 1], "published": published[:, 1],
                    "rms": float(np.sqrt(np.mean((published[:, 1] - g_tve[:, 1]) ** 2))),
                    "max": float(np.abs(published[:, 1] - g_tve[:, 1]).max())}
    motion_elements = {"t": t, "reported_M11": m_tve[:, 0], "estimated_M11": m_hat_tve[:, 0],
                       "rms": np.sqrt(np.mean((m_hat_tve - m_tve) ** 2, axis=0))}
    lap("motion errors")

    # ---- tip mass (eqs. 30-32)
    tip_ident, tip = None, {"added": tip_mass, "distance": tip_distance,
                            "from_entry_12": None, "from_entry_7": None}
    if tip_mass and (tip_source is not None or hasattr(source, "with_tip")):
        say(f"tip experiment: {tip_mass:g} kg on the flange axis at {tip_distance:g} m")
        tip_source = tip_source if tip_source is not None else source.with_tip(tip_mass, tip_distance)
        tip_ident, _, _ = _identify(tip_source, q_train, Yg, Ym, Yg.names, Ym.names, with_m=False)
        before = entry_map.paper_from_ours(pi_g)
        after = entry_map.paper_from_ours(tip_ident.g.values)
        for entry in (12, 7):
            k = entry - 1
            tip[f"from_entry_{entry}"] = float((after[k] - before[k]) / entry_map.m7_coefficient[k])
            tip[f"divisor_entry_{entry}"] = entry_map.m7_coefficient[k]
        tip["change_entry_4"] = float(after[3] - before[3])   # m_tip * distance (c7z m7 term)
        tip["paper_from_entry_12"] = (PAPER_PI_G_TIP[11] - PAPER_PI_G[11]) / PAPER_D1
        tip["paper_from_entry_7"] = (PAPER_PI_G_TIP[6] - PAPER_PI_G[6]) / PAPER_D2
        lap("tip experiment")

    truth_g = truth_m = None
    if hasattr(source, "truth_parameters"):
        full = source.truth_parameters()
        truth_g, truth_m = Yg.base.values(full), Ym.base.values(full)
    return Reproduction(robot=model.name, n_train=n_train, n_val=n_val, seed=seed, names_g=Yg.names,
                        names_m=Ym.names, identified=ident, tip_identified=tip_ident, entry_map=entry_map,
                        g_errors=g_err, m_errors=m_err, tip_mass=tip, torque=torque,
                        published_g2=published_g2, motion_elements=motion_elements, timings=timings,
                        truth_g=truth_g, truth_m=truth_m)


# ----------------------------------------------------------------------------- report

def _e(x) -> str:
    return "-" if x is None else f"{x:.3g}"


def tables_markdown(result: Reproduction) -> str:
    """Tables II and III (ours beside the paper's) and the M element errors."""
    n = len(result.g_errors["TS"]["mse"])
    lines = ["### Table II: mean square error of g per joint (N^2 m^2)", "",
             "| joint | TS ours | TS paper | VS ours | VS paper | TVE ours | TVE paper |", "|---|---|---|---|---|---|---|"]
    for j in range(n):
        cells = []
        for s in SETS:
            cells += [_e(result.g_errors[s]["mse"][j]), _e(PAPER_TABLE_II[s][j])]
        lines.append(f"| J{j + 1} | " + " | ".join(cells) + " |")
    lines += ["", "### Table III: maximum absolute error of g per joint (N m)", "",
              "| joint | TS ours | TS paper | VS ours | VS paper | TVE ours | TVE paper |", "|---|---|---|---|---|---|---|"]
    for j in range(n):
        cells = []
        for s in SETS:
            cells += [_e(result.g_errors[s]["max"][j]), _e(PAPER_TABLE_III[s][j])]
        lines.append(f"| J{j + 1} | " + " | ".join(cells) + " |")
    lines += ["", "Joint 1 is estimated too (ours) though its row is not used in the fit; the paper leaves it "
              "out ('-'). " + PAPER_TABLES_NOTE, "",
              "### Errors of the elements of M (kg^2 m^4 mean square, kg m^2 max); not reported by the paper", "",
              "| element | TS mse | TS max | VS mse | VS max | TVE mse | TVE max |", "|---|---|---|---|---|---|---|"]
    for k, name in enumerate(element_names(n)):
        cells = []
        for s in SETS:
            cells += [_e(result.m_errors[s]["mse"][k]), _e(result.m_errors[s]["max"][k])]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _plots(result: Reproduction, out: Path) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    files = []
    tq = result.torque
    n = tq["measured"].shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(8, 1.7 * n), sharex=True)
    for j, ax in enumerate(axes):
        ax.plot(tq["t"], tq["measured"][:, j], "b--", lw=1, label="measured (filtered)")
        ax.plot(tq["t"], tq["predicted"][:, j], "g-", lw=1, label="estimated, eq. 26")
        ax.set_ylabel(f"tau{j + 1} [Nm]")
    axes[0].legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("Torque validation (paper Fig. 4)")
    fig.tight_layout()
    fig.savefig(out / "fig4_torque_validation.png", dpi=90)
    plt.close(fig)
    files.append("fig4_torque_validation.png")

    me, pg = result.motion_elements, result.published_g2
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.5))
    axes[0].plot(pg["t"], pg["reported"], "b-", lw=1, label="reported")
    axes[0].plot(pg["t"], pg["ours"], "g--", lw=1, label="identified pi_g")
    axes[0].set_title("g_2 along the motion")
    axes[0].legend(fontsize=7)
    axes[1].plot(me["t"], me["reported_M11"], "b-", lw=1, label="reported")
    axes[1].plot(me["t"], me["estimated_M11"], "g--", lw=1, label="identified pi_m")
    axes[1].set_title("M_11 along the motion")
    axes[1].legend(fontsize=7)
    names = element_names(n)
    axes[2].semilogy(range(len(names)), np.maximum(me["rms"], 1e-18), "o")
    axes[2].set_xticks(range(len(names)))
    axes[2].set_xticklabels(names, rotation=90, fontsize=6)
    axes[2].set_title("RMS error per element of M")
    fig.suptitle("Element-wise comparison (paper Fig. 6)")
    fig.tight_layout()
    fig.savefig(out / "fig6_elements.png", dpi=90)
    plt.close(fig)
    files.append("fig6_elements.png")

    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.plot(pg["t"], pg["reported"], "b-", lw=1, label="reported by the source")
    ax.plot(pg["t"], pg["published"], "r--", lw=1, label="paper's pi_g (eq. 29) in our Y_g")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("g_2 [Nm]")
    ax.legend(fontsize=7)
    ax.set_title("g_2 with the published coefficients")
    fig.tight_layout()
    fig.savefig(out / "g2_published.png", dpi=90)
    plt.close(fig)
    files.append("g2_published.png")
    return files


def write_report(result: Reproduction, out_dir) -> dict:
    """Write ``reproduction.json``, ``report.md`` and the PNG plots to ``out_dir``; returns
    the JSON content."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = result.summary()
    files = _plots(result, out)
    summary["plots"] = files
    (out / "reproduction.json").write_text(strict_json(summary, indent=1) + "\n")

    em = result.entry_map
    ours = result.pi_g_paper_order()
    tip = result.entry_map.paper_from_ours(result.tip_identified.g.values) if result.tip_identified else None
    std = np.array([result.identified.g.std[c] for c in em.column])
    lines = [f"# Reproduction of Gaz, Flacco, De Luca (ICRA 2014) on {result.robot}", "",
             f"Training {result.n_train} and validation {result.n_val} random static configurations "
             f"(seed {result.seed}); base regressors Y_g ({len(result.names_g)} columns, cond "
             f"{result.identified.g.condition_number:.3g}) and Y_m ({len(result.names_m)} columns, cond "
             f"{result.identified.m.condition_number:.3g}; the paper's trigonometric collection: 74).", "",
             "## pi_g in the paper's order (eq. 28), m kg", "",
             "| entry | structure | our column | ours | std | paper eq. 29 | ours with tip | paper eq. 30 |",
             "|---|---|---|---|---|---|---|---|"]
    for k, text in enumerate(PAPER_PI_G_STRUCTURE):
        sign = "" if em.sign[k] > 0 else "-"
        lines.append(f"| {k + 1} | {text} | {sign}{em.names[em.column[k]]} | {ours[k]:.5g} | {std[k]:.2g} | "
                     f"{PAPER_PI_G[k]:.5g} | {'-' if tip is None else f'{tip[k]:.5g}'} | {PAPER_PI_G_TIP[k]:.5g} |")
    t = result.tip_mass
    lines += ["", "## Tip mass (eqs. 31-32)", "",
              f"Added: {t['added']:g} kg at {t['distance']:g} m on the flange axis.", "",
              "| from | ours (kg) | paper (kg) |", "|---|---|---|",
              f"| entry 12 / d1 | {_e(t['from_entry_12'])} | {_e(t.get('paper_from_entry_12'))} |",
              f"| entry 7 / d2 | {_e(t['from_entry_7'])} | {_e(t.get('paper_from_entry_7'))} |", "",
              "## Tables", "", tables_markdown(result), "",
              "## Torque validation (eq. 33, Fig. 4)", "",
              "| joint | " + " | ".join(f"J{j + 1}" for j in range(len(result.torque['rms']))) + " |",
              "|---|" + "---|" * len(result.torque["rms"]),
              "| RMS (N m) | " + " | ".join(f"{x:.3g}" for x in result.torque["rms"]) + " |",
              "| RMS without 1 s at each end | " + " | ".join(f"{x:.3g}" for x in result.torque["rms_interior"]) + " |",
              "| max (N m) | " + " | ".join(f"{x:.3g}" for x in result.torque["max"]) + " |", "",
              "![torque validation](fig4_torque_validation.png)", "", "![elements](fig6_elements.png)", "",
              "## The paper's pi_g in our Y_g", "",
              f"g_2 along the validation motion from eq. 29 against the source's: RMS "
              f"{result.published_g2['rms']:.3g} N m, max {result.published_g2['max']:.3g} N m (the source is "
              f"not the paper's arm unless it is its logged data).", "", "![g2](g2_published.png)", ""]
    (out / "report.md").write_text("\n".join(lines))
    return summary
