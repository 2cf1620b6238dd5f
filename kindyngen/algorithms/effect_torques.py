"""Joint effects beyond rigid bodies, as the robot description declares them, in symbolic form
for the derivations (a payload is a rigid body and is merged into the last link's parameters
instead, :mod:`kindyngen.model.inertial_parameters`).

Per joint i (the formulas the measured-data side uses too, :mod:`kindyngen.measured.effect_columns`),
with ``s_i`` the Coulomb shape ``sign(qd_i)`` (``sign(0) = 0``, generated as two selects), or
``tanh(qd_i / eps)`` when the description sets ``coulomb_smoothing: eps``:

* the *additive* effects ``a_i(q, qd) = fv_i qd_i + fc_i s_i + fs_i exp(-(qd_i / vs_i)^2) s_i
  + rs_i sin(k_i q_i) + rc_i cos(k_i q_i) + f0_i``: viscous, Coulomb and Stribeck friction,
  the position ripple (``k_i`` periods per revolution) and a torque offset;
* the armature ``Ia_i`` (reflected rotor inertia): ``Ia_i qdd_i`` in the torque, ``Ia_i`` on
  the diagonal of M;
* the load-dependent friction ``fl_i |y_i| s_i`` (``0 <= fl_i < 1``) on the torque the joint
  transmits apart from friction, ``y = tau_rigid(q, qd, qdd) + Ia qdd``.

So ``tau_i = y_i + fl_i |y_i| s_i + a_i`` (:func:`joint_torques`).  The forward dynamics
inverts it in closed form (:func:`transmitted_torques`): with ``u = tau - a``, ``y = u / (1 +
fl s sign(u))`` (``y`` and ``u`` have the same sign because ``fl |s| < 1``), then ``qdd = (M
+ diag(Ia))^-1 (y - c - g)``.

They enter ``tau``, ``fd``, ``M`` and ``M_lagrange`` (the armature) and the derivatives;
``c``, ``g``, ``S`` and the Christoffel route are unchanged (the armature is constant, friction
is not a Coriolis term).

Example:

>>> import symengine as se
>>> coulomb_shape(se.Symbol("v"), None)
Piecewise((1, 0 < v), (-1, v < 0), (0, True))
"""
from __future__ import annotations

import symengine as se

from ..model.robot_model import RobotModel

EFFECT_PARAMETERS = {"viscous_friction": "fv", "coulomb_friction": "fc", "torque_offset": "f0", "armature": "Ia",
                     "stribeck_friction": "fs", "position_ripple": ("rs", "rc"), "load_dependent_friction": "fl"}


def coulomb_shape(v: se.Basic, eps) -> se.Basic:
    """``sign(v)`` as a branch-free select, or ``tanh(v / eps)``."""
    if eps is not None:
        return se.tanh(v / se.sympify(eps))
    return se.Piecewise((se.Integer(1), se.StrictLessThan(0, v)), (se.Integer(-1), se.StrictLessThan(v, 0)),
                        (se.Integer(0), se.true))


def stribeck_shape(v: se.Basic, velocity, eps) -> se.Basic:
    """``exp(-(v / vs)^2) s(v)``: the static friction in excess of Coulomb's, fading with speed."""
    return se.exp(-(v / se.sympify(velocity)) ** 2) * coulomb_shape(v, eps)


def _ripple_shapes(model: RobotModel, i: int, q):
    r = model.joints[i].ripple
    return se.sin(r.order * q[i]), se.cos(r.order * q[i])


def additive_torques(model: RobotModel, q, qd) -> list[se.Basic]:
    """Per joint, ``a_i(q, qd)``: viscous, Coulomb and Stribeck friction, the ripple and the
    offset (exact coefficients baked in; zero where none is declared); ``qd`` may be None
    (zero), ``q`` only when no joint declares a ripple."""
    out = []
    for i in range(model.n):
        f = model.friction(i)
        terms = []
        if qd is not None and f.viscous != 0:
            terms.append(se.sympify(f.viscous) * qd[i])
        if qd is not None and f.coulomb != 0:
            terms.append(se.sympify(f.coulomb) * coulomb_shape(qd[i], model.coulomb_smoothing))
        if qd is not None and f.stribeck != 0:
            terms.append(se.sympify(f.stribeck) * stribeck_shape(qd[i], f.stribeck_velocity, model.coulomb_smoothing))
        if f.offset != 0:
            terms.append(se.sympify(f.offset))
        r = model.joints[i].ripple
        if r is not None and (r.sin_amplitude != 0 or r.cos_amplitude != 0):
            sin, cos = _ripple_shapes(model, i, q)
            terms += [se.sympify(r.sin_amplitude) * sin, se.sympify(r.cos_amplitude) * cos]
        out.append(se.Add(*terms) if terms else se.Integer(0))
    return out


