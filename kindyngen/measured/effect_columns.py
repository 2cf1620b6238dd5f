"""Joint effects beyond rigid bodies as regressor columns: friction, a torque offset and the
armature, linear in their coefficients, so that they are identified together with the base
parameters (append :func:`effect_columns` to the rigid-body rows).

Per joint i (1-based names; the same formulas as the generated code,
:mod:`kindyngen.algorithms.effect_torques`):

=====================  =========  ==========================================================
effect                 parameter  torque
=====================  =========  ==========================================================
``viscous_friction``   ``fv{i}``  ``fv_i * qd_i``
``coulomb_friction``   ``fc{i}``  ``fc_i * sign(qd_i)`` (``sign(0) = 0``), or
                                  ``fc_i * tanh(qd_i / eps)`` when ``eps`` (rad/s) is given
``torque_offset``      ``f0{i}``  ``f0_i`` (a constant bias of the sensor or drive)
``armature``           ``Ia{i}``  ``Ia_i * qdd_i`` (reflected rotor inertia)
=====================  =========  ==========================================================

Columns and names are ordered by effect in :data:`EFFECTS` order (whatever order the caller
lists them in), then by joint.  The column of joint i's coefficient is non-zero only on row i.

Note: the armature of a joint whose axis is fixed in the base (joint 1 of an arm on a fixed
base) has the same column as the first link's inertia about that axis, so the two can only be
identified as their sum (:func:`kindyngen.measured.estimation.least_squares` refuses and names
the direction).

Example:

>>> import numpy as np
>>> effect_names(("torque_offset", "viscous_friction"), 2)
('fv1', 'fv2', 'f01', 'f02')
>>> effect_columns("viscous_friction", np.array([[0.5, -2.0]]), None)[0]
array([[ 0.5,  0. ],
       [ 0. , -2. ]])
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

EFFECTS = ("viscous_friction", "coulomb_friction", "torque_offset", "armature")
#: effects on the measurement rather than torques at the joint (a description's joint keys
#: ``stiffness``, ``encoder_offset``, ``torque_gain``): ``ce{i}`` a compliance 1 / stiffness
#: (rad per N m), ``dq{i}`` an encoder offset (rad), ``gt{i}`` a relative torque-gain error.
#: Their columns depend on the model's torques (first order,
#: :func:`kindyngen.measured.discovery.sensing_columns`), so :func:`effect_columns` has none.
SENSING_EFFECTS = ("motor_side_elasticity", "encoder_offset", "torque_sensor_gain")
NONNEGATIVE = ("viscous_friction", "coulomb_friction", "armature", "motor_side_elasticity")   # physically >= 0
PREFIXES = {"viscous_friction": "fv", "coulomb_friction": "fc", "torque_offset": "f0", "armature": "Ia",
            "motor_side_elasticity": "ce", "encoder_offset": "dq", "torque_sensor_gain": "gt"}


def _effects(effects) -> tuple[str, ...]:
    """The requested effects checked and put in :data:`EFFECTS` order."""
    if isinstance(effects, str):
        effects = (effects,)
    effects = tuple(effects)
    known = EFFECTS + SENSING_EFFECTS
    for e in effects:
        if e not in known:
            close = difflib.get_close_matches(str(e), known, n=1, cutoff=0.0)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ValueError(f"unknown effect {e!r}; {hint}(known: {', '.join(known)})")
    duplicates = sorted({e for e in effects if effects.count(e) > 1})
    if duplicates:
        raise ValueError(f"effect(s) listed more than once: {', '.join(duplicates)}")
    return tuple(e for e in EFFECTS + SENSING_EFFECTS if e in effects)


def effect_names(effects, n: int) -> tuple[str, ...]:
    """Parameter names of ``effects`` for ``n`` joints: by effect (in :data:`EFFECTS` order,
    then :data:`SENSING_EFFECTS` order), then joint, e.g. ``('fv1', ..., 'fvn', 'fc1', ...)``."""
    return tuple(f"{PREFIXES[e]}{i + 1}" for e in _effects(effects) for i in range(int(n)))


def effect_of(name: str) -> str:
    """The effect a parameter name belongs to: ``effect_of('fc3') == 'coulomb_friction'``."""
    for effect, prefix in PREFIXES.items():
        if name.startswith(prefix) and name[len(prefix):].isdigit():
            return effect
    raise ValueError(f"{name!r} is not an effect parameter name (expected one of "
                     f"{', '.join(p + '<joint>' for p in PREFIXES.values())})")


def _joint_array(a, what: str) -> np.ndarray:
    a = np.asarray(a, float)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2:
        raise ValueError(f"{what} must be samples x joints, got shape {a.shape}")
    return a


def coulomb_eps(model) -> float | None:
    """The smoothing velocity of a robot description's Coulomb friction (rad/s), or None for
    ``sign(qd)``."""
    return float(model.coulomb_smoothing) if model.coulomb_smoothing is not None else None


def effect_columns(effects, qd, qdd, eps: float | None = None) -> np.ndarray:
    """Regressor columns of ``effects`` at N samples: array (N, n, k) with k = len(effects) * n,
    so that the effect torques are ``columns @ coefficients`` (coefficients ordered as
    :func:`effect_names`).  ``qd``, ``qdd``: samples x n (``qdd`` may be None when the armature
    is not requested); ``eps`` (rad/s, > 0): smooth Coulomb friction ``tanh(qd / eps)``."""
    effects = _effects(effects)
    sensing = [e for e in effects if e in SENSING_EFFECTS]
    if sensing:
        raise ValueError(f"{', '.join(sensing)} act on the measurement: their columns depend on the model "
                         f"(kindyngen.measured.discovery.sensing_columns)")
    qd = _joint_array(qd, "qd")
    N, n = qd.shape
    if "armature" in effects:
        if qdd is None:
            raise ValueError("the armature column needs qdd")
        qdd = _joint_array(qdd, "qdd")
        if qdd.shape != qd.shape:
            raise ValueError(f"qd and qdd have different shapes {qd.shape} and {qdd.shape}")
    if eps is not None and not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"the Coulomb smoothing eps must be a positive number of rad/s, got {eps!r}")
    out = np.zeros((N, n, len(effects) * n))
    rows = np.arange(n)
    for k, effect in enumerate(effects):
        if effect == "viscous_friction":
            value = qd
        elif effect == "coulomb_friction":
            value = np.sign(qd) if eps is None else np.tanh(qd / eps)
        elif effect == "torque_offset":
            value = np.ones_like(qd)
        else:
            value = qdd
        out[:, rows, k * n + rows] = value
    return out


def effect_torques(effects, values, qd, qdd, eps: float | None = None) -> np.ndarray:
    """Effect torques (N, n) for coefficients ``values``: an array ordered as
    :func:`effect_names` or a mapping from those names to numbers (every name required)."""
    columns = effect_columns(effects, qd, qdd, eps)
    names = effect_names(effects, columns.shape[1])
    if isinstance(values, dict):
        missing = [name for name in names if name not in values]
        unknown = [name for name in values if name not in names]
        if missing or unknown:
            raise ValueError(f"effect coefficients: missing {missing}, unknown {unknown}")
        values = [values[name] for name in names]
    values = np.asarray(values, float).reshape(-1)
    if values.shape != (len(names),):
        raise ValueError(f"{len(values)} coefficients for {len(names)} effect parameters {names}")
    return columns @ values


@dataclass(frozen=True)
class JointLaws:
    """A description's joint effects as float arrays (per joint; zeros where not declared):
    the coefficients of :mod:`kindyngen.algorithms.effect_torques`' laws, numerically.
    ``stribeck_velocity`` is 1 where no Stribeck term is declared, ``ripple_order`` 0 where no
    ripple is."""

    viscous: np.ndarray
    coulomb: np.ndarray
    offset: np.ndarray
    armature: np.ndarray
    stribeck: np.ndarray
    stribeck_velocity: np.ndarray
    load: np.ndarray
    ripple_sin: np.ndarray
    ripple_cos: np.ndarray
    ripple_order: np.ndarray
    eps: float | None


@lru_cache(maxsize=64)
def joint_laws(model) -> JointLaws:
    """The description's joint effects as float arrays (:class:`JointLaws`)."""
    def column(get):
        return np.array([float(get(i)) for i in range(model.n)])
    ripple = [j.ripple for j in model.joints]
    return JointLaws(
        viscous=column(lambda i: model.friction(i).viscous), coulomb=column(lambda i: model.friction(i).coulomb),
        offset=column(lambda i: model.friction(i).offset), armature=column(model.armature),
        stribeck=column(lambda i: model.friction(i).stribeck),
        stribeck_velocity=column(lambda i: model.friction(i).stribeck_velocity or 1),
        load=column(lambda i: model.friction(i).load or 0),
        ripple_sin=column(lambda i: ripple[i].sin_amplitude if ripple[i] else 0),
        ripple_cos=column(lambda i: ripple[i].cos_amplitude if ripple[i] else 0),
        ripple_order=column(lambda i: ripple[i].order if ripple[i] else 0), eps=coulomb_eps(model))


