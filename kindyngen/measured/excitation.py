"""Excitation trajectories for dynamic identification: what to record before identifying.

A periodic finite Fourier series per joint (Swevers, Ganseman, Bilgin Tukel, De Schutter,
Van Brussel, "Optimal robot excitation and identification", IEEE T-RA 13(5), 1997)::

    q_i(t) = q0_i + sum_k [ a_ik / (w k) sin(w k t) - b_ik / (w k) cos(w k t) ],  w = 2 pi f

whose coefficients are chosen to minimise the condition number of the stacked torque
regressor over one period (rigid-body base regressor of
:class:`kindyngen.measured.regressor_rows.TorqueRegressor`, plus, by default, one viscous,
one Coulomb and one offset column per joint), subject to position, velocity and acceleration
limits.  Periodic excitation lets a user average the periods of a recording (less noise) and
differentiate it in the frequency domain without edge effects.

Example (the numbers depend on the robot, harmonics and budget; a few seconds for the LWR):

>>> from kindyngen.readers.yaml_description import load_robot                                # doctest: +SKIP
>>> model = load_robot("robots/lwr4.yaml")                                # doctest: +SKIP
>>> result = optimise_excitation(model, default_limits(model))           # doctest: +SKIP
>>> result.feasible, result.condition_number < result.initial_condition_number  # doctest: +SKIP
(True, True)
>>> write_trajectory_csv("excitation.csv", result.trajectory, rate_hz=100)  # doctest: +SKIP
>>> write_trajectory_json("excitation.json", result)                      # doctest: +SKIP

How the limits are kept (why the result is feasible between grid points, not only on them):
every one of ``q - centre``, ``qd`` and ``qdd`` is a real trigonometric polynomial of degree
H in ``w t``.  For such a polynomial p with maximum modulus P, Bernstein's inequality gives
``|p''| <= H^2 P``; the maximum is at most half a grid step ``pi / M`` (in ``w t``) from a
grid point of an M-point grid, where ``|p| >= P (1 - (pi H / M)^2 / 2)``.  So requiring
``|p| <= kappa * limit`` on the grid with ``kappa = 1 - (pi H / M)^2 / 2`` guarantees
``|p| <= limit`` everywhere.  The constraints are linear in the coefficients, so SLSQP keeps
them with their exact Jacobian, and the returned point is the best iterate that satisfies
them.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.optimize import minimize

from ..algorithms.base_parameters import condition_number_2norm
from ..json_text import json_number, strict_json
from ..model.robot_model import RobotModel
from .effect_columns import coulomb_eps, effect_columns, effect_names
from .regressor_rows import TorqueRegressor, refuse_mimic_joints, torque_regressor
from . import MeasuredDataError

# the friction columns appended to the rigid-body base regressor (kindyngen.measured.effect_columns)
FRICTION_EFFECTS = ("viscous_friction", "coulomb_friction", "torque_offset")

# Defaults of default_limits().  The robot descriptions carry position limits only.
# 1.0 rad/s and 3.0 rad/s^2 are about half the rated joint speeds and well below the rated
# accelerations of the shipped arms (KUKA LWR IV+: 1.9-3.6 rad/s; Franka Panda: 2.2-2.6 rad/s
# and 7.5-20 rad/s^2), so a first identification run stays clear of the controller's own
# velocity, acceleration and torque limits (which stop the robot mid-recording); raise them
# for a better signal-to-noise ratio once the set-up is trusted.
DEFAULT_VELOCITY = 1.0        # rad/s, every joint
DEFAULT_ACCELERATION = 3.0    # rad/s^2, every joint
# kept clear of each position limit: tracking errors of a few 0.01 rad must not reach the
# software limit switches, which stop the robot and spoil the recording
DEFAULT_MARGIN = 0.1          # rad

# Defaults of optimise_excitation().
DEFAULT_HARMONICS = 5
DEFAULT_BASE_FREQUENCY_HZ = 0.1   # 10 s period: the highest harmonic (0.5 Hz) stays slow
# regressor samples per period = this times the number of harmonics: four samples per cycle
# of the fastest products in the regressor (qd_i qd_j: twice the highest harmonic)
SAMPLES_PER_HARMONIC = 20
# SLSQP iterations.  With the analytic gradient below one LWR iteration (7 joints, 5
# harmonics, 77 variables, 8400 linear constraints) takes about 0.2 s on 2 cores, and SLSQP
# usually stops on its own after 10-45 iterations (ftol); the cap bounds the worst case
DEFAULT_MAX_ITERATIONS = 60
# the constraint grid is this much denser than the optimisation grid (the tightening below
# makes any density safe; a denser grid only loses less of the limits: 0.3 % at 40 points
# per harmonic)
CONSTRAINT_DENSITY = 2
# the feasibility check runs on a grid this much denser than the optimisation grid
CHECK_DENSITY = 10


class ExcitationError(MeasuredDataError):
    """A request that cannot give an excitation trajectory (bad harmonics, frequency, limits)."""


# ----------------------------------------------------------------------------- trajectory

def _basis(t: np.ndarray, frequency_hz: float, harmonics: int):
    """Matrices Bq, Bv, Ba (N, 2H + 1) with q = Bq @ [a, b, q0] (one joint), likewise qd, qdd."""
    wk = 2.0 * math.pi * frequency_hz * np.arange(1, harmonics + 1)
    phase = np.outer(t, wk)
    S, C = np.sin(phase), np.cos(phase)
    ones, zeros = np.ones((len(t), 1)), np.zeros((len(t), 1))
    Bq = np.hstack([S / wk, -C / wk, ones])
    Bv = np.hstack([C, S, zeros])
    Ba = np.hstack([-S * wk, C * wk, zeros])
    return Bq, Bv, Ba


def _readonly(value, shape, name) -> np.ndarray:
    array = np.array(value, dtype=float)  # a copy: the caller's array may change later
    if array.shape != shape:
        raise ExcitationError(f"{name}: expected shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ExcitationError(f"{name}: every entry must be finite")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)  # eq=False: numpy arrays have no single truth value
class FourierTrajectory:
    """One period of a finite Fourier series per joint (SI units: s, rad).

    ``q_i(t) = q0_i + sum_k [a_ik / (w k) sin(w k t) - b_ik / (w k) cos(w k t)]``,
    ``w = 2 pi base_frequency_hz``; ``a``, ``b`` (n, H) are velocity amplitudes (rad/s),
    ``q0`` (n,) the offsets (rad).  ``q0`` is not the position at t = 0:
    ``q_i(0) = q0_i - sum_k b_ik / (w k)``.

    >>> traj = FourierTrajectory(0.5, a=[[1.0]], b=[[0.0]], q0=[0.2])
    >>> traj.period
    2.0
    >>> q, qd, qdd = traj.evaluate([0.0, 0.5])
    >>> np.round(q[:, 0], 6).tolist(), np.round(qd[:, 0], 6).tolist()
    ([0.2, 0.51831], [1.0, 0.0])
    """

    base_frequency_hz: float
    a: np.ndarray
    b: np.ndarray
    q0: np.ndarray

    def __post_init__(self):
        f = self.base_frequency_hz
        if isinstance(f, bool) or not isinstance(f, (int, float, np.floating, np.integer)) \
                or not math.isfinite(f) or f <= 0:
            raise ExcitationError(f"base_frequency_hz must be a positive finite number, got {f!r}")
        a = np.asarray(self.a, float)
        if a.ndim != 2 or a.shape[1] < 1:
            raise ExcitationError(f"a: expected shape (joints, harmonics), got {a.shape}")
        object.__setattr__(self, "base_frequency_hz", float(f))
        object.__setattr__(self, "a", _readonly(a, a.shape, "a"))
        object.__setattr__(self, "b", _readonly(self.b, a.shape, "b"))
        object.__setattr__(self, "q0", _readonly(self.q0, (a.shape[0],), "q0"))

    @property
    def n(self) -> int:
        return self.a.shape[0]

    @property
    def harmonics(self) -> int:
        return self.a.shape[1]

    @property
    def period(self) -> float:
        """T = 1 / base_frequency_hz (s)."""
        return 1.0 / self.base_frequency_hz

    def coefficients(self) -> np.ndarray:
        """(n, 2H + 1): row i is [a_i1 .. a_iH, b_i1 .. b_iH, q0_i] (the optimiser's variables)."""
        return np.hstack([self.a, self.b, self.q0[:, None]])

    @classmethod
    def from_coefficients(cls, base_frequency_hz: float, x) -> "FourierTrajectory":
        """Inverse of :meth:`coefficients`."""
        x = np.asarray(x, float)
        H = (x.shape[1] - 1) // 2
        return cls(base_frequency_hz, x[:, :H], x[:, H:2 * H], x[:, 2 * H])

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Analytic (q, qd, qdd) at the times t (s): three arrays (N, n)."""
        t = np.atleast_1d(np.asarray(t, float))
        if t.ndim != 1:
            raise ExcitationError(f"t: expected a 1-D array of times, got shape {t.shape}")
        X = self.coefficients()
        return tuple(B @ X.T for B in _basis(t, self.base_frequency_hz, self.harmonics))


# ----------------------------------------------------------------------------- limits

@dataclass(frozen=True, eq=False)
class ExcitationLimits:
    """What the excitation may use, per joint (SI units).

    ``lower``, ``upper``: usable positions (rad), the robot's limits already shrunk by
    ``margin`` (rad, recorded for the report); ``velocity`` (rad/s) and ``acceleration``
    (rad/s^2): bounds on |qd| and |qdd|."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    margin: float = 0.0

    def __post_init__(self):
        lower = np.atleast_1d(np.asarray(self.lower, float))
        n = lower.shape[0]
        for name in ("lower", "upper", "velocity", "acceleration"):
            value = np.asarray(getattr(self, name), float)
            if value.ndim == 0 and name in ("velocity", "acceleration"):
                value = np.full(n, float(value))  # one number for every joint
            object.__setattr__(self, name, _readonly(value, (n,), f"limits.{name}"))
        for name, unit in (("velocity", "rad/s"), ("acceleration", "rad/s^2")):
            value = getattr(self, name)
            if np.any(value <= 0):
                i = int(np.argmax(value <= 0))
                raise ExcitationError(f"{name} limit of joint {i + 1} must be positive, got {value[i]:g} {unit}")
        bad = np.flatnonzero(self.lower >= self.upper)
        if bad.size:
            i = int(bad[0])
            raise ExcitationError(
                f"joint {i + 1}: empty position range after the margin of {self.margin:g} rad "
                f"(lower {self.lower[i]:g} >= upper {self.upper[i]:g} rad)")
        object.__setattr__(self, "margin", float(self.margin))

    @property
    def n(self) -> int:
        return self.lower.shape[0]

    def as_dict(self) -> dict:
        return {"lower": self.lower.tolist(), "upper": self.upper.tolist(),
                "velocity": self.velocity.tolist(), "acceleration": self.acceleration.tolist(),
                "margin": self.margin}


def default_limits(model: RobotModel, velocity=DEFAULT_VELOCITY, acceleration=DEFAULT_ACCELERATION,
                   margin: float = DEFAULT_MARGIN) -> ExcitationLimits:
    """Limits from the robot description: its position limits shrunk by ``margin`` (rad) on
    each side, and ``velocity`` (rad/s) and ``acceleration`` (rad/s^2), one number for all
    joints or one per joint (the descriptions have no velocity limits).

    >>> from kindyngen.readers.yaml_description import load_robot                # doctest: +SKIP
    >>> lim = default_limits(load_robot("robots/lwr4.yaml"))  # doctest: +SKIP
    >>> round(float(lim.upper[1]), 4), float(lim.velocity[1])  # doctest: +SKIP
    (1.9944, 1.0)
    """
    margin = float(margin)
    if not math.isfinite(margin) or margin < 0:
        raise ExcitationError(f"margin must be a non-negative number of radians, got {margin!r}")
    refuse_mimic_joints(model)
    return ExcitationLimits(lower=model.lower + margin, upper=model.upper - margin,
                            velocity=velocity, acceleration=acceleration, margin=margin)


# ----------------------------------------------------------------------------- objective

def friction_columns(qd: np.ndarray, eps: float | None = None) -> np.ndarray:
    """(N, n, 3 n): viscous ``qd_i``, Coulomb ``sign(qd_i)`` (``tanh(qd_i / eps)`` with eps)
    and offset ``1`` on row i, ordered as :func:`friction_column_names` (by effect, then
    joint): the columns of :mod:`kindyngen.measured.effect_columns`."""
    return effect_columns(FRICTION_EFFECTS, qd, None, eps)


def friction_column_names(n: int) -> tuple[str, ...]:
    """``fv1..fvn, fc1..fcn, f01..f0n`` (:func:`kindyngen.measured.effect_columns.effect_names`)."""
    return effect_names(FRICTION_EFFECTS, n)


def sample_times(trajectory: FourierTrajectory, samples_per_period: int) -> np.ndarray:
    """The grid the condition number is taken on: ``t_k = k T / samples``, k = 0 .. samples - 1."""
    return np.arange(samples_per_period) * (trajectory.period / samples_per_period)


def stacked_regressor(regressor: TorqueRegressor, trajectory: FourierTrajectory, samples_per_period: int,
                      friction: bool = True, coulomb_smoothing: float | None = None) -> np.ndarray:
    """The regressor rows of one period stacked: (samples n, base columns [+ 3 n friction]),
    sample by sample (rows 0..n-1: the joints at t_0); ``coulomb_smoothing``: eps (rad/s) of
    a ``tanh(qd / eps)`` Coulomb column, None for ``sign(qd)``."""
    q, qd, qdd = trajectory.evaluate(sample_times(trajectory, samples_per_period))
    W = regressor(q, qd, qdd)
    if friction:
        W = np.concatenate([W, friction_columns(qd, coulomb_smoothing)], axis=2)
    return W.reshape(-1, W.shape[2])


def condition_number(regressor: TorqueRegressor, trajectory: FourierTrajectory, samples_per_period: int,
                     friction: bool = True, coulomb_smoothing: float | None = None) -> float:
    """2-norm condition number of :func:`stacked_regressor` (inf when rank-deficient).

    ``regressor``: ``TorqueRegressor(model)`` (built once: it compiles the regressor)."""
    W = stacked_regressor(regressor, trajectory, samples_per_period, friction, coulomb_smoothing)
    return condition_number_2norm(W)


class _Objective:
    """A smooth surrogate of log(cond W(x)) and its gradient, and cond W(x) itself.

    Surrogate: ``log(||s||_p ||1/s||_p) = (log sum s_i^p + log sum s_i^-p) / p`` over the
    singular values s_i (p = ``POWER``), the p-norm stand-ins for s_max and 1/s_min.  It is
    at least log cond and at most ``2 log(columns) / p`` above it, and, unlike
    ``s_max / s_min``, smooth where singular values meet, which is where the minimum of the
    condition number tends to lie; on the plain log cond SLSQP (BFGS) wandered off after a
    few iterations (LWR: 280 -> 97 after 5 iterations, then up to 1e3 and back).  The log makes the scale independent of the robot's units.

    Gradient: with ``d s_i = u_i^T dW v_i`` it needs only the regressor's partial
    derivatives per sample (6 n batched evaluations by central differences: the regressor is
    a polynomial of degree 2 in qd and 1 in qdd and smooth in q) and one eigen-decomposition,
    instead of one decomposition per variable (77 for the LWR) with finite differences.
    sign(qd) is piecewise constant and taken with derivative zero (the objective jumps when
    a sample's velocity changes sign; the best feasible iterate is kept anyway)."""

    STEP = 1e-6
    POWER = 10

    def __init__(self, regressor: TorqueRegressor, t: np.ndarray, frequency_hz: float, harmonics: int,
                 friction: bool, eps: float | None):
        self.R, self.friction, self.eps = regressor, friction, eps
        self.n, self.H = regressor.n, harmonics
        self.Bq, self.Bv, self.Ba = _basis(t, frequency_hz, harmonics)
        self._key, self._value = None, None

    def evaluate(self, x):
        """(surrogate, its gradient, cond), cached for the last x (SLSQP asks for f and g apart)."""
        key = x.tobytes()
        if key == self._key:
            return self._value
        X = x.reshape(self.n, 2 * self.H + 1)
        states = [B @ X.T for B in (self.Bq, self.Bv, self.Ba)]        # q, qd, qdd: (N, n)
        W = self.R(*states)
        p = W.shape[2]
        if self.friction:
            W = np.concatenate([W, friction_columns(states[1], self.eps)], axis=2)
        N, n, m = W.shape
        W2 = W.reshape(N * n, m)
        # singular values and right vectors from the Gram matrix (m x m): ten times faster
        # than the SVD of W, and accurate to about eps cond^2 relative (1e-10 at cond 1e3);
        # the reported condition number is recomputed by SVD
        lam, V = np.linalg.eigh(W2.T @ W2)
        s, V = np.sqrt(np.maximum(lam[::-1], 0.0)), V[:, ::-1]
        if not s[-1] > 1e-7 * s[0]:
            # (numerically) rank-deficient: no useful gradient; a large value keeps the line
            # search away
            value = (float(np.log(1e7)) + 1.0, np.zeros_like(x), math.inf)
        else:
            P = self.POWER
            r_hi, r_lo = (s / s[0]) ** P, (s[-1] / s) ** P
            f = np.log(s[0] / s[-1]) + (np.log(r_hi.sum()) + np.log(r_lo.sum())) / P
            c = r_hi / r_hi.sum() / s - r_lo / r_lo.sum() / s          # d f / d s_i
            # d f / d W = sum_i c_i u_i v_i^T with u_i = W v_i / s_i
            G = (W2 @ ((V * (c / s)) @ V.T)).reshape(N, n, m)
            Gr = G[:, :, :p]
            g = [np.zeros((N, n)) for _ in states]                     # d f / d q_j(t_k) ...
            h = self.STEP
            for kind in range(3):
                for j in range(n):
                    plus, minus = [a.copy() for a in states], [a.copy() for a in states]
                    plus[kind][:, j] += h
                    minus[kind][:, j] -= h
                    dY = (self.R(*plus) - self.R(*minus)) / (2 * h)
                    g[kind][:, j] = np.einsum("trc,trc->t", Gr, dY)
            if self.friction:
                rows = np.arange(n)
                g[1] += G[:, rows, p + rows]                            # viscous: d qd / d qd = 1
                if self.eps is not None:                                # smooth Coulomb: tanh
                    slope = (1.0 - np.tanh(states[1] / self.eps) ** 2) / self.eps
                    g[1] += G[:, rows, p + n + rows] * slope
            grad = g[0].T @ self.Bq + g[1].T @ self.Bv + g[2].T @ self.Ba
            value = (float(f), grad.ravel(), float(s[0] / s[-1]))
        self._key, self._value = key, value
        return value


# ----------------------------------------------------------------------------- optimisation

@dataclass(frozen=True, eq=False)
class ExcitationResult:
    """An optimised excitation.

    ``condition_number``: 2-norm condition number of the stacked regressor (base rigid-body
    columns, then ``friction_column_names`` if ``friction``) on ``samples_per_period`` samples
    ``t_k = k T / samples_per_period``; ``initial_condition_number``: the same for the random
    feasible start.  ``feasible`` and the ``max_*_violation`` values (rad, rad/s, rad/s^2;
    0 when within) come from a grid ``CHECK_DENSITY`` (10) times denser, against the limits
    themselves (not the tightened ones the optimiser used)."""

    robot: str
    trajectory: FourierTrajectory
    limits: ExcitationLimits
    condition_number: float
    initial_condition_number: float
    iterations: int
    feasible: bool
    max_position_violation: float
    max_velocity_violation: float
    max_acceleration_violation: float
    friction: bool
    samples_per_period: int
    columns: tuple[str, ...]
    coulomb_smoothing: float | None
    rest_at_start: bool
    seed: int
    message: str


def violations(trajectory: FourierTrajectory, limits: ExcitationLimits, samples: int) -> tuple[float, float, float]:
    """Largest excess over the position, velocity and acceleration limits on ``samples``
    evenly spaced times of one period (0 when within)."""
    q, qd, qdd = trajectory.evaluate(np.arange(samples) * (trajectory.period / samples))
    position = np.maximum(q - limits.upper, limits.lower - q).max()
    velocity = (np.abs(qd) - limits.velocity).max()
    acceleration = (np.abs(qdd) - limits.acceleration).max()
    return tuple(max(0.0, float(v)) for v in (position, velocity, acceleration))


def _check_int(value, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ExcitationError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def optimise_excitation(model: RobotModel, limits: ExcitationLimits, harmonics: int = DEFAULT_HARMONICS,
                        base_frequency_hz: float = DEFAULT_BASE_FREQUENCY_HZ, samples_per_period: int | None = None,
                        friction: bool = True, seed: int = 0, max_iterations: int = DEFAULT_MAX_ITERATIONS,
                        progress: Callable[[str], None] | None = None, rest_at_start: bool = True) -> ExcitationResult:
    """Fourier coefficients (a, b, q0) minimising the condition number of the stacked regressor.

    ``samples_per_period`` (default ``SAMPLES_PER_HARMONIC * harmonics``): regressor samples
    for the objective.  ``rest_at_start`` (default True) adds ``qd(0) = qdd(0) = 0`` per
    joint (so also at t = T): a robot at rest at ``q(0)`` can start the trajectory, and
    repeat it, without a jump in velocity or acceleration; it needs ``harmonics >= 2``.
    The start is random (``seed``) with each joint's oscillation scaled to 90 % of its
    tightest limit, centred in its range; the same arguments give the same result.
    Optimiser: SLSQP (smooth objective, linear inequality and equality constraints with exact
    Jacobians) for at most ``max_iterations`` iterations; ``progress`` receives one line per
    iteration.

    >>> from kindyngen.readers.yaml_description import load_robot                                  # doctest: +SKIP
    >>> model = load_robot("robots/lwr4.yaml")                                  # doctest: +SKIP
    >>> r = optimise_excitation(model, default_limits(model), harmonics=3, max_iterations=20)  # doctest: +SKIP
    >>> r.feasible, r.trajectory.a.shape                                        # doctest: +SKIP
    (True, (7, 3))
    """
    harmonics = _check_int(harmonics, "harmonics", 1)
    if isinstance(base_frequency_hz, bool) or not isinstance(base_frequency_hz, (int, float, np.number)) \
            or not math.isfinite(base_frequency_hz) or base_frequency_hz <= 0:
        raise ExcitationError(f"base_frequency_hz must be a positive finite number, got {base_frequency_hz!r}")
    base_frequency_hz = float(base_frequency_hz)
    if not isinstance(limits, ExcitationLimits):
        raise ExcitationError(f"limits must be an ExcitationLimits (see default_limits), got {type(limits).__name__}")
    if limits.n != model.n:
        raise ExcitationError(f"limits are for {limits.n} joints, the robot {model.name!r} has {model.n}")
    if rest_at_start and harmonics < 2:
        raise ExcitationError("rest_at_start needs harmonics >= 2 (with one harmonic it leaves no motion)")
    if samples_per_period is None:
        samples_per_period = SAMPLES_PER_HARMONIC * harmonics
    # at least four samples per cycle of the highest harmonic (two per cycle of the products
    # qd_i qd_j in the regressor), or the grid aliases the motion
    samples_per_period = _check_int(samples_per_period, "samples_per_period", 4 * harmonics)
    max_iterations = _check_int(max_iterations, "max_iterations", 0)
    seed = _check_int(seed, "seed", 0)
    if progress is not None and not callable(progress):
        raise ExcitationError("progress must be a callable taking one string")
    try:
        R = torque_regressor(model)
    except ValueError as exc:
        raise ExcitationError(str(exc)) from exc

    n, H = model.n, harmonics
    eps = coulomb_eps(model) if friction else None
    columns = tuple(R.names) + (friction_column_names(n) if friction else ())
    if samples_per_period * n < len(columns):
        raise ExcitationError(f"samples_per_period={samples_per_period} gives {samples_per_period * n} regressor rows, "
                              f"fewer than the {len(columns)} columns")

    # --- constraints: |q - centre| <= kappa r, |qd| <= kappa v, |qdd| <= kappa a on M points
    M = max(CONSTRAINT_DENSITY * samples_per_period, 20 * H)
    kappa = 1.0 - 0.5 * (math.pi * H / M) ** 2          # Bernstein bound, module docstring
    kappa_slsqp = kappa - 1e-6                            # room for SLSQP's round-off
    period = 1.0 / base_frequency_hz
    tc = np.arange(M) * (period / M)
    Bq, Bv, Ba = _basis(tc, base_frequency_hz, H)
    eye = np.eye(n)
    Kq, Kv, Ka = (np.kron(eye, B) for B in (Bq, Bv, Ba))   # row i M + k: joint i, time k
    centre = 0.5 * (limits.lower + limits.upper)
    half = 0.5 * (limits.upper - limits.lower)
    A = np.vstack([-Kq, Kq, -Kv, Kv, -Ka, Ka])
    rep = lambda v: np.repeat(v, M)  # noqa: E731  (per joint -> per constraint row)

    def bounds(k):
        return np.concatenate([rep(k * half + centre), rep(k * half - centre), rep(k * limits.velocity),
                               rep(k * limits.velocity), rep(k * limits.acceleration), rep(k * limits.acceleration)])

    h_slsqp, h_kappa = bounds(kappa_slsqp), bounds(kappa)
    constraints = [{"type": "ineq", "fun": lambda x: h_slsqp + A @ x, "jac": lambda x: A}]
    if rest_at_start:
        # qd_i(0) = sum_k a_ik = 0, qdd_i(0) = w sum_k k b_ik = 0 (divided by w: well scaled)
        row = np.concatenate([np.ones(H), np.zeros(H), [0.0]])
        row2 = np.concatenate([np.zeros(H), np.arange(1, H + 1) / H, [0.0]])
        E = np.vstack([np.kron(eye, row), np.kron(eye, row2)])
        constraints.append({"type": "eq", "fun": lambda x: E @ x, "jac": lambda x: E})
    else:
        E = np.zeros((0, n * (2 * H + 1)))

    def feasible(x) -> bool:
        return bool(np.all(h_kappa + A @ x >= 0) and np.all(np.abs(E @ x) <= 1e-9))

    # --- start: random coefficients, larger for low harmonics (as a smooth motion), each
    # joint centred and scaled into its limits
    rng = np.random.default_rng(seed)
    k = np.arange(1, H + 1)
    a0 = rng.standard_normal((n, H)) / k
    b0 = rng.standard_normal((n, H)) / k
    if rest_at_start:
        a0 -= a0.mean(axis=1, keepdims=True)
        b0 -= np.outer(b0 @ k, k) / (k @ k)
    q_osc, qd_osc, qdd_osc = (B @ np.hstack([a0, b0, np.zeros((n, 1))]).T for B in (Bq, Bv, Ba))
    with np.errstate(divide="ignore"):
        scale = 0.9 * kappa * np.minimum.reduce([half / np.abs(q_osc).max(axis=0),
                                                 limits.velocity / np.abs(qd_osc).max(axis=0),
                                                 limits.acceleration / np.abs(qdd_osc).max(axis=0)])
    x0 = np.hstack([a0 * scale[:, None], b0 * scale[:, None], centre[:, None]]).ravel()

    objective = _Objective(R, np.arange(samples_per_period) * (period / samples_per_period),
                           base_frequency_hz, H, friction, eps)
    start = FourierTrajectory.from_coefficients(base_frequency_hz, x0.reshape(n, 2 * H + 1))
    initial_cond = condition_number(R, start, samples_per_period, friction, eps)
    # the best feasible point by the true condition number (the objective is its surrogate)
    best = {"x": x0.copy(), "cond": objective.evaluate(x0)[2]}
    count = [0]

    def consider(x):
        cond = objective.evaluate(x)[2]
        if cond < best["cond"] and feasible(x):
            best["x"], best["cond"] = x.copy(), cond

    def callback(xk):
        count[0] += 1
        consider(xk)
        if progress is not None:
            cond = objective.evaluate(xk)[2]
            progress(f"excitation: iteration {count[0]}/{max_iterations}: condition number {cond:.6g} "
                     f"(best feasible {best['cond']:.6g})")

    if progress is not None:
        progress(f"excitation: {model.name}, {n} joints x {H} harmonics, {len(columns)} columns, "
                 f"start condition number {initial_cond:.6g}")
    if max_iterations > 0:
        result = minimize(lambda x: objective.evaluate(x)[0], x0, jac=lambda x: objective.evaluate(x)[1],
                          method="SLSQP", constraints=constraints, callback=callback,
                          options={"maxiter": max_iterations, "ftol": 1e-9})
        consider(result.x)
        iterations, message = int(result.nit), str(result.message)
    else:
        iterations, message = 0, "no iterations requested"

    trajectory = FourierTrajectory.from_coefficients(base_frequency_hz, best["x"].reshape(n, 2 * H + 1))
    cond = condition_number(R, trajectory, samples_per_period, friction, eps)
    excess = violations(trajectory, limits, CHECK_DENSITY * samples_per_period)
    return ExcitationResult(robot=model.name, trajectory=trajectory, limits=limits, condition_number=cond,
                            initial_condition_number=float(initial_cond), iterations=iterations,
                            feasible=all(v == 0.0 for v in excess), max_position_violation=excess[0],
                            max_velocity_violation=excess[1], max_acceleration_violation=excess[2],
                            friction=bool(friction), samples_per_period=samples_per_period, columns=columns,
                            coulomb_smoothing=eps if friction else None,
                            rest_at_start=bool(rest_at_start), seed=seed, message=message)


# ----------------------------------------------------------------------------- files

def trajectory_header(n: int) -> list[str]:
    """``t, q1..qn, qd1..qdn, qdd1..qddn``: the project's log format (s, rad, rad/s, rad/s^2)."""
    return ["t"] + [f"{name}{i}" for name in ("q", "qd", "qdd") for i in range(1, n + 1)]


def write_trajectory_csv(path, trajectory: FourierTrajectory, rate_hz: float, periods: int = 1) -> int:
    """Write the trajectory sampled at ``rate_hz`` over ``periods`` periods, t = k / rate_hz
    for 0 <= t <= periods T (the end included: with ``rest_at_start`` it is back at rest at
    q(0)).  Numbers are written with 17 significant digits.  Returns the number of rows.

    >>> traj = FourierTrajectory(0.5, a=[[1.0]], b=[[0.0]], q0=[0.2])
    >>> import tempfile, os; path = os.path.join(tempfile.mkdtemp(), "x.csv")
    >>> write_trajectory_csv(path, traj, rate_hz=10)
    21
    >>> open(path).readline().strip()
    't,q1,qd1,qdd1'
    """
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float, np.number)) \
            or not math.isfinite(rate_hz) or rate_hz <= 0:
        raise ExcitationError(f"rate_hz must be a positive finite number, got {rate_hz!r}")
    periods = _check_int(periods, "periods", 1)
    # the small tolerance keeps the end sample when periods T rate is an integer up to round-off
    count = int(math.floor(periods * trajectory.period * rate_hz + 1e-9)) + 1
    t = np.arange(count) / float(rate_hz)
    q, qd, qdd = trajectory.evaluate(t)
    with open(Path(path), "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(trajectory_header(trajectory.n))
        for row in np.column_stack([t, q, qd, qdd]):
            writer.writerow([format(float(v), ".17g") for v in row])
    return count


def trajectory_document(result: ExcitationResult) -> dict:
    """The JSON document of :func:`write_trajectory_json` (plain Python values; an infinite
    condition number, of a rank-deficient design, as the string "Infinity": :mod:`kindyngen.json_text`)."""
    traj = result.trajectory
    return {
        "format": "kindyngen-excitation",
        "version": 1,
        "robot": result.robot,
        "formula": "q_i(t) = q0_i + sum_k [a_ik/(w k) sin(w k t) - b_ik/(w k) cos(w k t)], w = 2 pi f",
        "base_frequency_hz": traj.base_frequency_hz,
        "period_s": traj.period,
        "harmonics": traj.harmonics,
        "a": traj.a.tolist(),
        "b": traj.b.tolist(),
        "q0": traj.q0.tolist(),
        "limits": result.limits.as_dict(),
        "units": {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "a": "rad/s", "b": "rad/s",
                  "q0": "rad", "base_frequency_hz": "Hz"},
        "condition_number": json_number(float(result.condition_number)),
        "initial_condition_number": json_number(float(result.initial_condition_number)),
        "columns": list(result.columns),
        "friction": result.friction,
        "samples_per_period": result.samples_per_period,
        "coulomb_smoothing": result.coulomb_smoothing,
        "rest_at_start": result.rest_at_start,
        "iterations": result.iterations,
        "seed": result.seed,
        "feasible": result.feasible,
        "max_violation": {"position": result.max_position_violation, "velocity": result.max_velocity_violation,
                          "acceleration": result.max_acceleration_violation},
    }


def write_trajectory_json(path, result: ExcitationResult) -> None:
    """Write :func:`trajectory_document` as strict JSON (:func:`kindyngen.json_text.strict_json`)."""
    text = strict_json(trajectory_document(result), indent=2)
    Path(path).write_text(text + "\n")


def read_trajectory_json(path) -> FourierTrajectory:
    """The trajectory of a file written by :func:`write_trajectory_json`."""
    data = json.loads(Path(path).read_text())
    if not isinstance(data, dict) or data.get("format") != "kindyngen-excitation":
        raise ExcitationError(f"{path}: not a kindyngen excitation file")
    return FourierTrajectory(data["base_frequency_hz"], data["a"], data["b"], data["q0"])
