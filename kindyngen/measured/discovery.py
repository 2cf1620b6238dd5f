"""Name the effect a nominal model is missing: greedy forward selection over a library of
candidate effects, judged by time-blocked cross-validation, an information criterion that
does not count autocorrelated samples as independent, and a noise floor estimated from the
data.

The nominal description (geometry and inertial parameters) is taken as correct; its
prediction ``tau_nom = Y(q, qd, qdd) @ (P @ parameter_vector(model))`` is subtracted from the
measured torque and the residual ``r = tau - tau_nom`` is what candidate effects must explain.
Every candidate is a set of regressor columns, linear in its parameters, fitted *for all
joints at once* (per-joint parameters, one candidate = one block of columns):

=============================  ==========================  =====================================
candidate                      parameters                  torque on joint i
=============================  ==========================  =====================================
``viscous_friction``           ``fv1..fvn`` (>= 0)         ``fv_i qd_i``
``coulomb_friction``           ``fc1..fcn`` (>= 0)         ``fc_i sign(qd_i)`` (``tanh(qd/eps)``)
``torque_offset``              ``f01..f0n``                ``f0_i``
``armature``                   ``Ia1..Ian`` (>= 0)         ``Ia_i qdd_i``
``payload``                    ``payload_m .. payload_Izz``  the last 10 columns of ``Y @ P``
                                                           (a body on the flange; its 10
                                                           barycentric values add to the last
                                                           link's; pseudo-inertia kept positive
                                                           definite)
``base_tilt``                  ``dgx, dgy, dgz``           gravity torques of the nominal
                                                           parameters under ``g_nom + dg``
                                                           (exactly linear in ``g``)
``stribeck_friction``          ``fs1..fsn`` (>= 0, + vs)   ``fs_i exp(-(qd_i/vs)^2) sign(qd_i)``,
                                                           ``vs`` from :data:`STRIBECK_VS`, then
                                                           refined between the grid points
``position_ripple``            ``rs1.., rc1..``            ``rs_i sin(k q_i) + rc_i cos(k q_i)``
``load_dependent_friction``    ``fl1..fln`` (>= 0)         ``fl_i |tau_nom_i| sign(qd_i)``
``motor_side_elasticity``      ``ce1..cen`` (>= 0, peak    ``q_logged = q + ce_i tau_i``
                              deflection <= 0.05 rad)     (``ce = 1 / stiffness``): to first
                                                           order ``-D tau_nom . ce_i (tau_i,
                                                           taud_i, taudd_i) e_i``
``encoder_offset``             ``dq1..dqn`` (+-0.05 rad)   ``q_logged = q + dq_i``: ``-dtau_nom/
                                                           dq_i dq_i``
``torque_sensor_gain``         ``gt1..gtn`` (+-0.5)        ``tau_logged = (1 + gt_i) tau_i``:
                                                           ``gt_i tau_nom_i``
=============================  ==========================  =====================================

The last three act on the measurement, not the joint: their columns are directional
derivatives of the nominal torques by central differences (exact in qd and qdd), with the
joint torque ``tau_i`` taken from the low-passed measured torque (:func:`spring_torque`).

**Parallel filtering.**  Every column (and ``tau_nom``) is computed from each recording's
motion estimate (the low-passed q and its derivatives), then filtered with the recording's
*unfiltered* torque by the same linear filter and decimated
(:func:`kindyngen.measured.log_preparing.filtered_rows`).  ``sign(qd)`` of a filtered velocity
against a filtered torque would smear a Coulomb step into a spurious negative Stribeck dip;
a linear filter applied to both sides keeps every linear-in-parameters law exact.

Judgement (constants below; each rule says why):

* **Held-out error**: every recording cut into K contiguous time blocks (``folds``), fold k
  the k-th block of every recording (so the folds do not depend on the order of the
  recordings); fit on K-1, predict the held-out fold; out-of-fold predictions give a
  held-out RMS per joint.  Contiguous blocks because filtered, autocorrelated samples next to
  a training sample are not independent test data.
* **Physical domain**: every fit (selection, folds, final) holds the coefficients inside
  their range (table above) by bounded least squares; a payload whose free fit breaks
  positive definiteness is fitted again as a semidefinite program, not dropped.
* **Criterion**: ``BIC_eff = N_eff log(RSS / rows) + rank log(N_eff)`` with the effective
  sample size per joint ``N_eff = N / (1 + 2 sum_k rho_k)`` (autocorrelation of the
  residual of the larger model, summed up to the first non-positive lag), summed over joints.
  Both models of a comparison use the same ``N_eff``.
* **Noise floor** per joint: ``1.4826 median|d2 r| / sqrt(6)``, the robust (MAD) scale of
  the second difference of the *unfiltered* residual within each segment, times the noise
  gain of the parallel filter (:func:`kindyngen.measured.log_preparing.noise_gain`) (white noise of std s gives
  ``d2`` of std ``sqrt(6) s``; smooth effects contribute ``(omega dt)^2`` of their amplitude,
  sparse jumps such as Coulomb reversals are ignored by the median).  Torques low-passed
  before logging have correlated noise whose second difference is small: the floor is then
  an underestimate and the stop falls to the cross-validation rule.
* **Acceptance** of the best remaining candidate (the one with the lowest held-out MSE when
  fitted together with the already chosen ones): (a) held-out MSE (summed over joints) falls
  by at least :data:`MIN_RELATIVE_IMPROVEMENT`; (b) ``BIC_eff`` falls by at least
  :data:`BIC_MARGIN` (strong evidence on the Kass-Raftery scale); (c) its block of
  parameters is non-zero: the Wald statistic ``dRSS / s^2 * N_eff / rows`` exceeds the
  chi-square quantile :data:`WALD_P` of its rank; (d) it matters: some joint's held-out RMS
  falls by :data:`MATTER` noise floors.  At the end every chosen effect must still pass (a)
  and (d) against the fit without it (backward check).  Stop when no candidate passes, or when every
  joint's held-out RMS is within :data:`NOISE_STOP` times its noise floor, or the residual is
  at rounding level (:data:`ROUNDING`).
* **Indistinguishable**: another candidate is indistinguishable from the best when the
  fold-wise difference of their held-out MSE is within :data:`AMBIGUITY_SE` standard errors
  of zero, or within ``(AMBIGUITY_NOISE * floor)^2``, *and* the smallest principal angle
  between their columns (the chosen ones projected out) is at most
  :data:`AMBIGUITY_ANGLE_DEG`; every flag is re-examined at the end beside all the effects
  chosen after it.  Then nothing is *named*: the best
  member's columns stay in the fit (so the remaining residual keeps shrinking and
  ``rms_after`` is honest), the group goes to ``indistinguishable`` with a motion that would
  separate it (:func:`separating_motion`), and ``effects`` does not list it.  The principal
  angle between the two column spaces is reported with it.
* **Not determined**: a joint coefficient at a finite bound (or at 0 of ``[0, x]``), with a
  relative standard error above :data:`REL_STD_MAX`, a sensing one whose torque stays below
  :data:`MATTER` floors, or a compliance below :data:`NOISE_BIAS_FACTOR` times what the
  torque noise alone gives (:func:`elastic_noise_bias`) is reported as not determined
  (:func:`undetermined`), never as a value.
* **Verdict**: ``explained`` when every joint's final held-out RMS is within
  :data:`EXPLAINED_FACTOR` x its noise floor; else ``unexplained`` says, per joint, how far
  above and what the rest correlates with.

Example (runs in seconds; ``segments`` are :class:`kindyngen.measured.log_preparing.Segment`):

>>> from kindyngen.readers.yaml_description import load_robot                          # doctest: +SKIP
>>> d = discover(load_robot("robots/lwr4.yaml"), segments)          # doctest: +SKIP
>>> d.effects, d.indistinguishable                                  # doctest: +SKIP
(('viscous_friction',), ())
>>> d.values["fv2"], d.rms_after                                    # doctest: +SKIP
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np
from scipy.stats import chi2

from ..model.inertial_parameters import NAMES as BARYCENTRIC_NAMES
from ..model.inertial_parameters import parameter_vector
from ..model.robot_model import RobotModel
from .effect_columns import effect_columns, effect_names
from .log_preparing import Segment, filtered_rows, noise_gain, zero_phase_low_pass
from .regressor_rows import description_torques, torque_regressor

CANDIDATES = ("viscous_friction", "coulomb_friction", "torque_offset", "armature", "payload",
              "base_tilt", "stribeck_friction", "position_ripple", "load_dependent_friction",
              "motor_side_elasticity", "encoder_offset", "torque_sensor_gain")
#: candidates whose coefficients are physically non-negative: fitted with them held >= 0
#: (friction coefficients, the Stribeck excess over Coulomb, reflected inertia, compliance)
NONNEGATIVE_CANDIDATES = ("viscous_friction", "coulomb_friction", "armature", "stribeck_friction",
                          "load_dependent_friction", "motor_side_elasticity")


#: a torque sensor's relative gain error is fitted within +-TORQUE_GAIN_ERROR_MAX: one that
#: reads less than half (or 1.5 times) the torque is broken, not mis-scaled
TORQUE_GAIN_ERROR_MAX = 0.5
#: an encoder offset is fitted within +-ENCODER_OFFSET_MAX rad: the column is the first-order
#: term of tau(q - dq), whose neglected second-order part grows as dq^2 (0.25 % at 0.05 rad)
ENCODER_OFFSET_MAX = 0.05


def _bounds(candidate: str) -> tuple[float, float]:
    """The physical range of a candidate's coefficients (+-inf: no bound)."""
    if candidate in NONNEGATIVE_CANDIDATES:
        return 0.0, np.inf
    if candidate == "torque_sensor_gain":
        return -TORQUE_GAIN_ERROR_MAX, TORQUE_GAIN_ERROR_MAX
    if candidate == "encoder_offset":
        return -ENCODER_OFFSET_MAX, ENCODER_OFFSET_MAX
    if candidate == "motor_side_elasticity":
        return 0.0, ENCODER_OFFSET_MAX          # fitted as the peak deflection (rad), see _Rows
    return -np.inf, np.inf


