"""A robot model written back as YAML description data (the README schema), so that a model
read from a URDF can be saved, edited and reloaded like any description: ``dh: none``, every
joint by ``origin`` (the URDF child frame at q = 0 in the parent link's frame) and ``axis``.
Models whose link frames lie on their joint axes only (URDF, modified DH): a standard DH
table is kept as its table.

Angles that are exact multiples of pi/12 are written as expressions (``pi/2``), everything
else as the shortest decimal of its double; the reloaded model predicts the same values to
the last bit or so (the exact rationals are not all short decimals).

Example:

>>> from kindyngen.readers.yaml_description import load_robot, parse_robot
>>> model = load_robot("robots/panda.yaml")                  # doctest: +SKIP
>>> describe(model)["joints"][1]["origin"]                  # doctest: +SKIP
{'xyz': [0.0, 0.0, 0.0], 'rpy': ['-pi/2', 0, 0]}
>>> parse_robot(describe(model)).n                           # doctest: +SKIP
7
"""
from __future__ import annotations

import sympy

from ..model.robot_model import Friction, Link, RobotModel
from ..model.placement import ANGLE_STEP, Z, Placement, rotation, translation
from .input_bounds import beyond_turn


def _angle(value) -> float | str:
    """An exact multiple of pi/12 as an expression string, anything else as a float."""
    value = sympy.nsimplify(value) if isinstance(value, float) else sympy.sympify(value)
    multiple = value * ANGLE_STEP / sympy.pi
    if multiple.is_Integer:
        return 0 if value == 0 else sympy.sstr(value)
    return float(value)


def _number(value) -> float:
    return float(sympy.sympify(value))


def origin(placement: Placement) -> dict:
    """A placement as ``{xyz, rpy}`` (``T(xyz) Rz(yaw) Ry(pitch) Rx(roll)``).

    >>> from kindyngen.model.placement import rpy_xyz
    >>> origin(rpy_xyz((0.1, 0, 0), (sympy.pi / 2, 0, 0)))
    {'xyz': [0.1, 0.0, 0.0], 'rpy': ['pi/2', 0, 0]}
    >>> origin(rpy_xyz((0, 0, 0), (0, sympy.pi / 2, 0)))["rpy"]    # gimbal lock: roll 0
    [0, 'pi/2', 0]
    """
    R, p = placement.matrix()
    R = R.applyfunc(sympy.nsimplify) if R.has(sympy.Float) else R
    cos_pitch = sympy.simplify(sympy.sqrt(R[0, 0] ** 2 + R[1, 0] ** 2))
    pitch = sympy.atan2(-R[2, 0], cos_pitch)
    if cos_pitch == 0:
        # pitch = +-pi/2: only roll -+ yaw is defined; roll = 0 and all of it in yaw
        roll, yaw = sympy.Integer(0), sympy.atan2(-R[0, 1], R[1, 1])
    else:
        roll, yaw = sympy.atan2(R[2, 1], R[2, 2]), sympy.atan2(R[1, 0], R[0, 0])
    return {"xyz": [_number(v) for v in p], "rpy": [_angle(sympy.simplify(a)) for a in (roll, pitch, yaw)]}


def _mimic(joint, joints) -> dict:
    """A mimic joint's ``mimic`` entry (the joint it follows by name), none for the others."""
    if joint.mimic is None:
        return {}
    return {"mimic": {"joint": joints[joint.mimic.joint].name, "multiplier": _exact(joint.mimic.multiplier),
                      "offset": _exact(joint.mimic.offset)}}


def _exact(value) -> float | str:
    """A rational as the shortest decimal when that is it exactly, else as a fraction
    (``'1/3'``, which the reader takes exactly).

    >>> _exact(sympy.Rational(1, 4)), _exact(sympy.Rational(-2, 3))
    (0.25, '-2/3')
    """
    value = sympy.Rational(value)
    return float(value) if sympy.Rational(repr(float(value))) == value else str(value)