def effect_torques(model: RobotModel, qd, qdd, q=None) -> list[se.Basic]:
    """Per joint, the effect torques of a description *without* load-dependent friction:
    ``a_i(q, qd) + Ia_i qdd_i`` (``qd``/``qdd`` may be None: zero)."""
    if has_load_friction(model):
        raise ValueError(f"{model.name}: with load-dependent friction the effects are not additive "
                         f"(joint_torques, transmitted_torques)")
    out = []
    for i, a in enumerate(additive_torques(model, q, qd)):
        terms = [] if a == 0 else [a]
        if qdd is not None and model.armature(i) != 0:
            terms.append(se.sympify(model.armature(i)) * qdd[i])
        out.append(se.Add(*terms) if terms else se.Integer(0))
    return out


def has_load_friction(model: RobotModel) -> bool:
    return any(model.friction(i).load not in (None, 0) for i in range(model.n))


def _load_factor(model: RobotModel, i: int, qd, sign_of) -> se.Basic:
    """``1 + fl_i s_i sign(x)``, x the argument whose sign is taken."""
    f = model.friction(i)
    return se.Integer(1) + se.sympify(f.load) * coulomb_shape(qd[i], model.coulomb_smoothing) * \
        coulomb_shape(sign_of, None)


def joint_torques(model: RobotModel, rigid, q, qd, qdd) -> list[se.Basic]:
    """The joint torques from the rigid-body torques ``rigid`` (per joint): ``y + fl |y| s +
    a(q, qd)`` with ``y = rigid + Ia qdd``."""
    if not has_load_friction(model):
        return [t + e for t, e in zip(rigid, effect_torques(model, qd, qdd, q))]
    out = []
    for i, (t, a) in enumerate(zip(rigid, additive_torques(model, q, qd))):
        y = t + se.sympify(model.armature(i)) * qdd[i] if qdd is not None and model.armature(i) != 0 else t
        load = model.friction(i).load
        if load not in (None, 0):
            y = y + se.sympify(load) * se.Abs(y) * coulomb_shape(qd[i], model.coulomb_smoothing)
        out.append(y + a)
    return out


def transmitted_torques(model: RobotModel, tau, q, qd) -> list[se.Basic]:
    """``y`` (per joint) from the applied torques ``tau``: ``u = tau - a(q, qd)``, ``y = u /
    (1 + fl s sign(u))``, the torque that accelerates the rigid bodies and the armature
    (``fd``: ``qdd = (M + diag(Ia))^-1 (y - c - g)``)."""
    out = []
    for i, (t, a) in enumerate(zip(tau, additive_torques(model, q, qd))):
        u = t - a if a != 0 else t
        if model.friction(i).load not in (None, 0):
            u = u / _load_factor(model, i, qd, u)
        out.append(u)
    return out


def with_armature(model: RobotModel, M):
    """M (nested lists) with each joint's armature added on the diagonal."""
    out = [list(row) for row in M]
    for i in range(model.n):
        if model.armature(i) != 0:
            out[i][i] = out[i][i] + se.sympify(model.armature(i))
    return out


