"""Joint effects beyond rigid bodies, as the robot description declares them, in symbolic form
for the derivations: friction, a torque offset and the armature (a payload is a rigid body and
is merged into the last link's parameters instead, :mod:`kindyngen.model.inertial_parameters`).

Per joint i (the formulas the measured-data side uses too, :mod:`kindyngen.measured.effect_columns`):

* viscous friction ``fv_i qd_i``; Coulomb friction ``fc_i sign(qd_i)`` (``sign(0) = 0``,
  generated as two selects), or ``fc_i tanh(qd_i / eps)`` when the description sets
  ``coulomb_smoothing: eps`` (smooth, for optimisers); a torque offset ``f0_i`` (a constant
  bias of the sensor or drive);
* armature ``Ia_i`` (reflected rotor inertia): ``Ia_i qdd_i`` in the torque, ``Ia_i`` on the
  diagonal of M.

They enter ``tau``, ``fd``, ``M`` and ``M_lagrange``; ``c``, ``g``, ``S`` and the Christoffel
route are unchanged (the armature is constant, friction is not a Coriolis term).

Example:

>>> import symengine as se
>>> coulomb_shape(se.Symbol("v"), None)
Piecewise((1, 0 < v), (-1, v < 0), (0, True))
"""
from __future__ import annotations

import symengine as se

from ..model.robot_model import RobotModel

EFFECT_PARAMETERS = {"viscous_friction": "fv", "coulomb_friction": "fc", "torque_offset": "f0", "armature": "Ia"}


def coulomb_shape(v: se.Basic, eps) -> se.Basic:
    """``sign(v)`` as a branch-free select, or ``tanh(v / eps)``."""
    if eps is not None:
        return se.tanh(v / se.sympify(eps))
    return se.Piecewise((se.Integer(1), se.StrictLessThan(0, v)), (se.Integer(-1), se.StrictLessThan(v, 0)),
                        (se.Integer(0), se.true))


def effect_torques(model: RobotModel, qd, qdd) -> list[se.Basic]:
    """Per joint, the friction, offset and armature torques of the description (exact
    coefficients baked in; zero where none is declared); ``qd``/``qdd`` may be None (zero)."""
    out = []
    for i in range(model.n):
        f = model.friction(i)
        terms = []
        if qd is not None and f.viscous != 0:
            terms.append(se.sympify(f.viscous) * qd[i])
        if qd is not None and f.coulomb != 0:
            terms.append(se.sympify(f.coulomb) * coulomb_shape(qd[i], model.coulomb_smoothing))
        if f.offset != 0:
            terms.append(se.sympify(f.offset))
        if qdd is not None and model.armature(i) != 0:
            terms.append(se.sympify(model.armature(i)) * qdd[i])
        out.append(se.Add(*terms) if terms else se.Integer(0))
    return out


def with_armature(model: RobotModel, M):
    """M (nested lists) with each joint's armature added on the diagonal."""
    out = [list(row) for row in M]
    for i in range(model.n):
        if model.armature(i) != 0:
            out[i][i] = out[i][i] + se.sympify(model.armature(i))
    return out


def effect_parameter_names(model: RobotModel) -> tuple[str, ...]:
    """Names of the effect coefficients the description declares, by effect then joint:
    ``fv1 .. fvn, fc1 .., f01 .., Ia1 ..`` (1-based joints)."""
    return tuple(f"{EFFECT_PARAMETERS[e]}{i + 1}" for e in model.effects for i in range(model.n))


def effect_parameter_values(model: RobotModel) -> tuple:
    """The description's values of :func:`effect_parameter_names`, exact."""
    values = {"viscous_friction": lambda i: model.friction(i).viscous,
              "coulomb_friction": lambda i: model.friction(i).coulomb,
              "torque_offset": lambda i: model.friction(i).offset,
              "armature": model.armature}
    return tuple(values[e](i) for e in model.effects for i in range(model.n))


def effect_columns(model: RobotModel, qd, qdd) -> list[tuple[int, se.Basic]]:
    """The torque regressor's effect columns, ordered as :func:`effect_parameter_names`: for
    each coefficient, the joint whose torque it acts on and what multiplies it there
    (``qd_i``, the Coulomb shape of ``qd_i``, 1, ``qdd_i``)."""
    shapes = {"viscous_friction": lambda i: qd[i],
              "coulomb_friction": lambda i: coulomb_shape(qd[i], model.coulomb_smoothing),
              "torque_offset": lambda i: se.Integer(1),
              "armature": lambda i: qdd[i]}
    return [(i, shapes[effect](i)) for effect in model.effects for i in range(model.n)]


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
    if model.payload is not None:
        parts.append("A payload fixed to the flange is merged into the last link's parameters. ")
    return "".join(parts)