def _public(key: str) -> str:
    """The candidate a block key stands for (``stribeck_friction@0.05`` -> ``stribeck_friction``)."""
    return key.split("@")[0]

#: Stribeck velocities tried (rad/s): at every step each is fitted with the chosen effects
#: and the one of lowest held-out error stands for the candidate (the choice counts as one
#: extra parameter in the criterion).
STRIBECK_VS = (0.02, 0.05, 0.1, 0.2, 0.5)
#: Ripple periods per radian of joint angle (``sin(k q)``, ``cos(k q)``).
RIPPLE_K = 6.0

#: (a) held-out MSE must fall by this fraction: below it a gain is within what re-fitting on
#: other folds varies by.
MIN_RELATIVE_IMPROVEMENT = 0.02
#: (b) BIC_eff must fall by this much (strong evidence).
BIC_MARGIN = 10.0
#: (c) right-tail probability of the chi-square test of the candidate's block (several
#: candidates are tested at each step: a small level keeps false positives rare).
WALD_P = 1e-4
#: stop once every joint's held-out RMS is within this factor of its noise floor.
NOISE_STOP = 1.2
#: residual RMS below this times the torque RMS is rounding, not an effect.
ROUNDING = 1e-9
#: ambiguity: held-out MSE gap within this many fold standard errors ...
AMBIGUITY_SE = 2.0
#: ... or a gap below (this fraction of the noise floor)^2 per joint, summed.
AMBIGUITY_NOISE = 0.1
#: ... and only when the two blocks' columns (the chosen ones projected out) are this close:
#: their smallest principal angle at most this many degrees (else the data can tell them
#: apart, and the fits' closeness is chance).
AMBIGUITY_ANGLE_DEG = 20.0
#: (d) a named effect must matter: some joint's held-out RMS falls by at least this many
#: noise floors (0.25: an effect of RMS 0.75 floors beside noise of one floor).
MATTER = 0.25
#: verdict: the data is explained when every joint's held-out RMS is within this factor of
#: its noise floor.
EXPLAINED_FACTOR = 1.5
#: a joint coefficient is *determined* by the data only when its relative standard error is
#: at most this (the value at least 3 standard errors from zero); otherwise it is reported as
#: not determined and model.yaml leaves it out (see :func:`undetermined`)
REL_STD_MAX = 1.0 / 3.0
#: ... and, for an elastic joint, only when its compliance is at least this many times what the
#: torque sensor's noise alone produces through the spring-torque column (errors in variables:
#: the column is built from the measured torque, whose noise the residual shares)
NOISE_BIAS_FACTOR = 3.0
#: eigenvalues of the column-scaled normal matrix below this times the largest are dropped
#: (minimum-norm solution: the payload's columns are rank-deficient among themselves).
RCOND = 1e-11

NOISE_METHOD = ("robust scale of the second difference of the unfiltered residual within each segment, "
                "1.4826 median|d2 r| / sqrt(6), times the noise gain of the parallel filter")

_SEPARATE = {
    frozenset({"payload", "base_tilt"}): "rotate the wrist (joints 5-7) through large angles at a few "
    "arm poses: a payload's gravity torque follows the flange orientation, a tilt's does not",
    frozenset({"payload", "torque_offset"}): "visit several poses far apart (joint 2 and 4 over most "
    "of their range): gravity torques of a payload change with the pose, an offset does not",
    frozenset({"base_tilt", "torque_offset"}): "swing joint 1 through a large angle: a tilted base's "
    "gravity torques vary with joint 1, an offset does not",
    frozenset({"coulomb_friction", "viscous_friction"}): "run the joints at several constant speeds "
    "(or a multisine with varied amplitudes): Coulomb friction does not grow with speed",
    frozenset({"coulomb_friction", "stribeck_friction"}): "include slow constant-speed sweeps (below "
    "and above the Stribeck velocity)",
    frozenset({"coulomb_friction", "load_dependent_friction"}): "move the same joint at the same speeds "
    "under very different loads (poses or accelerations)",
    frozenset({"position_ripple", "torque_offset"}): "move each joint over several ripple periods",
    frozenset({"armature", "payload"}): "accelerate the wrist joints hard at different poses",
}


def separating_motion(a: str, b: str) -> str:
    """What motion would tell candidate ``a`` from ``b`` (a sentence)."""
    return _SEPARATE.get(frozenset({a, b}), "a motion that excites the two candidates' columns differently "
                         "(larger range, several speeds, several poses)")


# ---------------------------------------------------------------------------------------------
# results