def additive_derivatives(model: RobotModel, q, qd) -> tuple[list, list]:
    """Per joint, ``(da_i/dq_i, da_i/dqd_i)``: the additive effects depend on the joint's own
    q and qd only.  The sign shape contributes 0 (its derivative wherever it has one),
    ``tanh(qd / eps)`` its derivative."""
    dq, dqd = [], []
    for i in range(model.n):
        f = model.friction(i)
        terms = [se.sympify(f.viscous)] if f.viscous != 0 else []
        eps = model.coulomb_smoothing
        if f.coulomb != 0 and eps is not None:
            terms.append(se.sympify(f.coulomb) * se.diff(coulomb_shape(qd[i], eps), qd[i]))
        if f.stribeck != 0:
            v = qd[i]
            fade = se.exp(-(v / se.sympify(f.stribeck_velocity)) ** 2)
            # d/dv [exp(-(v/vs)^2) s(v)]: the sign's derivative is 0, tanh's is not
            terms.append(se.sympify(f.stribeck) * se.diff(fade, v) * coulomb_shape(v, eps))
            if eps is not None:
                terms.append(se.sympify(f.stribeck) * fade * se.diff(coulomb_shape(v, eps), v))
        dqd.append(se.Add(*terms) if terms else se.Integer(0))
        r = model.joints[i].ripple
        if r is not None and (r.sin_amplitude != 0 or r.cos_amplitude != 0):
            sin, cos = _ripple_shapes(model, i, q)
            dq.append(r.order * (se.sympify(r.sin_amplitude) * cos - se.sympify(r.cos_amplitude) * sin))
        else:
            dq.append(se.Integer(0))
    return dq, dqd


def joint_torque_derivatives(model: RobotModel, y, q, qd) -> tuple[list, list, list]:
    """For ``tau = y + fl |y| s + a``: per joint the factor ``1 + fl s sign(y)`` on row i of
    ``dy/dq`` and ``dy/dqd``, and the diagonal terms ``da_i/dq_i`` and ``da_i/dqd_i + fl |y_i|
    ds_i/dqd_i``."""
    dq, dqd = additive_derivatives(model, q, qd)
    factor = [se.Integer(1)] * model.n
    for i in range(model.n):
        load = model.friction(i).load
        if load in (None, 0):
            continue
        factor[i] = _load_factor(model, i, qd, y[i])
        if model.coulomb_smoothing is not None:
            dqd[i] = dqd[i] + se.sympify(load) * se.Abs(y[i]) * se.diff(coulomb_shape(qd[i], model.coulomb_smoothing),
                                                                          qd[i])
    return factor, dq, dqd


def transmitted_derivatives(model: RobotModel, tau, q, qd) -> tuple[list, list]:
    """Per joint, ``(-dy_i/dq_i, -dy_i/dqd_i)`` of :func:`transmitted_torques` (``y`` depends on
    the joint's own q and qd only): what adds to the diagonal of the bias derivatives in
    ``fd``'s derivatives.  Without load-dependent friction ``y = tau - a``: ``da/dq``,
    ``da/dqd``; with it ``u / (1 + c)``, c = fl s sign(u) (sign(u) piecewise constant)."""
    dq, dqd = additive_derivatives(model, q, qd)
    if not has_load_friction(model):
        return dq, dqd
    a = additive_torques(model, q, qd)
    out_q, out_qd = [], []
    for i in range(model.n):
        load = model.friction(i).load
        if load in (None, 0):
            out_q.append(dq[i])
            out_qd.append(dqd[i])
            continue
        u = tau[i] - a[i]
        factor = _load_factor(model, i, qd, u)
        out_q.append(dq[i] / factor)
        d = dqd[i] / factor
        if model.coulomb_smoothing is not None:
            ds = se.diff(coulomb_shape(qd[i], model.coulomb_smoothing), qd[i])
            d = d + u * se.sympify(load) * ds * coulomb_shape(u, None) / factor ** 2
        out_qd.append(d)
    return out_q, out_qd


def effect_parameter_names(model: RobotModel) -> tuple[str, ...]:
    """Names of the effect coefficients the description declares, by effect then joint:
    ``fv1 .. fvn, fc1 .., f01 .., Ia1 .., fs1 .., rs1 .., rc1 .., fl1 ..`` (1-based joints;
    the Stribeck velocities and ripple orders are part of the description, not coefficients)."""
    out = []
    for e in model.effects:
        prefixes = EFFECT_PARAMETERS[e]
        for prefix in (prefixes,) if isinstance(prefixes, str) else prefixes:
            out += [f"{prefix}{i + 1}" for i in range(model.n)]
    return tuple(out)