def _joint(joint, effects: dict) -> dict:
    R_after, p_after = joint.after.matrix()
    if any(v != 0 for v in p_after):
        # a URDF joint turns about its child frame's origin; a standard DH link frame is
        # not on its own joint's axis
        raise ValueError(f"joint {joint.name or '?'}: the link frame is off the joint axis (a standard DH "
                         f"row); keep its DH table instead")
    axis = R_after.T * sympy.Matrix([0, 0, 1])        # the joint axis in the link frame
    row = {"type": joint.kind} if joint.prismatic else {}
    if joint.name:
        row["name"] = joint.name
    row["origin"] = origin(joint.before * (_offset(joint) * joint.after))
    row["axis"] = [_number(v) for v in axis]
    row.update(lower=_limit(joint, joint.lower), upper=_limit(joint, joint.upper), **effects)
    return row


def _limit(joint, value: float) -> float | str:
    """A joint limit; a revolute one beyond a full turn (a multi-turn URDF joint) as an
    expression, the form the YAML reader takes such a range in (a plain number beyond a full
    turn is read as degrees written by mistake and refused).

    >>> from kindyngen.model.robot_model import Joint
    >>> joint = Joint(Placement(), Placement(), 0, -10.0, 2.5)
    >>> _limit(joint, joint.lower), _limit(joint, joint.upper)
    ('-10.0', 2.5)
    """
    if not joint.prismatic and beyond_turn(value):
        return repr(float(value))
    return float(value)


def _offset(joint) -> Placement:
    """The joint offset as a constant motion (it is part of the origin once written)."""
    if joint.prismatic:
        return translation(0, 0, joint.offset)
    return rotation(Z, joint.offset)


def _effects(friction: Friction | None, armature, joint=None) -> dict:
    out = {}
    if friction is not None:
        out["friction"] = {"viscous": _number(friction.viscous), "coulomb": _number(friction.coulomb),
                           "offset": _number(friction.offset)}
        if friction.stribeck_velocity is not None:
            out["friction"].update(stribeck=_number(friction.stribeck),
                                   stribeck_velocity=_number(friction.stribeck_velocity))
        if friction.load is not None:
            out["friction"]["load"] = _number(friction.load)
    if armature is not None:
        out["armature"] = _number(armature)
    if joint is not None and joint.ripple is not None:
        r = joint.ripple
        out["ripple"] = {"sin": _number(r.sin_amplitude), "cos": _number(r.cos_amplitude), "order": int(r.order)}
    for key in ("stiffness", "encoder_offset", "torque_gain"):
        if joint is not None and getattr(joint, key) is not None:
            out[key] = _number(getattr(joint, key))
    return out


def _link(link: Link) -> dict:
    return {"mass": _number(link.mass), "com": [_number(v) for v in link.com],
            "inertia": [_number(v) for v in link.inertia]}


def describe(model: RobotModel) -> dict:
    """The YAML data (``dh: none``) of ``model``: joints by origin and axis, links, payload,
    tool, effects, bundles. Frames and joint order are the model's. A tree closed by loops is refused
    (ValueError): its loops would be lost."""
    if model.has_loops:
        raise ValueError("closed loops (loop joints) are not written by describe: keep the description as it is")
    data = {"name": model.name, "dh": "none", "gravity": [_number(v) for v in model.gravity],
            "joints": [_joint(j, {**_effects(j.friction, j.armature, j), **_mimic(j, model.joints)})
                       for j in model.joints],
            "links": [_link(link) for link in model.links]}
    if model.payload is not None:
        data["payload"] = _link(model.payload)
    if model.coulomb_smoothing is not None:
        data["coulomb_smoothing"] = _number(model.coulomb_smoothing)
    if not model.tool.is_identity:
        data["tool"] = origin(model.tool)
    if model.bundles:
        data["bundles"] = {name: list(members) for name, members in model.bundles}
    return data