def coulomb_shape(qd, eps: float | None) -> np.ndarray:
    """``sign(qd)`` (0 at 0), or ``tanh(qd / eps)``."""
    return np.sign(qd) if eps is None else np.tanh(qd / eps)


def law_torques(model, q, qd, qdd, rigid) -> np.ndarray:
    """The joint torques (N, n) of a description from its rigid-body torques ``rigid`` (N, n)
    and its effects, numerically, the laws of :mod:`kindyngen.algorithms.effect_torques`:
    ``y + fl |y| s + fv qd + fc s + fs exp(-(qd / vs)^2) s + rs sin(k q) + rc cos(k q) + f0``
    with ``y = rigid + Ia qdd`` and ``s`` the Coulomb shape.

    >>> from kindyngen.readers.yaml_description import parse_robot
    >>> m = parse_robot({"name": "one", "dh": "none", "gravity": [0, 0, -9.81], "joints": [{"lower": -3,
    ...     "upper": 3, "friction": {"coulomb": 0.5, "load": 0.1}, "ripple": {"sin": 0.2, "order": 6}}],
    ...     "links": [{"mass": 1, "com": [0, 0, 0], "inertia": [0.01, 0.01, 0.01, 0, 0, 0]}]})
    >>> float(law_torques(m, [[0.0]], [[1.0]], [[0.0]], [[2.0]])[0, 0])      # 2 + 0.1 * 2 + 0.5 + 0.2 sin(0)
    2.7
    """
    q, qd, qdd, rigid = (np.asarray(a, float) for a in (q, qd, qdd, rigid))
    return applied_laws(joint_laws(model), q, qd, qdd, rigid)[0]


def applied_laws(laws: JointLaws, q, qd, qdd, rigid) -> tuple:
    """``(tau, y, s)``: the joint torques of ``laws`` on the rigid-body torques ``rigid`` (see
    :func:`law_torques`), the transmitted torque ``y = rigid + Ia qdd`` and the Coulomb shape
    ``s`` of qd (the one place the laws are written numerically)."""
    s = coulomb_shape(qd, laws.eps)
    y = rigid + laws.armature * qdd
    tau = y + laws.load * np.abs(y) * s + laws.viscous * qd + laws.coulomb * s + laws.offset
    if np.any(laws.stribeck):
        tau = tau + laws.stribeck * np.exp(-(qd / laws.stribeck_velocity) ** 2) * s
    if np.any(laws.ripple_order):
        tau = tau + laws.ripple_sin * np.sin(laws.ripple_order * q) + laws.ripple_cos * np.cos(laws.ripple_order * q)
    return tau, y, s