def effect_parameter_values(model: RobotModel) -> tuple:
    """The description's values of :func:`effect_parameter_names`, exact."""
    zero = se.Integer(0)

    def ripple(i, k):
        r = model.joints[i].ripple
        return zero if r is None else (r.sin_amplitude, r.cos_amplitude)[k]
    values = {"viscous_friction": [lambda i: model.friction(i).viscous],
              "coulomb_friction": [lambda i: model.friction(i).coulomb],
              "torque_offset": [lambda i: model.friction(i).offset],
              "armature": [model.armature],
              "stribeck_friction": [lambda i: model.friction(i).stribeck],
              "position_ripple": [lambda i: ripple(i, 0), lambda i: ripple(i, 1)],
              "load_dependent_friction": [lambda i: model.friction(i).load or zero]}
    return tuple(get(i) for e in model.effects for get in values[e] for i in range(model.n))


def effect_columns(model: RobotModel, q, qd, qdd, y=None) -> list[tuple[int, se.Basic]]:
    """The torque regressor's effect columns, ordered as :func:`effect_parameter_names`: for
    each coefficient, the joint whose torque it acts on and what multiplies it there
    (``qd_i``, the Coulomb shape of ``qd_i``, 1, ``qdd_i``, the Stribeck shape, ``sin(k q_i)``,
    ``cos(k q_i)``, ``|y_i| s_i``).  ``y``: the transmitted torques (rigid bodies and armature
    at the description's own parameters), needed for load-dependent friction, whose column
    makes ``tau = Y p`` exact at those parameters only (the term is bilinear)."""
    eps = model.coulomb_smoothing

    def stribeck(i):
        velocity = model.friction(i).stribeck_velocity
        return stribeck_shape(qd[i], velocity, eps) if velocity is not None else se.Integer(0)

    def ripple(i, k):
        r = model.joints[i].ripple
        return se.Integer(0) if r is None else _ripple_shapes(model, i, q)[k]

    def load(i):
        if model.friction(i).load is None:
            return se.Integer(0)
        if y is None:
            raise ValueError("the load-dependent friction's column needs the transmitted torques y")
        return se.Abs(y[i]) * coulomb_shape(qd[i], eps)
    shapes = {"viscous_friction": [lambda i: qd[i]],
              "coulomb_friction": [lambda i: coulomb_shape(qd[i], eps)],
              "torque_offset": [lambda i: se.Integer(1)],
              "armature": [lambda i: qdd[i]],
              "stribeck_friction": [stribeck],
              "position_ripple": [lambda i: ripple(i, 0), lambda i: ripple(i, 1)],
              "load_dependent_friction": [load]}
    return [(i, shape(i)) for effect in model.effects for shape in shapes[effect] for i in range(model.n)]


def description_text(model: RobotModel) -> str:
    """What the generated headers say about the effects (empty when there are none)."""
    parts = []
    if "viscous_friction" in model.effects:
        shape = (f"tanh(qd / {float(model.coulomb_smoothing):g})" if model.coulomb_smoothing is not None
                 else "sign(qd) (0 at qd = 0)")
        parts.append(f"Joint friction tau_f = fv qd + fc {shape} + f0 (fv in N m s/rad, fc and f0 in N m) "
                     f"is included in tau and fd. ")
    if "armature" in model.effects:
        parts.append("Armature Ia (kg m^2) is included: Ia qdd in tau, Ia on the diagonal of M (and in fd). ")
    if "stribeck_friction" in model.effects:
        parts.append("Stribeck friction fs exp(-(qd / vs)^2) s(qd) (fs in N m, vs in rad/s, s the Coulomb shape) "
                     "is included in tau and fd. ")
    if "position_ripple" in model.effects:
        parts.append("A position ripple rs sin(k q) + rc cos(k q) (N m, k periods per revolution) is included in "
                     "tau and fd. ")
    if "load_dependent_friction" in model.effects:
        parts.append("Load-dependent friction fl |y| s(qd) on the transmitted torque y = tau_rigid + Ia qdd "
                     "(0 <= fl < 1) is included in tau and, inverted in closed form, in fd; M is the inertia of "
                     "y. ")
    if model.payload is not None:
        parts.append("A payload fixed to the flange is merged into the last link's parameters. ")
    return "".join(parts)
