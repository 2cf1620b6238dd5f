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

**Streamed.**  The columns are computed and filtered window by window (:class:`Recording`:
a recording read piece by piece, any length) and folded into moments (:class:`_Moments`: per
fold Gram matrices and per-joint triangular factors, per-joint lagged products for ``N_eff``);
every fit and statistic below comes from those, so memory does not grow with the log.  The
noise floor's median, the Stribeck refinement and the elasticity's noise bias take further
passes over the data.

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
from typing import Callable, Iterable, Sequence

import numpy as np
from scipy.stats import chi2

from ..model.inertial_parameters import NAMES as BARYCENTRIC_NAMES
from ..model.inertial_parameters import parameter_vector
from ..model.robot_model import RobotModel
from .effect_columns import effect_columns, effect_names
from .log_preparing import Segment, filtered_rows, noise_gain, zero_phase_low_pass
from .log_streaming import ChunkedParallelFilter, overlap_rows
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
        return 0.0, ENCODER_OFFSET_MAX          # fitted as the peak deflection (rad), see _Problem
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


#: lags of the residual's autocorrelation folded for the effective sample count (filtered,
#: decimated rows decorrelate within a few lags); a fit whose residual is still correlated at
#: MAX_LAG lags has its residual computed in one more pass over the data instead
MAX_LAG = 32
#: rows of lagged products formed at once (a (LAG_ROWS, columns x MAX_LAG) temporary)
LAG_ROWS = 1024
#: samples per chunk of the data pass (the parallel filter's output chunk)
CHUNK_ROWS = 20000
#: samples whose columns are computed at once (at most the chunk): (4096, 7, 124) doubles are 28 MB
WINDOW_ROWS = 4096


class _Moments:
    """What the data pass keeps of the filtered rows ``[A | r]`` (candidate columns, residual of
    the nominal model) and of the signals: per cross-validation fold the Gram matrix and
    right-hand side summed over joints and the per-joint triangular factor (exact residual
    sums, :class:`kindyngen.measured.ls_factor.LSFactor`); per joint the Gram matrix of
    ``[A | r | signals | 1]``; per joint the lagged products of ``[A_j | r_j]`` over the
    columns that can be non-zero on joint j, lags 1 .. MAX_LAG, with the first and last
    MAX_LAG rows (the autocorrelation of any fit's residual, exactly).  Memory O(columns^2 x
    (folds + joints x MAX_LAG)), whatever the log length; Gram matrices and factors of
    chunks, folds and files add up."""

    def __init__(self, n, widths, support, folds, lags):
        from .ls_factor import LSFactor
        p = int(sum(widths))
        self.n, self.p, self.folds, self.lags = n, p, folds, lags
        self.factors = [LSFactor.empty(n, p) for _ in range(folds)]
        self.G = np.zeros((folds, p, p))
        self.b = np.zeros((folds, p))
        self.rows = np.zeros(folds, int)
        self.signals = np.zeros((n, p + 7, p + 7))
        self.support = support                      # per joint: column indices (into A) that can be non-zero
        self.lagged = [np.zeros((lags, len(s) + 1, len(s) + 1)) for s in support]
        self.head = [np.zeros((0, len(s) + 1)) for s in support]
        self.tail = [np.zeros((0, len(s) + 1)) for s in support]
        self.sum_tau2 = 0.0

    def add(self, fold_of, A, r, signals, tau):
        """Fold filtered rows: ``A`` (m, n, p), ``r`` (m, n) residual of the nominal model,
        ``signals`` (m, n, 5), ``tau`` (m, n) the filtered torque, rows in time order;
        ``fold_of`` (m) their folds."""
        m, n = r.shape
        for k in np.unique(fold_of):
            rows = fold_of == k
            Ak, rk = A[rows], r[rows]
            self.factors[k] = self.factors[k].fold(Ak, rk)
            A2 = Ak.reshape(len(Ak) * n, self.p)
            self.G[k] += A2.T @ A2
            self.b[k] += A2.T @ rk.reshape(-1)
            self.rows[k] += int(rows.sum())
        Z = np.concatenate([A, r[:, :, None], signals, np.ones((m, n, 1))], axis=2).transpose(1, 0, 2)
        self.signals += Z.transpose(0, 2, 1) @ Z
        self.sum_tau2 += float(np.sum(tau ** 2))
        L = self.lags
        for j in range(n):
            X = np.concatenate([A[:, j, self.support[j]], r[:, j, None]], axis=1)
            if L == 0:
                continue
            Y = np.concatenate([self.tail[j], X])
            t0 = len(self.tail[j])
            if len(Y) > L:
                # rows t >= L of Y against their L predecessors: M_k += sum_t y_{t-k} y_t^T, all
                # lags in one product per block of rows (the window view copied LAG_ROWS at a time)
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
            self.tail[j] = Y[-L:] if L else Y[:0]

    @property
    def samples(self) -> int:
        return int(self.rows.sum())