@dataclass(frozen=True, eq=False)
class Step:
    """One accepted (or ambiguous) step of the forward selection.

    ``effect``: the candidate fitted at this step; ``alternatives``: candidates that explain
    the residual about equally well (empty when the effect is named); ``parameter_names``,
    ``values``, ``std`` (std inflated by ``sqrt(rows / N_eff)``); ``rms_before``/``rms_after``:
    held-out RMS per joint (N m) before/after adding it; ``criterion_before``/``_after``:
    BIC_eff of the two models (same N_eff); ``improvement``: relative fall of the held-out
    MSE; ``wald``: the block statistic and its threshold; ``note``."""

    effect: str
    alternatives: tuple[str, ...]
    parameter_names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    rms_before: np.ndarray
    rms_after: np.ndarray
    criterion_before: float
    criterion_after: float
    improvement: float
    wald: tuple[float, float]
    note: str


@dataclass(frozen=True, eq=False)
class Discovery:
    """The outcome of :func:`discover`.

    ``effects``: the named effects in order (``()`` when none); ``fitted``: every candidate
    whose columns are in the final fit (the named ones plus one representative of each
    indistinguishable group); ``steps``; ``rms_before``/``rms_after``: held-out RMS per joint
    (N m) of the nominal model and of nominal + fitted effects; ``noise_floor`` per joint and
    ``noise_method``; ``indistinguishable``: tuple of ``(names, reason)``; ``notes``;
    ``values``/``std``: every fitted parameter by name (fv1.., fc1.., f01.., Ia1.. as in the
    description; payload_m, payload_mx, ... the barycentric values to add to the last link;
    dgx, dgy, dgz the gravity change); ``payload``: the 10 barycentric values (minimum norm
    where not identifiable) or None; ``payload_mass``: the payload mass when identifiable;
    ``gravity``: the fitted gravity vector (base_tilt) or None; ``tilt_deg``: (roll about x,
    pitch about y, total) in degrees, or None; ``n_eff``: effective samples per joint of the
    final residual; ``samples``; ``folds``."""

    effects: tuple[str, ...]
    fitted: tuple[str, ...]
    steps: tuple[Step, ...]
    rms_before: np.ndarray
    rms_after: np.ndarray
    noise_floor: np.ndarray
    noise_method: str
    indistinguishable: tuple[tuple[tuple[str, ...], str], ...]
    notes: tuple[str, ...]
    values: dict
    std: dict
    payload: np.ndarray | None
    payload_mass: float | None
    gravity: np.ndarray | None
    tilt_deg: tuple[float, float, float] | None
    n_eff: np.ndarray
    samples: int
    folds: int
    stribeck_vs: float | None = None    # the Stribeck velocity fitted for stribeck_friction, if fitted
    ripple_k: float = RIPPLE_K
    eps: float | None = None
    explained: bool = True              # every joint's held-out RMS within EXPLAINED_FACTOR x its floor
    unexplained: tuple[str, ...] = ()   # where the rest lives, one sentence per joint
    filtering: tuple[str, ...] = ()     # the parallel filters of the recordings (LowPass.describe)
    negligible: tuple[str, ...] = ()    # fitted coefficients whose own torque stays below MATTER floors
    #: joint coefficients the data does not determine, name -> why (not written to model.yaml)
    undetermined: dict = field(default_factory=dict)


def predict_effects(discovery: Discovery, model: RobotModel, q, qd, qdd, effects=None, spring=None) -> np.ndarray:
    """Torques (N, n) of the fitted ``effects`` (default: every fitted one) with the values
    of ``discovery``, along new motion: what the discovered model adds to the nominal one
    (to first order for the effects on the measurement).  ``spring``: the joint torque and its
    derivatives (:func:`spring_torque`), needed for ``motor_side_elasticity``."""
    effects = discovery.fitted if effects is None else tuple(effects)
    q, qd, qdd = (np.asarray(a, float) for a in (q, qd, qdd))
    if "motor_side_elasticity" in effects and spring is None:
        raise ValueError("motor_side_elasticity needs the joint torque: pass spring=spring_torque(tau, dt)")
    tau_nom = nominal_torques(model, q, qd, qdd)
    out = np.zeros_like(q)
    for name in effects:
        if name not in discovery.fitted:
            raise ValueError(f"{name} was not fitted (fitted: {', '.join(discovery.fitted) or 'none'})")
        columns, names, _ = _columns(name, model, q, qd, qdd, tau_nom, discovery.eps, discovery.ripple_k,
                                     discovery.stribeck_vs, spring)
        out += columns @ np.array([discovery.values[k] for k in names])
    return out


# ---------------------------------------------------------------------------------------------
# columns

def nominal_torques(model: RobotModel, q, qd, qdd) -> np.ndarray:
    """The description's rigid-body torques ``Y @ (P @ parameter_vector(model))``, (N, n)."""
    return description_torques(model, q, qd, qdd, effects=False)


def _gravity_columns(model: RobotModel, q) -> np.ndarray:
    """(N, n, 3): gravity torques of the nominal parameters under unit gravity along base x,
    y, z.  Each model is built with its own gravity (a tilted model's base map differs)."""
    full = parameter_vector(model)
    zero = np.zeros_like(q)
    out = []
    for g in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
        R = torque_regressor(replace(model, gravity=g))
        out.append(R(q, zero, zero) @ (R.base_map @ full))
    return np.stack(out, axis=2)


def _directional(torques, q, qd, qdd, dq, dqd, dqdd) -> np.ndarray:
    """Derivative of ``torques(q, qd, qdd)`` (N, n) along the motion change ``(dq, dqd, dqdd)``
    (N, n each), by central differences (exact in qdd and qd, where the torque is affine and
    quadratic; the step is 1e-5 rad of the largest position change, error ~1e-10 relative)."""
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
    tau_i``: ``tau_i``).  Columns of joint i's coefficient in column i."""
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
            # q_logged = q + dq_i: the true torque is tau(q_logged - dq_i e_i) ~ tau - dtau/dq_i dq_i
            dq[:, i] = 1.0
            out[:, :, i] = -_directional(torques, q, qd, qdd, dq, zero, zero)
        else:
            # q_logged = q + tau_i / K_i: the true motion is the logged one minus
            # (tau_i, taud_i, taudd_i) / K_i, linear in 1 / K_i to first order
            s, sd, sdd = spring
            dqd, dqdd = zero.copy(), zero.copy()
            dq[:, i], dqd[:, i], dqdd[:, i] = s[:, i], sd[:, i], sdd[:, i]
            out[:, :, i] = -_directional(torques, q, qd, qdd, dq, dqd, dqdd)
    return out, tuple(f"{'dq' if name == 'encoder_offset' else 'ce'}{i + 1}" for i in range(n))


def spring_of(segment) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint torque of a motor-side encoder's spring along a segment and its first two
    time derivatives: the low-passed measured torque (the joint torque itself, whatever the
    model misses).  Its noise correlates with the residual's: :func:`elastic_noise_bias`
    says how large a compliance that noise alone produces."""
    smooth = segment.tau if segment.low_pass is not None or len(segment.t) < 60 else \
        zero_phase_low_pass(segment.tau, 1.0 / segment.dt, min(5.0, 0.2 / segment.dt))
    return spring_torque(smooth, segment.dt)


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
    gives an elastic-joint fit: the least-squares coefficient of joint i's spring column
    built from noise (of the level :func:`noise_floor` finds in the segment's residual against
    ``torques(q, qd, qdd)``), against that noise, both through the segment's parallel filter,
    over the squared norm of the column built from the measured torque (``springs``, default
    :func:`spring_of` of each segment).  The spring column is made of the measured torque,
    whose noise the residual shares (errors in variables): a compliance not well above this
    is the noise's, not the joint's."""
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