class _Problem:
    """Fits of any subset of the candidate blocks from the data pass's moments, inside the
    physical domain (coefficients flagged non-negative are held >= 0).

    The columns are scaled to unit norm (the scaled unknowns ``theta``); the elasticity
    candidate's columns are divided by the peak |joint torque| first (fitted as the peak
    deflection, :meth:`natural`).  Folds: each recording cut into ``folds`` contiguous time
    blocks, fold k the k-th block of every recording (the same folds whatever the order of
    the recordings)."""

    def __init__(self, moments: _Moments, keys, widths, details, names, peak, specs):
        self.m = moments
        self.N, self.n = moments.samples, moments.n
        self.keys, self.details, self.names = list(keys), dict(details), dict(names)
        self.peak, self.specs = peak, specs
        self.slices, start, lower, unit = {}, 0, [], []
        for key, width in zip(keys, widths):
            self.slices[key] = np.arange(start, start + width)
            start += width
            lower += [_bounds(_public(key))] * width
            unit.append(1.0 / peak if _public(key) == "motor_side_elasticity" else np.ones(width))
        d = np.concatenate(unit) if unit else np.zeros(0)
        G_raw = moments.G.sum(axis=0)
        norm = np.sqrt(np.maximum(np.diag(G_raw), 0.0)) * d
        self.scale = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1), 0.0)
        self.to_raw = d * self.scale             # coefficient of the raw (as folded) columns per theta
        bounds = np.array(lower, float).reshape(-1, 2)
        live = np.where(self.scale > 0, self.scale, 1.0)
        self.lower = np.where(self.scale > 0, bounds[:, 0] / live, -np.inf)
        self.upper = np.where(self.scale > 0, bounds[:, 1] / live, np.inf)
        D = self.to_raw
        self.Gf = [D[:, None] * G * D[None, :] for G in moments.G]
        self.bf = [D * b for b in moments.b]
        self.G = D[:, None] * G_raw * D[None, :]
        self.b = D * moments.b.sum(axis=0)

    def columns(self, names):
        return np.concatenate([self.slices[c] for c in names]) if names else np.zeros(0, int)

    def live(self, key) -> bool:
        """Whether a block has any non-zero column on this motion."""
        return bool(np.any(np.diag(self.m.G.sum(axis=0))[self.slices[key]] > 0))

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

    def raw(self, idx, theta) -> np.ndarray:
        """Coefficients of all the folded (raw) columns for ``theta`` on ``idx``."""
        out = np.zeros(self.m.p)
        out[idx] = theta * self.to_raw[idx]
        return out

    def residual_sums(self, coef) -> np.ndarray:
        """Per joint, the sum of squared residuals ``r - A coef`` over all rows (from the factors)."""
        return np.sum([f.residual_sums(coef) for f in self.m.factors], axis=0)

    def fit(self, names):
        """Full-data fit and out-of-fold residual sums of the candidates ``names``."""
        idx = self.columns(names)
        theta, inv, rank = self._solve(self.G[np.ix_(idx, idx)], self.b[idx], idx)
        joint_rss = self.residual_sums(self.raw(idx, theta))
        oof = np.zeros((self.m.folds, self.n))
        for k, (factor, Gf, bf) in enumerate(zip(self.m.factors, self.Gf, self.bf)):
            th, _, _ = self._solve((self.G - Gf)[np.ix_(idx, idx)], (self.b - bf)[idx], idx)
            oof[k] = factor.residual_sums(self.raw(idx, th))
        fold_mse = np.sum(oof, axis=1) / np.maximum(self.m.rows, 1)
        heldout = np.sqrt(np.maximum(np.sum(oof, axis=0), 0) / self.N)
        return dict(names=tuple(names), idx=idx, theta=theta, inv=inv, rank=rank, joint_rss=joint_rss,
                    rss=float(np.sum(joint_rss)), fold_mse=fold_mse, heldout=heldout,
                    mse=float(np.sum(np.maximum(np.sum(oof, axis=0), 0)) / self.N))

    def with_theta(self, fit, theta) -> dict:
        """``fit`` with other coefficients (the same columns): its residual sums again."""
        joint_rss = self.residual_sums(self.raw(fit["idx"], theta))
        return dict(fit, theta=theta, joint_rss=joint_rss, rss=float(np.sum(joint_rss)))

    def residual_rms(self, fit) -> np.ndarray:
        return np.sqrt(np.maximum(fit["joint_rss"], 0) / self.N)

    def criterion(self, fit, n_eff_total):
        rows = self.N * self.n
        return float(n_eff_total * math.log(max(fit["rss"], 1e-300) / rows) + fit["rank"] * math.log(n_eff_total))

    def _residual_sums_1(self, fit, j):
        """Joint j: (sum of the residual, the weights w with residual = [A_j | r_j] w on the support)."""
        coef = self.raw(fit["idx"], fit["theta"])
        sup = self.m.support[j]
        w = np.concatenate([-coef[sup], [1.0]])
        S = self.m.signals[j]
        p = self.m.p
        total = S[p, p + 6] - coef @ S[:p, p + 6]       # sum of r_j minus sum of A_j coef
        return total, w

    def effective_samples(self, fit) -> tuple[np.ndarray, bool]:
        """:func:`effective_samples` of the fit's residual from the lagged products (per joint
        ``N / (1 + 2 sum rho_k)`` up to the first non-positive lag), and whether that lag lies
        within the lags folded (else the residual itself is needed)."""
        N, L = self.N, self.m.lags
        out = np.empty(self.n)
        exact = True
        for j in range(self.n):
            total, w = self._residual_sums_1(fit, j)
            mean = total / N
            acf0 = fit["joint_rss"][j] - N * mean ** 2
            if acf0 <= 0:
                out[j] = N
                continue
            head = np.cumsum(self.m.head[j] @ w)              # sums of the first k residuals
            tail = np.cumsum((self.m.tail[j] @ w)[::-1])      # sums of the last k residuals
            s = 0.0
            lags = min(L, N - 1)
            for k in range(1, lags + 1):
                acf = w @ self.m.lagged[j][k - 1] @ w - mean * ((total - tail[k - 1]) + (total - head[k - 1])) \
                    + (N - k) * mean ** 2
                rho = acf / acf0
                if rho <= 0:
                    break
                s += rho
            else:
                exact = exact and lags >= N - 1
            out[j] = min(N, max(1.0, N / (1.0 + 2.0 * s)))
        return out, exact

    def contribution_rms(self, fit, column) -> np.ndarray:
        """Per joint, the RMS of one column's torque in ``fit`` (N m)."""
        where = np.flatnonzero(fit["idx"] == column)[0]
        c = fit["theta"][where] * self.to_raw[column]
        return np.abs(c) * np.sqrt(np.maximum(self.m.signals[:, column, column], 0) / self.N)

    def correlations(self, fit, j) -> list[tuple[float, str]]:
        """(|correlation|, label) of joint j's residual with each filtered signal."""
        S = self.m.signals[j]
        p, N = self.m.p, self.N
        coef = self.raw(fit["idx"], fit["theta"])
        w = np.concatenate([-coef, [1.0]])
        total = S[p, p + 6] - coef @ S[:p, p + 6]
        r_norm2 = fit["joint_rss"][j] - total ** 2 / N
        out = []
        for k, label in enumerate(SIGNALS):
            x = p + 1 + k
            cross = w @ S[:p + 1, x] - total * S[x, p + 6] / N
            x_norm2 = S[x, x] - S[x, p + 6] ** 2 / N
            den = math.sqrt(max(r_norm2, 0) * max(x_norm2, 0))
            out.append((abs(float(cross)) / den if den > 0 else 0.0, label))
        return out

    def root(self):
        """A square matrix with the Gram matrix of the scaled columns (summed over joints and
        rows) as its own: the triangular factor of all folds' and joints' factors stacked."""
        stacked = np.vstack([f.R[j] for f in self.m.factors for j in range(self.n)])
        R = np.linalg.qr(stacked, mode="r") if len(stacked) else stacked
        return R * self.to_raw


def _support(keys, widths, n) -> list[np.ndarray]:
    """Per joint, the columns of the stacked blocks that can be non-zero on it: a per-joint
    law's column i acts on joint i only; the payload, the base tilt and the effects on the
    measurement act on every joint."""
    out = [[] for _ in range(n)]
    start = 0
    for key, width in zip(keys, widths):
        dense = _public(key) in ("payload", "base_tilt", "encoder_offset", "motor_side_elasticity")
        for c in range(width):
            for j in range(n):
                if dense or c % n == j:
                    out[j].append(start + c)
        start += width
    return [np.array(s, int) for s in out]


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
    where = np.flatnonzero(np.isin(idx, own)) if np.all(np.isin(own, idx)) else None
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
    before = float(np.linalg.eigvalsh(pseudo_inertia(values[where]))[0])
    out = problem.with_theta(fit, theta)
    size = problem.N * problem.n
    return out, (f"payload: the free fit's pseudo-inertia has smallest eigenvalue {before:.3g} kg m^2; fitted "
                 f"again inside the physical domain (pseudo-inertia >= {PAYLOAD_EPSILON:g} kg m^2, a semidefinite "
                 f"program): full-data RMS {math.sqrt(fit['rss'] / size):.4g} -> "
                 f"{math.sqrt(out['rss'] / size):.4g} N m")


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