def spring_torque(tau, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint torque seen by a motor-side encoder's spring and its first two time
    derivatives, from a smooth torque estimate ``tau`` (N, n) sampled every ``dt`` s (the
    nominal torque along the logged motion: free of the torque sensor's noise)."""
    tau = np.asarray(tau, float)
    if len(tau) < 3:
        return tau, np.zeros_like(tau), np.zeros_like(tau)
    d = np.gradient(tau, dt, axis=0, edge_order=2)
    return tau, d, np.gradient(d, dt, axis=0, edge_order=2)


def _columns(name, model, q, qd, qdd, tau_nom, eps, ripple_k, stribeck_vs, spring=None):
    """(columns (N, n, k), parameter names, detail text) of one candidate.  ``spring``: the
    joint torque and its derivatives (:func:`spring_torque`), for ``motor_side_elasticity``."""
    n = model.n
    if name in ("viscous_friction", "coulomb_friction", "torque_offset", "armature"):
        return effect_columns(name, qd, qdd, eps), effect_names(name, n), ""
    rows = np.arange(n)
    if name == "payload":
        R = torque_regressor(model)
        Yb = R(q, qd, qdd)
        P = R.base_map[:, -10:]               # the last link's 10 barycentric columns
        return Yb @ P, tuple(f"payload_{k}" for k in BARYCENTRIC_NAMES), ""
    if name == "base_tilt":
        return _gravity_columns(model, q), ("dgx", "dgy", "dgz"), ""
    if name in ("encoder_offset", "motor_side_elasticity"):
        out, names = sensing_columns(name, lambda *m: nominal_torques(model, *m), q, qd, qdd, spring)
        detail = "" if name == "encoder_offset" else "ce_i = 1 / K_i (rad per N m), K_i the joint stiffness"
        return out, names, detail
    if name in ("stribeck_friction", "position_ripple", "load_dependent_friction", "torque_sensor_gain"):
        if name == "stribeck_friction":
            values = [np.exp(-(qd / stribeck_vs) ** 2) * np.sign(qd)]
            names, detail = [f"fs{i + 1}" for i in range(n)], f"vs = {stribeck_vs:.3g} rad/s"
        elif name == "position_ripple":
            values = [np.sin(ripple_k * q), np.cos(ripple_k * q)]
            names = [f"rs{i + 1}" for i in range(n)] + [f"rc{i + 1}" for i in range(n)]
            detail = f"k = {ripple_k:g} periods per rad"
        elif name == "torque_sensor_gain":
            # tau_logged = (1 + gt_i) tau_i: the relative gain error times the joint torque
            values, names, detail = [tau_nom], [f"gt{i + 1}" for i in range(n)], "gt_i: relative gain error"
        else:
            values, names, detail = [np.abs(tau_nom) * np.sign(qd)], [f"fl{i + 1}" for i in range(n)], ""
        out = np.zeros((len(q), n, n * len(values)))
        for k, v in enumerate(values):
            out[:, rows, k * n + rows] = v
        return out, tuple(names), detail
    raise ValueError(f"unknown candidate {name!r} (known: {', '.join(CANDIDATES)})")


# ---------------------------------------------------------------------------------------------
# statistics

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


def _bounded_solve(G, b, lower, upper):
    """Minimise ``th' G th - 2 b' th`` with ``lower <= th <= upper``: bounded least squares
    on the square root of ``G`` (eigen-decomposition, so a singular ``G`` is fine)."""
    from scipy.optimize import lsq_linear
    w, V = np.linalg.eigh(G)
    keep = w > RCOND * max(w.max(), 1e-300)
    root = np.sqrt(w[keep])[:, None] * V[:, keep].T
    target = (V[:, keep].T @ b) / np.sqrt(w[keep])
    return lsq_linear(root, target, bounds=(lower, upper), method="bvls").x


class _Problem:
    """All candidate columns stacked once; fits of any subset via Gram matrices, inside the
    physical domain (coefficients flagged non-negative are held >= 0).

    ``fold_of``: the fold of every row (each recording cut into ``folds`` contiguous time
    blocks, fold k the k-th block of every recording: the same folds whatever the order of
    the recordings)."""

    def __init__(self, blocks, r, fold_of, folds):
        self.N, self.n = r.shape
        self.r = r
        self.blocks = blocks
        A = np.concatenate([b[0] for b in blocks.values()], axis=2) if blocks else np.zeros((self.N, self.n, 0))
        self.slices, start = {}, 0
        lower = []                               # (low, high) per column
        for name, (cols, _, _) in blocks.items():
            self.slices[name] = np.arange(start, start + cols.shape[2])
            start += cols.shape[2]
            lower += [_bounds(_public(name))] * cols.shape[2]
        scale = np.sqrt(np.sum(A ** 2, axis=(0, 1)))
        self.scale = np.where(scale > 0, 1.0 / np.where(scale > 0, scale, 1), 0.0)
        bounds = np.array(lower, float).reshape(-1, 2)
        # bounds on the scaled unknowns theta = value / scale (a zero column is free)
        live = np.where(self.scale > 0, self.scale, 1.0)
        self.lower = np.where(self.scale > 0, bounds[:, 0] / live, -np.inf)
        self.upper = np.where(self.scale > 0, bounds[:, 1] / live, np.inf)
        self.A = A * self.scale                  # unit columns (zero columns stay zero)
        self.fold_rows = [np.flatnonzero(fold_of == k) for k in range(folds)]
        A2 = self.A.reshape(self.N * self.n, -1)
        r2 = r.reshape(-1)
        self.G = A2.T @ A2
        self.b = A2.T @ r2
        self.Gf, self.bf = [], []
        for rows in self.fold_rows:
            Af = self.A[rows].reshape(len(rows) * self.n, -1)
            self.Gf.append(Af.T @ Af)
            self.bf.append(Af.T @ r[rows].reshape(-1))

    def columns(self, names):
        return np.concatenate([self.slices[c] for c in names]) if names else np.zeros(0, int)

    def _solve(self, G, b, idx):
        """Solution in the physical domain and pseudo-inverse of the normal equations; rank."""
        if len(b) == 0:
            return np.zeros(0), np.zeros((0, 0)), 0
        w, V = np.linalg.eigh(G)
        keep = w > RCOND * max(w.max(), 1e-300)
        inv = (V[:, keep] / w[keep]) @ V[:, keep].T
        theta = inv @ b
        lower, upper = self.lower[idx], self.upper[idx]
        if np.any(theta < lower) or np.any(theta > upper):
            theta = _bounded_solve(G, b, lower, upper)
        return theta, inv, int(keep.sum())

    def fit(self, names):
        """Full-data fit and out-of-fold residuals of the candidates ``names``."""
        idx = self.columns(names)
        theta, inv, rank = self._solve(self.G[np.ix_(idx, idx)], self.b[idx], idx)
        residual = self.r - self.A[:, :, idx] @ theta
        oof = np.empty_like(self.r)
        for rows, Gf, bf in zip(self.fold_rows, self.Gf, self.bf):
            th, _, _ = self._solve((self.G - Gf)[np.ix_(idx, idx)], (self.b - bf)[idx], idx)
            oof[rows] = self.r[rows] - self.A[rows][:, :, idx] @ th
        fold_mse = np.array([np.sum(np.mean(oof[rows] ** 2, axis=0)) for rows in self.fold_rows])
        return dict(names=tuple(names), idx=idx, theta=theta, inv=inv, rank=rank, residual=residual,
                    rss=float(np.sum(residual ** 2)), oof=oof, fold_mse=fold_mse,
                    heldout=np.sqrt(np.mean(oof ** 2, axis=0)), mse=float(np.sum(np.mean(oof ** 2, axis=0))))

    def criterion(self, fit, n_eff_total):
        rows = self.N * self.n
        return float(n_eff_total * math.log(max(fit["rss"], 1e-300) / rows) + fit["rank"] * math.log(n_eff_total))


#: smallest eigenvalue (kg m^2) the payload's pseudo-inertia is held to in the constrained fit
PAYLOAD_EPSILON = 1e-6


def _physical_payload(problem: _Problem, fit: dict):
    """When the fitted payload's pseudo-inertia is not positive definite: the fit again with
    it held >= PAYLOAD_EPSILON (a semidefinite program, CLARABEL through cvxpy), the other
    non-negative coefficients >= 0.  Returns (fit, note) or None when the free fit is
    physical already."""
    from .consistent import pseudo_inertia
    idx = fit["idx"]
    own = problem.slices["payload"]
    where = np.searchsorted(idx, own) if np.all(np.isin(own, idx)) else None
    if where is None:
        return None
    values = fit["theta"] * problem.scale[idx]
    if np.linalg.eigvalsh(pseudo_inertia(values[where]))[0] >= PAYLOAD_EPSILON:
        return None
    import cvxpy as cp
    G, b = problem.G[np.ix_(idx, idx)], problem.b[idx]
    w, V = np.linalg.eigh(G)
    keep = w > RCOND * max(w.max(), 1e-300)
    root = np.sqrt(w[keep])[:, None] * V[:, keep].T
    target = (V[:, keep].T @ b) / np.sqrt(w[keep])
    T = np.stack([pseudo_inertia(np.eye(10)[k]).reshape(16) for k in range(10)], axis=1)
    x = cp.Variable(len(idx))                    # scaled unknowns, as the fit's theta
    body = cp.multiply(problem.scale[idx][where], x[where])
    J = cp.reshape(T @ body, (4, 4), order="C")
    constraints = [0.5 * (J + J.T) >> PAYLOAD_EPSILON * np.eye(4)]
    lower, upper = problem.lower[idx], problem.upper[idx]
    for bound, sign in ((lower, 1), (upper, -1)):
        k = np.flatnonzero(np.isfinite(bound))
        if k.size:
            constraints.append(sign * (x[k] - bound[k]) >= 0)
    cp.Problem(cp.Minimize(cp.sum_squares(root @ x - target)), constraints).solve(solver="CLARABEL")
    if x.value is None:
        return None
    theta = np.asarray(x.value, float)
    residual = problem.r - problem.A[:, :, idx] @ theta
    before = float(np.linalg.eigvalsh(pseudo_inertia(values[where]))[0])
    out = dict(fit, theta=theta, residual=residual, rss=float(np.sum(residual ** 2)))
    return out, (f"payload: the free fit's pseudo-inertia has smallest eigenvalue {before:.3g} kg m^2; fitted "
                 f"again inside the physical domain (pseudo-inertia >= {PAYLOAD_EPSILON:g} kg m^2, a semidefinite "
                 f"program): full-data RMS {math.sqrt(fit['rss'] / residual.size):.4g} -> "
                 f"{math.sqrt(out['rss'] / residual.size):.4g} N m")


def _principal_cosine(A, B) -> float:
    """Cosine of the smallest principal angle between the column spaces of A and B (rows x k)."""
    def basis(M):
        if M.shape[1] == 0:
            return M
        U, s, _ = np.linalg.svd(M, full_matrices=False)
        return U[:, s > 1e-8 * max(s.max(), 1e-300)]
    Qa, Qb = basis(A), basis(B)
    if Qa.shape[1] == 0 or Qb.shape[1] == 0:
        return 0.0
    return float(np.linalg.svd(Qa.T @ Qb, compute_uv=False).max())


# ---------------------------------------------------------------------------------------------
# the search

class _Rows:
    """Every recording's candidate columns, computed from its motion estimate and filtered
    together with its unfiltered torque (:func:`kindyngen.measured.log_preparing.filtered_rows`)."""

    #: signals filtered alongside, for the "what the residual left correlates with" verdict
    SIGNALS = ("q", "qd", "qdd", "sign(qd)", "nominal torque")

    def __init__(self, model, segments, folds, eps, ripple_k, need_spring):
        self.model, self.segments, self.eps, self.ripple_k = model, tuple(segments), eps, ripple_k
        self.motion, self.spring = [], []
        nominal, measured, signals, fold_of, floors, weights = [], [], [], [], [], []
        for seg in self.segments:
            q, qd, qdd = seg.q, seg.qd, seg.qdd
            tau_nom = nominal_torques(model, q, qd, qdd)
            raw = seg.tau_unfiltered if seg.low_pass is not None else seg.tau
            self.spring.append(spring_of(seg) if need_spring else None)
            self.motion.append((q, qd, qdd, tau_nom))
            stack = np.stack([tau_nom, q, qd, qdd, np.sign(qd), tau_nom], axis=2)
            _, F, tau_f = filtered_rows(seg, stack)
            nominal.append(F[:, :, 0])
            signals.append(F[:, :, 1:])
            measured.append(tau_f)
            m = len(tau_f)
            fold_of.append(np.minimum((np.arange(m) * folds) // m, folds - 1))
            floors.append(noise_floor(raw - tau_nom, [len(raw)]) * noise_gain(seg.low_pass))
            weights.append(m)
        # motor_side_elasticity is fitted as the peak deflection ce_i max|tau_i| (rad), so that
        # its bound is the first-order model's range of validity, as for an encoder offset
        self.spring_peak = (np.max([np.max(np.abs(sp[0]), axis=0) for sp in self.spring], axis=0)
                            if need_spring else None)
        self.nominal = np.concatenate(nominal)
        self.tau = np.concatenate(measured)
        self.signals = np.concatenate(signals)
        self.fold_of = np.concatenate(fold_of)
        w = np.array(weights, float)[:, None]
        self.floor = np.sqrt(np.sum(w * np.array(floors) ** 2, axis=0) / w.sum())
        self.low_pass = tuple(dict.fromkeys(s.low_pass.describe() for s in self.segments if s.low_pass))

    def block(self, key, vs=None):
        """(filtered columns (rows, n, k), names, detail) of one candidate key."""
        name = _public(key)
        if vs is None and "@" in key:
            vs = float(key.split("@")[1])
        parts, names, detail = [], (), ""
        for seg, (q, qd, qdd, tau_nom), spring in zip(self.segments, self.motion, self.spring):
            cols, names, detail = _columns(name, self.model, q, qd, qdd, tau_nom, self.eps, self.ripple_k, vs, spring)
            if name == "motor_side_elasticity":
                cols = cols / self.peak()
            parts.append(filtered_rows(seg, cols)[1])
        return np.concatenate(parts), names, detail

    def elasticity_noise_bias(self) -> np.ndarray:
        """Per joint, the compliance the torque noise alone gives (:func:`elastic_noise_bias`)."""
        return elastic_noise_bias(lambda *m: nominal_torques(self.model, *m), self.segments, self.spring)

    def peak(self) -> np.ndarray:
        """Per joint, the largest |joint torque| (N m; 1 where it is zero)."""
        return np.where(self.spring_peak > 0, self.spring_peak, 1.0)

    def natural(self, key, values) -> np.ndarray:
        """A block's fitted values in the candidate's own units (a peak deflection -> ce)."""
        return values / self.peak() if _public(key) == "motor_side_elasticity" else values


#: candidates whose coefficients are one per joint (the ones judged by :func:`undetermined`)
_WHOLE_BODY = ("payload", "base_tilt")
#: candidates on the measurement, whose coefficient must also change some torque to be written
SENSING = ("motor_side_elasticity", "encoder_offset", "torque_sensor_gain")


def undetermined(blocks: dict, values: dict, std: dict, fitted: dict, negligible=(), elastic_bias=None) -> dict:
    """The joint coefficients the data does not determine, name -> why: not to be written as
    values.  ``blocks``: candidate -> its parameter names; ``values``/``std``: natural values
    and standard deviations; ``fitted``: the values as fitted (the bounds apply to these);
    ``negligible``: coefficients whose own torque stays below :data:`MATTER` noise floors;
    ``elastic_bias``: per joint, the compliance the torque noise alone produces
    (:meth:`_Rows.elasticity_noise_bias`).  A coefficient is undetermined when it sits at a
    finite bound of its physical range (the data pulls beyond it), or at 0 of a range [0, x]
    (nothing there, or not resolved), when its relative standard error exceeds
    :data:`REL_STD_MAX`, when it is a sensing coefficient that changes no torque above the
    noise, or a compliance not :data:`NOISE_BIAS_FACTOR` times above the noise's own.

    >>> undetermined({"viscous_friction": ("fv1", "fv2")}, {"fv1": 0.5, "fv2": 0.01},
    ...              {"fv1": 0.01, "fv2": 0.02}, {"fv1": 0.5, "fv2": 0.01})
    {'fv2': 'relative standard error 2 > 0.33'}
    """
    out = {}
    for candidate, names in blocks.items():
        if candidate in _WHOLE_BODY:
            continue
        low, high = _bounds(candidate)
        width = high - low if math.isfinite(high - low) else max(abs(fitted[nm]) for nm in names) or 1.0
        for i, nm in enumerate(names):
            v, e, f = values[nm], std.get(nm, 0.0), fitted[nm]
            reasons = []
            if math.isfinite(high) and abs(f - high) <= 1e-6 * width or \
                    low < 0 and math.isfinite(low) and abs(f - low) <= 1e-6 * width:
                reasons.append(f"at the edge of its physical range [{low:g}, {high:g}]: the data pulls beyond it")
            elif low == 0 and abs(f) <= 1e-9 * width:
                reasons.append("at 0, the edge of its physical range: absent, or not resolved")
            elif v == 0 or e / abs(v) > REL_STD_MAX:
                rel = math.inf if v == 0 else e / abs(v)
                reasons.append(f"relative standard error {rel:.2g} > {REL_STD_MAX:.2g}")
            if candidate in SENSING and nm in negligible:
                reasons.append(f"its torque stays below {MATTER:g} noise floors on every joint")
            if candidate == "motor_side_elasticity" and elastic_bias is not None and \
                    abs(v) < NOISE_BIAS_FACTOR * elastic_bias[i]:
                reasons.append(f"the torque sensor's noise alone gives ce = {elastic_bias[i]:.3g} through the "
                               f"spring torque (needs {NOISE_BIAS_FACTOR:g} x that): the joint's torque is too small "
                               f"against the noise to show its spring")
            if reasons:
                out[nm] = "; ".join(reasons)
    return out


def _where(fit, floor, signals, factor, rounding) -> tuple[str, ...]:
    """Sentences on the joints whose residual stays above ``factor`` x floor (and above the
    rounding level ``rounding``, N m), and what it correlates with most (filtered signals of
    that joint)."""
    out = []
    residual = fit["residual"]
    for j in np.flatnonzero((fit["heldout"] > factor * floor) & (fit["heldout"] > rounding)):
        r = residual[:, j] - residual[:, j].mean()
        corr = []
        for k, label in enumerate(_Rows.SIGNALS):
            x = signals[:, j, k] - signals[:, j, k].mean()
            den = float(np.linalg.norm(r) * np.linalg.norm(x))
            corr.append((abs(float(r @ x)) / den if den > 0 else 0.0, label))
        c, label = max(corr)
        out.append(f"joint {j + 1}: held-out RMS {fit['heldout'][j]:.3g} N m = {fit['heldout'][j] / max(floor[j], 1e-300):.3g} x "
                   f"its noise floor {floor[j]:.3g}; correlates most with its {label} (|r| = {c:.2f})")
    return tuple(out)


def discover(model: RobotModel, segments: Sequence[Segment], candidates: Sequence[str] = CANDIDATES,
             folds: int = 5, progress: Callable[[str], None] | None = None, eps: float | None = None,
             *, ripple_k: float = RIPPLE_K, stribeck_vs: Sequence[float] = STRIBECK_VS) -> Discovery:
    """Which of ``candidates`` does the nominal ``model`` miss on ``segments``?  See the module
    text for the rules.  ``segments``: one or more recordings' segments, each filtered on
    its own (a segment with a ``low_pass`` is parallel-filtered here); ``eps``: Coulomb
    smoothing (rad/s) of the Coulomb candidate (None: ``sign``); the description's own
    declared effects are assumed absent (a note says so when it declares some)."""
    progress = progress or (lambda text: None)
    candidates = tuple(dict.fromkeys(candidates))
    for c in candidates:
        if c not in CANDIDATES:
            raise ValueError(f"unknown candidate {c!r} (known: {', '.join(CANDIDATES)})")
    segments = tuple(segments)
    if not segments:
        raise ValueError("discover needs at least one segment")
    if folds < 2:
        raise ValueError("folds must be at least 2")
    notes = []
    if model.effects:
        notes.append(f"the description declares {', '.join(model.effects)}: ignored here (rigid bodies only "
                     f"are the nominal prediction)")
    progress("nominal prediction and candidate columns (parallel filtering)")
    data = _Rows(model, segments, folds, eps, ripple_k, "motor_side_elasticity" in candidates)
    N, n = data.tau.shape
    if N < 10 * folds:
        raise ValueError(f"{N} samples are too few for {folds} folds")
    r = data.tau - data.nominal
    floor = data.floor
    scale = float(np.sqrt(np.mean(data.tau ** 2))) or 1.0
    # one block of columns per candidate; the Stribeck candidate has one per velocity of the
    # grid, and at every step the velocity with the lowest held-out error stands for it
    blocks, variants = {}, {}
    for c in candidates:
        for vs in (tuple(stribeck_vs) if c == "stribeck_friction" else (None,)):
            key = c if vs is None else f"{c}@{vs:g}"
            blocks[key] = data.block(key)
            variants.setdefault(c, []).append(key)
    details = {key: b[2] for key, b in blocks.items()}
    problem = _Problem(blocks, r, data.fold_of, folds)
    extra_k = {"stribeck_friction": 1 if len(stribeck_vs) > 1 else 0}
    A2 = problem.A.reshape(N * n, -1)

    def angle(key_a, key_b, base_keys) -> float:
        """Smallest principal angle (deg) between two blocks once ``base_keys``' columns are
        projected out."""
        B = A2[:, problem.columns(base_keys)]

        def proj_out(M):
            if B.shape[1] == 0:
                return M
            coef, *_ = np.linalg.lstsq(B, M, rcond=None)
            return M - B @ coef
        cos = _principal_cosine(proj_out(A2[:, problem.columns([key_a])]), proj_out(A2[:, problem.columns([key_b])]))
        return math.degrees(math.acos(min(1.0, cos)))

    def close_fits(fa, fb) -> tuple[bool, float, float]:
        d = fa["fold_mse"] - fb["fold_mse"]
        gap, se = float(d.mean()), float(d.std(ddof=1) / math.sqrt(len(d)))
        small = float(np.sum((AMBIGUITY_NOISE * floor) ** 2))
        return (gap <= AMBIGUITY_SE * se or gap <= small), gap, se

    def matters(before, after) -> float:
        """Largest fall of a joint's held-out RMS, in noise floors."""
        return float(np.max((before["heldout"] - after["heldout"]) / np.maximum(floor, 1e-300)))

    current = problem.fit(())
    rms_before = current["heldout"].copy()
    chosen, steps, flagged = [], [], {}         # chosen: block keys; flagged: key -> alternatives
    remaining = [c for c in candidates if any(np.any(problem.A[:, :, problem.slices[k]]) for k in variants[c])]
    for c in candidates:
        if c not in remaining:
            notes.append(f"{c}: its columns vanish on this motion (not tried)")

    def at_floor(fit) -> str | None:
        if np.all(np.sqrt(np.mean(fit["residual"] ** 2, axis=0)) <= ROUNDING * scale):
            return "the residual is at rounding level"
        if np.all(fit["heldout"] <= NOISE_STOP * floor):
            return f"every joint's held-out RMS is within {NOISE_STOP}x its noise floor"
        return None

    while remaining:
        reason = at_floor(current)
        if reason:
            notes.append(f"stopped: {reason}")
            break
        progress(f"step {len(steps) + 1}: trying {', '.join(remaining)}")
        trials, key_of = {}, {}
        for c in remaining:
            fits = [(problem.fit(chosen + [k]), k) for k in variants[c]]
            trials[c], key_of[c] = min(fits, key=lambda f: f[0]["mse"])
        best = min(remaining, key=lambda c: trials[c]["mse"])
        best_key = key_of[best]
        fit = trials[best]
        n_eff = effective_samples(fit["residual"])
        n_eff_total = float(n_eff.sum())
        rows = N * n
        k_extra = extra_k.get(best, 0)
        crit_before = problem.criterion(current, n_eff_total)
        crit_after = problem.criterion(fit, n_eff_total) + k_extra * math.log(n_eff_total)
        improvement = 1.0 - fit["mse"] / current["mse"] if current["mse"] > 0 else 0.0
        dof = max(rows - fit["rank"], 1)
        s2 = fit["rss"] / dof
        wald = (current["rss"] - fit["rss"]) / max(s2, 1e-300) * n_eff_total / rows
        r_block = max(fit["rank"] - current["rank"], 1)
        wald_threshold = float(chi2.isf(WALD_P, r_block))
        gain = matters(current, fit)
        failed = []
        if improvement < MIN_RELATIVE_IMPROVEMENT:
            failed.append(f"held-out MSE falls by {100 * improvement:.3g} % < {100 * MIN_RELATIVE_IMPROVEMENT:g} %")
        if crit_after > crit_before - BIC_MARGIN:
            failed.append(f"BIC_eff changes by {crit_after - crit_before:.4g} (needs < -{BIC_MARGIN:g})")
        if wald < wald_threshold:
            failed.append(f"Wald {wald:.4g} < {wald_threshold:.4g}")
        if gain < MATTER:
            failed.append(f"no joint's held-out RMS falls by {MATTER:g} noise floors (largest fall {gain:.3g})")
        if failed:
            notes.append(f"stopped: best remaining candidate {best} rejected ({'; '.join(failed)})")
            break
        # indistinguishable: a held-out error about as low as the best's AND columns that
        # (after the chosen ones are projected out) nearly span the same space
        alternatives, reasons = [], []
        for c in remaining:
            if c == best:
                continue
            close, gap, se = close_fits(trials[c], fit)
            if not close:
                continue
            deg = angle(best_key, key_of[c], chosen)
            if deg > AMBIGUITY_ANGLE_DEG:
                continue
            alternatives.append(c)
            reasons.append(f"{c}: held-out MSE {trials[c]['mse']:.4g} vs {fit['mse']:.4g} "
                           f"(gap {gap:.3g} +- {se:.3g}, fold standard error), smallest principal angle "
                           f"{deg:.3g} deg; to separate: {separating_motion(best, c)}")
        idx = fit["idx"]
        cov_scale = s2 * rows / n_eff_total
        values = fit["theta"] * problem.scale[idx]
        std = np.sqrt(np.maximum(np.diag(fit["inv"]), 0) * cov_scale) * problem.scale[idx]
        own = np.isin(idx, problem.slices[best_key])
        note = details.get(best_key, "")
        if alternatives:
            flagged[best_key] = (tuple(alternatives), "; ".join(reasons))
            note = (note + "; " if note else "") + f"indistinguishable from {', '.join(alternatives)}: not named"
        steps.append(Step(effect=best, alternatives=tuple(alternatives),
                          parameter_names=blocks[best_key][1], values=data.natural(best_key, values[own]),
                          std=data.natural(best_key, std[own]),
                          rms_before=current["heldout"], rms_after=fit["heldout"],
                          criterion_before=crit_before, criterion_after=crit_after, improvement=improvement,
                          wald=(float(wald), wald_threshold), note=note))
        chosen.append(best_key)
        remaining.remove(best)
        current = fit

    # backward check: every chosen effect must still matter beside all the others
    changed = True
    while changed and len(chosen) > 1:
        changed = False
        worst, worst_gain = None, None
        for k in chosen:
            without = problem.fit([c for c in chosen if c != k])
            rise = 1.0 - current["mse"] / without["mse"] if without["mse"] > 0 else 0.0
            g = matters(without, current)
            if rise < MIN_RELATIVE_IMPROVEMENT or g < MATTER:
                if worst is None or g < worst_gain:
                    worst, worst_gain = k, g
        if worst is not None:
            chosen.remove(worst)
            flagged.pop(worst, None)
            current = problem.fit(chosen)
            notes.append(f"{_public(worst)}: dropped in the final check (without it no joint's held-out RMS rises "
                         f"by {MATTER:g} noise floors beside the other effects; largest rise {worst_gain:.3g})")
            changed = True

    # re-examine every flagged ambiguity in the final context: swap the stand-in for each
    # alternative while keeping every other chosen effect
    groups = []
    for key, (alternatives, _) in list(flagged.items()):
        others = [c for c in chosen if c != key]
        still, reasons = [], []
        for c in alternatives:
            if any(_public(k) == c for k in chosen):
                continue                          # chosen as well later: both are in the fit
            swapped, alt_key = min(((problem.fit(others + [k]), k) for k in variants[c]),
                                   key=lambda f: f[0]["mse"])
            close, gap, se = close_fits(swapped, current)
            deg = angle(key, alt_key, others)
            if close and deg <= AMBIGUITY_ANGLE_DEG:
                still.append(c)
                reasons.append(f"{c}: held-out MSE {swapped['mse']:.4g} vs {current['mse']:.4g} with the other "
                               f"effects (gap {gap:.3g} +- {se:.3g}), smallest principal angle {deg:.3g} deg; to "
                               f"separate: {separating_motion(_public(key), c)}")
        if still:
            groups.append(((_public(key),) + tuple(still),
                           "explain the residual about equally well: " + "; ".join(reasons)))
        else:
            flagged.pop(key)
            notes.append(f"{_public(key)}: named after all (re-examined beside the effects chosen after it, its "
                         f"alternatives no longer explain the data as well or their columns differ)")
    named = [_public(k) for k in chosen if k not in flagged]

    # the Stribeck velocity between the grid points: 1-D search of the final fit's RSS
    stribeck_key = next((k for k in chosen if k.startswith("stribeck")), None)
    vs_final = None
    final_blocks = {k: blocks[k] for k in chosen}
    if stribeck_key is not None:
        from scipy.optimize import minimize_scalar
        grid = sorted(float(v) for v in stribeck_vs)
        vs0 = float(stribeck_key.split("@")[1])
        i = grid.index(vs0)
        lo = grid[i - 1] if i > 0 else vs0 / 2
        hi = grid[i + 1] if i + 1 < len(grid) else vs0 * 2
        others = {k: blocks[k] for k in chosen if k != stribeck_key}

        def rss_at(log_vs):
            trial = dict(others)
            trial["stribeck_friction"] = data.block("stribeck_friction", math.exp(log_vs))
            return problem_for(trial).fit(list(trial))["rss"]

        def problem_for(bl):
            return _Problem(bl, r, data.fold_of, folds)
        best_log = minimize_scalar(rss_at, bounds=(math.log(lo), math.log(hi)), method="bounded",
                                   options={"xatol": 1e-3}).x
        vs_final = float(math.exp(best_log))
        final_blocks = {}
        for k in chosen:
            final_blocks[k] = (data.block("stribeck_friction", vs_final) if k == stribeck_key else blocks[k])
        details[stribeck_key] = f"vs = {vs_final:.3g} rad/s (refined between the grid points {lo:g} and {hi:g})"
    final_problem = _Problem(final_blocks, r, data.fold_of, folds) if chosen else problem
    final = final_problem.fit(list(final_blocks) if chosen else [])
    if "payload" in final_blocks:
        physical = _physical_payload(final_problem, final)
        if physical is not None:
            final, text = physical
            notes.append(text)

    # final values of every fitted candidate
    idx = final["idx"]
    rows = N * n
    n_eff = effective_samples(final["residual"])
    s2 = final["rss"] / max(rows - final["rank"], 1)
    values = final["theta"] * final_problem.scale[idx] if len(idx) else np.zeros(0)
    std = (np.sqrt(np.maximum(np.diag(final["inv"]), 0) * s2 * rows / n_eff.sum()) * final_problem.scale[idx]
           if len(idx) else np.zeros(0))
    names = [name for c in chosen for name in final_blocks[c][1]]
    fitted_values = dict(zip(names, map(float, values)))      # as fitted (bounds apply to these)
    natural = np.concatenate([data.natural(c, values[final_problem.slices[c]]) for c in chosen]) \
        if chosen else np.zeros(0)
    value_of = dict(zip(names, map(float, natural)))
    for k in chosen:
        low, high = _bounds(_public(k))
        if not (math.isfinite(low) and math.isfinite(high)):
            continue
        edges = (low, high) if low < 0 else (high,)      # a coefficient at 0 of [0, x] is just absent
        pinned = [nm for nm in final_blocks[k][1]
                  if any(abs(fitted_values[nm] - e) <= 1e-6 * (high - low) for e in edges)]
        if pinned:
            notes.append(f"{_public(k)}: {', '.join(pinned)} at the edge of the physical range [{low:g}, {high:g}]: "
                         f"the data pulls beyond it, so read these as standing in for something else (an error "
                         f"of the nominal model, an effect outside the library)")
    # per coefficient, whether its own torque matters (MATTER noise floors on some joint):
    # a joint's spring or gain that changes nothing above the noise stays ideal in model.yaml
    negligible = []
    for c in chosen:
        for k, nm in zip(final_problem.slices[c], final_blocks[c][1]):
            contribution = np.sqrt(np.mean((final_problem.A[:, :, k] * final["theta"][k]) ** 2, axis=0))
            if np.all(contribution < MATTER * np.maximum(floor, 1e-300)):
                negligible.append(nm)
    std_natural = np.concatenate([data.natural(c, std[final_problem.slices[c]]) for c in chosen]) \
        if chosen else np.zeros(0)
    std_of = dict(zip(names, map(float, std_natural)))
    bias = data.elasticity_noise_bias() if any(_public(k) == "motor_side_elasticity" for k in chosen) else None
    not_determined = undetermined(
        {_public(k): final_blocks[k][1] for k in chosen}, value_of, std_of,
        {nm: fitted_values[nm] for nm in names}, negligible, bias)
    payload = payload_mass = gravity = tilt = None
    fitted = tuple(_public(k) for k in chosen)
    for k in chosen:
        if details[k]:
            notes.append(f"{_public(k)}: {details[k]}")
    if "payload" in fitted:
        payload = np.array([value_of[f"payload_{k}"] for k in BARYCENTRIC_NAMES])
        # the mass is identifiable when its direction has no part in the fit's null space
        G = final_problem.G[np.ix_(idx, idx)]
        w, V = np.linalg.eigh(G)
        null = V[:, w <= RCOND * w.max()]
        e = (idx == final_problem.slices["payload"][0]).astype(float)
        if null.shape[1] == 0 or np.linalg.norm(null.T @ e) < 1e-6:
            payload_mass = float(payload[0])
        else:
            notes.append("payload mass not identifiable on this motion (only combinations of the flange "
                         "body's parameters are)")
    if "base_tilt" in fitted:
        g0 = np.array([float(v) for v in model.gravity])
        gravity = g0 + np.array([value_of["dgx"], value_of["dgy"], value_of["dgz"]])
        total = math.degrees(math.acos(np.clip(g0 @ gravity / (np.linalg.norm(g0) * np.linalg.norm(gravity)), -1, 1)))
        # roll about base x and pitch about base y of a base whose level gravity is -z
        roll = math.degrees(math.atan2(-gravity[1], -gravity[2]))
        pitch = math.degrees(math.atan2(gravity[0], -gravity[2]))
        tilt = (roll, pitch, total)
    unexplained = _where(final, floor, data.signals, EXPLAINED_FACTOR, 1e3 * ROUNDING * scale)
    return Discovery(effects=tuple(named), fitted=fitted, steps=tuple(steps), rms_before=rms_before,
                     rms_after=final["heldout"], noise_floor=floor, noise_method=NOISE_METHOD,
                     indistinguishable=tuple(groups), notes=tuple(notes), values=value_of, std=std_of,
                     payload=payload, payload_mass=payload_mass, gravity=gravity, tilt_deg=tilt, n_eff=n_eff,
                     samples=N, folds=folds, ripple_k=ripple_k, eps=eps,
                     stribeck_vs=vs_final, explained=not unexplained, unexplained=unexplained,
                     filtering=data.low_pass, negligible=tuple(negligible), undetermined=not_determined)