#: signals filtered alongside the columns, for the "what the residual left correlates with" verdict
SIGNALS = ("q", "qd", "qdd", "sign(qd)", "nominal torque")


@dataclass(frozen=True)
class Recording:
    """One segment of a recording as the data pass reads it: ``rows`` samples, given by
    ``pieces()`` (a fresh iterator of consecutive preprocessed pieces at each call: every pass
    reads the recording again), each a :class:`kindyngen.measured.log_preparing.Segment` with
    its unfiltered torque and ``low_pass``.  ``index``: the recording's place among all (the
    seed of its noise for :func:`elastic_noise_bias`)."""

    rows: int
    pieces: Callable[[], Iterable[Segment]]
    index: int = 0


def in_memory(segments: Sequence[Segment]) -> tuple[Recording, ...]:
    """Recordings of segments already in memory (each piece the whole segment)."""
    return tuple(Recording(len(seg.t), (lambda seg=seg: iter((seg,))), i) for i, seg in enumerate(segments))


def _smoothing(rows: int, dt: float, low_pass):
    """(rate, cutoff, order) of the smoothing :func:`spring_of` applies to the torque (None:
    none: a segment filtered already, or too short) and the halo of rows it needs."""
    if low_pass is not None or rows < 60:
        return None, 2
    from .log_preparing import Preprocessing
    cutoff = min(5.0, 0.2 / dt)
    return (1.0 / dt, cutoff, 4), overlap_rows(Preprocessing(cutoff_hz=cutoff), dt) + 2


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


def _spring(context, dt, i0, i1, smoothing):
    """The spring torque and its derivatives (:func:`spring_of`) on rows ``i0:i1`` of a window."""
    tau = context["tau"]
    if smoothing is not None:
        tau = zero_phase_low_pass(tau, *smoothing)
    return tuple(x[i0:i1] for x in spring_torque(tau, dt))


@dataclass
class _PassResult:
    moments: "_Moments"
    widths: list
    names: dict
    details: dict
    peak: np.ndarray | None
    floors: list            # per recording: (counts of |d2| per bin, noise gain, filtered rows)
    low_pass: tuple
    chunks: int
    residual: np.ndarray | None


def _data_pass(model, recordings, specs, eps, ripple_k, folds, chunk_rows, lags, need_spring, progress,
               peak=None, coef=None) -> _PassResult:
    """One pass over the recordings: every candidate column of ``specs`` (block key -> (name,
    Stribeck velocity or None)) computed window by window from the motion estimate, filtered
    with the unfiltered torque (chunked parallel filter), and folded into :class:`_Moments`.
    The elasticity columns are folded undivided (the peak |torque|, found along the way, scales
    them afterwards); ``peak``: given, when known from an earlier pass.  The noise floor's
    second differences are counted per recording in bins (:func:`_count_bins`; the exact median
    follows in :func:`_median_pass`).  ``coef``: raw
    coefficients of the columns of ``specs``: the residual ``r - A coef`` of every row is kept
    as well (``residual``), for a fit whose autocorrelation reaches beyond the lags folded."""
    import time

    from .log_preparing import Preprocessing
    n = model.n
    keys = list(specs)
    widths, names, details = None, {}, {}
    moments = None
    found_peak = np.zeros(n)
    floors, low_pass_text = [], []
    started, last, read, chunks = time.perf_counter(), time.perf_counter(), 0, 0
    residual = []
    for rec in recordings:
        state = dict(emitted=0, m_total=None, filt=None, bins=np.zeros((n, MEDIAN_BINS), np.int64))

        def fold(F, tau):
            nonlocal moments, chunks
            p = int(sum(widths))
            A, nominal, signals = F[:, :, :p], F[:, :, p], F[:, :, p + 1:]
            if moments is None:
                moments = _Moments(n, widths, _support(keys, widths, n), folds, lags)
            i = state["emitted"] + np.arange(len(tau))
            state["emitted"] += len(tau)
            M = state["m_total"]
            moments.add(np.minimum((i * folds) // M, folds - 1), A, tau - nominal, signals, tau)
            if coef is not None:
                residual.append(tau - nominal - A @ coef)
            chunks += 1

        # the halo depends on the segment (its filter): look at its first piece
        first = next(iter(rec.pieces()), None)
        if first is None:
            continue
        lp = first.low_pass
        smoothing, halo = _smoothing(rec.rows, first.dt, lp) if need_spring else (None, 2)
        state["m_total"] = -(-rec.rows // lp.decimate) if lp is not None else rec.rows
        if lp is not None:
            state["filt"] = ChunkedParallelFilter(lp, overlap_rows(Preprocessing(cutoff_hz=lp.cutoff_hz,
                                                                                 order=lp.order), first.dt),
                                                  chunk_rows)
            low_pass_text.append(lp.describe())
        for seg, a, context, s, e in piece_windows(rec.pieces(), min(chunk_rows, WINDOW_ROWS), max(halo, 2)):
            i0, i1 = s - a, e - a
            # the nominal torque on the window's rows and 2 on either side (second differences)
            c0, c1 = max(0, i0 - 2), min(len(context["q"]), i1 + 2)
            tau_ctx = nominal_torques(model, context["q"][c0:c1], context["qd"][c0:c1], context["qdd"][c0:c1])
            d2 = np.diff(context["raw"][c0:c1] - tau_ctx, 2, axis=0)
            centre = a + c0 + 1 + np.arange(len(d2))
            _count_bins(state["bins"], d2[(centre >= s) & (centre < e)])
            q, qd, qdd = context["q"][i0:i1], context["qd"][i0:i1], context["qdd"][i0:i1]
            tau_nom = tau_ctx[i0 - c0:i1 - c0]
            spring = _spring(context, seg.dt, i0, i1, smoothing) if need_spring else None
            if spring is not None:
                found_peak = np.maximum(found_peak, np.max(np.abs(spring[0]), axis=0))
            blocks = []
            for key in keys:
                name, vs = specs[key]
                cols, nm, detail = _columns(name, model, q, qd, qdd, tau_nom, eps, ripple_k, vs, spring)
                blocks.append(cols)
                names[key], details[key] = nm, detail
            if widths is None:
                widths = [b.shape[2] for b in blocks]
            stack = np.concatenate(blocks + [np.stack([tau_nom, q, qd, qdd, np.sign(qd), tau_nom], axis=2)], axis=2)
            m = len(q)
            read += m
            if state["filt"] is None:
                fold(stack, context["tau"][i0:i1])
            else:
                flat = np.concatenate([stack.reshape(m, -1), context["raw"][i0:i1]], axis=1)
                for out in state["filt"].push(flat):
                    fold(out[:, :-n].reshape(len(out), n, -1), out[:, -n:])
            now = time.perf_counter()
            if now - last > 5.0:
                last = now
                progress(f"{read} samples read ({read / (now - started):,.0f} samples/s), "
                         f"{moments.samples if moments else 0} rows folded in {chunks} chunks (after decimation)")
        if state["filt"] is not None:
            for out in state["filt"].finish():
                fold(out[:, :-n].reshape(len(out), n, -1), out[:, -n:])
        floors.append((state["bins"], noise_gain(lp), state["emitted"]))
    now = time.perf_counter()
    if moments is not None:
        progress(f"{read} samples read, {moments.samples} rows folded in {chunks} chunks in {now - started:.1f} s "
                 f"({read / max(now - started, 1e-9):,.0f} samples/s)")
    return _PassResult(moments, widths, names, details, found_peak if peak is None else peak, floors,
                       tuple(dict.fromkeys(low_pass_text)), chunks,
                       np.concatenate(residual) if residual else None)


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


def _median_pass(model, recordings, counts, chunk_rows) -> list[np.ndarray]:
    """Per recording, the noise floor ``1.4826 median|d2 r| / sqrt(6)`` of its unfiltered
    residual (:func:`noise_floor`), exactly and in bounded memory: the data pass counted the
    values per bin, so the bins of the two middle ranks are known; this pass keeps only the
    values in those bins and picks the ranks among them (``np.median``'s mean of the two middle
    values for an even count)."""
    n = model.n
    out = []
    for rec, bins in zip(recordings, counts):
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
            tau_ctx = nominal_torques(model, context["q"][c0:c1], context["qd"][c0:c1], context["qdd"][c0:c1])
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


def _elastic_noise_bias_pass(model, recordings, raw_floors, chunk_rows) -> np.ndarray:
    """:func:`elastic_noise_bias` of the recordings, window by window: the noise of each
    recording drawn in order from its seed (the same numbers as drawn whole), smoothed and
    differentiated in windows with the smoothing's overlap, its columns and the measured
    torque's through the chunked parallel filter."""
    from .log_preparing import Preprocessing

    def torques(*motion):
        return nominal_torques(model, *motion)
    n = model.n
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
    (:func:`elastic_noise_bias`).  A coefficient is undetermined when it sits at a
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


def _where(problem, fit, floor, factor, rounding) -> tuple[str, ...]:
    """Sentences on the joints whose residual stays above ``factor`` x floor (and above the
    rounding level ``rounding``, N m), and what it correlates with most (filtered signals of
    that joint)."""
    out = []
    for j in np.flatnonzero((fit["heldout"] > factor * floor) & (fit["heldout"] > rounding)):
        c, label = max(problem.correlations(fit, j))
        out.append(f"joint {j + 1}: held-out RMS {fit['heldout'][j]:.3g} N m = {fit['heldout'][j] / max(floor[j], 1e-300):.3g} x "
                   f"its noise floor {floor[j]:.3g}; correlates most with its {label} (|r| = {c:.2f})")
    return tuple(out)


def discover(model: RobotModel, segments: Sequence[Segment | Recording], candidates: Sequence[str] = CANDIDATES,
             folds: int = 5, progress: Callable[[str], None] | None = None, eps: float | None = None,
             *, ripple_k: float = RIPPLE_K, stribeck_vs: Sequence[float] = STRIBECK_VS,
             chunk_rows: int = CHUNK_ROWS) -> Discovery:
    """Which of ``candidates`` does the nominal ``model`` miss on ``segments``?  See the module
    text for the rules.  ``segments``: one or more recordings' segments, each filtered on
    its own (a segment with a ``low_pass`` is parallel-filtered here), as Segments in memory
    or as :class:`Recording` (read piece by piece: logs of any length in bounded memory);
    ``eps``: Coulomb smoothing (rad/s) of the Coulomb candidate (None: ``sign``); the
    description's own declared effects are assumed absent (a note says so when it declares
    some).  ``chunk_rows``: samples per window of the data pass (the result does not depend
    on it, to rounding)."""
    progress = progress or (lambda text: None)
    candidates = tuple(dict.fromkeys(candidates))
    for c in candidates:
        if c not in CANDIDATES:
            raise ValueError(f"unknown candidate {c!r} (known: {', '.join(CANDIDATES)})")
    segments = tuple(segments)
    if not segments:
        raise ValueError("discover needs at least one segment")
    recordings = tuple(s if isinstance(s, Recording) else in_memory([s])[0] for s in segments)
    recordings = tuple(replace(r, index=i) for i, r in enumerate(recordings))
    if folds < 2:
        raise ValueError("folds must be at least 2")
    notes = []
    if model.effects:
        notes.append(f"the description declares {', '.join(model.effects)}: ignored here (rigid bodies only "
                     f"are the nominal prediction)")
    progress("nominal prediction and candidate columns (parallel filtering), folded chunk by chunk")
    need_spring = "motor_side_elasticity" in candidates
    # one block of columns per candidate; the Stribeck candidate has one per velocity of the
    # grid, and at every step the velocity with the lowest held-out error stands for it
    specs, variants = {}, {}
    for c in candidates:
        for vs in (tuple(stribeck_vs) if c == "stribeck_friction" else (None,)):
            key = c if vs is None else f"{c}@{vs:g}"
            specs[key] = (c, None if vs is None else float(vs))
            variants.setdefault(c, []).append(key)

    def data_pass(pass_specs, lags, peak=None, coef=None):
        return _data_pass(model, recordings, pass_specs, eps, ripple_k, folds, chunk_rows, lags, need_spring,
                          progress, peak, coef)

    def problem_of(result, pass_specs):
        keys = list(result.names)
        return _Problem(result.moments, keys, result.widths, result.details, result.names,
                        np.where(result.peak > 0, result.peak, 1.0) if result.peak is not None else None,
                        pass_specs)

    def n_eff_of(prob, fit) -> np.ndarray:
        n_eff, exact = prob.effective_samples(fit)
        if exact:
            return n_eff
        progress(f"the residual's autocorrelation reaches beyond lag {MAX_LAG}: one more pass for the residual")
        keys = list(fit["names"])
        again = data_pass({k: prob.specs[k] for k in keys}, 0, peak,
                          coef=prob.raw(fit["idx"], fit["theta"])[fit["idx"]])
        return effective_samples(again.residual)

    main = data_pass(specs, MAX_LAG)
    if main.moments is None:
        raise ValueError("discover needs at least one sample")
    N, n = main.moments.samples, model.n
    if N < 10 * folds:
        raise ValueError(f"{N} samples are too few for {folds} folds")
    progress("the noise floor: the middle values of the binned second differences (a pass over the data)")
    raw_floors = _median_pass(model, recordings, [f[0] for f in main.floors], chunk_rows)
    w = np.array([f[2] for f in main.floors], float)[:, None]
    floor = np.sqrt(np.sum(w * np.array([fl * f[1] for fl, f in zip(raw_floors, main.floors)]) ** 2, axis=0)
                    / w.sum())
    scale = math.sqrt(main.moments.sum_tau2 / (N * n)) or 1.0
    problem = problem_of(main, specs)
    peak = problem.peak
    details = dict(problem.details)
    block_names = problem.names

    def natural(key, values):
        """A block's fitted values in the candidate's own units (a peak deflection -> ce)."""
        return values / peak if _public(key) == "motor_side_elasticity" else values
    extra_k = {"stribeck_friction": 1 if len(stribeck_vs) > 1 else 0}
    A2 = problem.root()

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
    remaining = [c for c in candidates if any(problem.live(k) for k in variants[c])]
    for c in candidates:
        if c not in remaining:
            notes.append(f"{c}: its columns vanish on this motion (not tried)")

    def at_floor(fit) -> str | None:
        if np.all(problem.residual_rms(fit) <= ROUNDING * scale):
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
        n_eff = n_eff_of(problem, fit)
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
                          parameter_names=block_names[best_key], values=natural(best_key, values[own]),
                          std=natural(best_key, std[own]),
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
    final_problem = problem
    if stribeck_key is not None:
        from scipy.optimize import minimize_scalar
        grid = sorted(float(v) for v in stribeck_vs)
        vs0 = specs[stribeck_key][1]
        i = grid.index(vs0)
        lo = grid[i - 1] if i > 0 else vs0 / 2
        hi = grid[i + 1] if i + 1 < len(grid) else vs0 * 2
        others = {k: specs[k] for k in chosen if k != stribeck_key}

        def rss_at(log_vs):
            # a pass over the data for each velocity tried (the columns of exp(-(qd/vs)^2))
            trial = dict(others, stribeck_friction=("stribeck_friction", math.exp(log_vs)))
            return problem_of(data_pass(trial, 0, peak), trial).fit(list(trial))["rss"]
        progress("refining the Stribeck velocity (a pass over the data per velocity tried)")
        best_log = minimize_scalar(rss_at, bounds=(math.log(lo), math.log(hi)), method="bounded",
                                   options={"xatol": 1e-3}).x
        vs_final = float(math.exp(best_log))
        final_specs = {k: (("stribeck_friction", vs_final) if k == stribeck_key else specs[k]) for k in chosen}
        final_problem = problem_of(data_pass(final_specs, MAX_LAG, peak), final_specs)
        details[stribeck_key] = f"vs = {vs_final:.3g} rad/s (refined between the grid points {lo:g} and {hi:g})"
        block_names = dict(block_names, **final_problem.names)
    final = final_problem.fit(chosen)
    if "payload" in chosen:
        physical = _physical_payload(final_problem, final)
        if physical is not None:
            final, text = physical
            notes.append(text)

    # final values of every fitted candidate
    idx = final["idx"]
    rows = N * n
    n_eff = n_eff_of(final_problem, final)
    s2 = final["rss"] / max(rows - final["rank"], 1)
    values = final["theta"] * final_problem.scale[idx] if len(idx) else np.zeros(0)
    std = (np.sqrt(np.maximum(np.diag(final["inv"]), 0) * s2 * rows / n_eff.sum()) * final_problem.scale[idx]
           if len(idx) else np.zeros(0))
    names = [name for c in chosen for name in block_names[c]]
    fitted_values = dict(zip(names, map(float, values)))      # as fitted (bounds apply to these)
    natural_values = np.concatenate([natural(c, values[np.isin(idx, final_problem.slices[c])]) for c in chosen]) \
        if chosen else np.zeros(0)
    value_of = dict(zip(names, map(float, natural_values)))
    for k in chosen:
        low, high = _bounds(_public(k))
        if not (math.isfinite(low) and math.isfinite(high)):
            continue
        edges = (low, high) if low < 0 else (high,)      # a coefficient at 0 of [0, x] is just absent
        pinned = [nm for nm in block_names[k]
                  if any(abs(fitted_values[nm] - e) <= 1e-6 * (high - low) for e in edges)]
        if pinned:
            notes.append(f"{_public(k)}: {', '.join(pinned)} at the edge of the physical range [{low:g}, {high:g}]: "
                         f"the data pulls beyond it, so read these as standing in for something else (an error "
                         f"of the nominal model, an effect outside the library)")
    # per coefficient, whether its own torque matters (MATTER noise floors on some joint):
    # a joint's spring or gain that changes nothing above the noise stays ideal in model.yaml
    negligible = []
    for c in chosen:
        for k, nm in zip(final_problem.slices[c], block_names[c]):
            contribution = final_problem.contribution_rms(final, k)
            if np.all(contribution < MATTER * np.maximum(floor, 1e-300)):
                negligible.append(nm)
    std_natural = np.concatenate([natural(c, std[np.isin(idx, final_problem.slices[c])]) for c in chosen]) \
        if chosen else np.zeros(0)
    std_of = dict(zip(names, map(float, std_natural)))
    bias = _elastic_noise_bias_pass(model, recordings, raw_floors, chunk_rows) \
        if any(_public(k) == "motor_side_elasticity" for k in chosen) else None
    not_determined = undetermined(
        {_public(k): block_names[k] for k in chosen}, value_of, std_of,
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
    unexplained = _where(final_problem, final, floor, EXPLAINED_FACTOR, 1e3 * ROUNDING * scale)
    return Discovery(effects=tuple(named), fitted=fitted, steps=tuple(steps), rms_before=rms_before,
                     rms_after=final["heldout"], noise_floor=floor, noise_method=NOISE_METHOD,
                     indistinguishable=tuple(groups), notes=tuple(notes), values=value_of, std=std_of,
                     payload=payload, payload_mass=payload_mass, gravity=gravity, tilt_deg=tilt, n_eff=n_eff,
                     samples=N, folds=folds, ripple_k=ripple_k, eps=eps,
                     stribeck_vs=vs_final, explained=not unexplained, unexplained=unexplained,
                     filtering=main.low_pass, negligible=tuple(negligible), undetermined=not_determined)
