"""What a robot description predicts its sensors read along logged motion, and how that reading
changes with each coefficient ``discover`` fits: the model written is the model fitted.

Every effect acts in one place (:func:`reading`):

* the *measurement* effects change what is read, not the joint: the logged position is ``q_logged
  = q + encoder_offset + tau / stiffness`` (a motor-side encoder behind an elastic joint), the
  logged torque ``tau_logged = torque_gain tau``; so the true motion is the logged one with the
  offset and the spring's deflection taken off, the spring's torque being the low-passed
  measured torque divided by the gain (:func:`kindyngen.measured.discovery.spring_of`);
* the *joint* effects are torques at the joint along that true motion:
  ``tau = y + fl |y| s + a(q, qd)``, ``y = tau_rigid + Ia qdd``
  (:func:`kindyngen.measured.effect_columns.law_torques`, the numeric twin of the generated
  code's laws);
* the rigid bodies are the description's links (a payload merged into the last one) under its
  gravity: ``tau_rigid = Y(q, qd, qdd) P values + sum_k (g - g_nominal)_k G_k(q) values``, one
  compiled regressor for every inertial value and gravity (:class:`RigidBodies`; torques are
  affine in gravity, ``G_k`` the regressor under unit gravity along base axis k).

A :class:`Point` is one description (its coefficients in the units the schema defines);
:func:`columns` are the derivatives of the predicted reading by each coefficient there (the
linearisation ``discover``'s Gauss-Newton steps use; at the nominal rigid-body model they are the
candidate columns of the selection).  :func:`model_at` writes coefficients into a description and
reads it back, so a point is exactly what ``model.yaml`` holds.

Coefficient names (1-based joints): ``fv fc f0 Ia fs fl rs rc`` + joint (friction, offset,
armature, Stribeck, load-dependent, ripple sine and cosine), ``vs`` and ``rk`` + joint (the
Stribeck velocity and the ripple order: fixed, not fitted, in a linearisation), ``ce`` (compliance
``1 / stiffness``), ``dq`` (encoder offset), ``gt`` (torque gain - 1), ``payload_m ..
payload_Izz`` (barycentric values added at the flange), ``tilt_x tilt_y`` (the base's tilt, rad:
gravity turned about two axes square to it, its magnitude the description's; :func:`tilted_gravity`),
``d_m1 .. d_Izzn`` (link parameters added to the description's, barycentric).

Example (the LWR with a torque sensor reading 0.94 of joint 2's torque and 0.8 N m of Coulomb
friction there, at rest in the zero pose but moving at 0.1 rad/s: 0.94 (0.03 + 0.8) N m):

>>> from kindyngen.readers.yaml_description import load_robot
>>> nominal = load_robot("robots/lwr4.yaml")
>>> model = model_at(nominal, "robots/lwr4.yaml", {"gt2": -0.06, "fc2": 0.8})
>>> model.joints[1].torque_gain, model.joints[1].friction.coulomb
(47/50, 4/5)
>>> q, qd = np.zeros((1, 7)), np.full((1, 7), 0.1)
>>> reading(point_of(model), RigidBodies(nominal), q, qd, q).round(3)[0, :2]
array([0.  , 0.78])
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import yaml

from ..model.inertial_parameters import NAMES as BARYCENTRIC_NAMES
from ..model.robot_model import RobotModel
from ..readers.input_bounds import QUANTITIES
from .effect_columns import JointLaws, applied_laws, joint_laws
from .regressor_rows import full_values, torque_regressor

#: the joint coefficients of each candidate (per joint, one column on its own joint's row each)
JOINT_PREFIXES = {"viscous_friction": ("fv",), "coulomb_friction": ("fc",), "torque_offset": ("f0",),
                  "armature": ("Ia",), "stribeck_friction": ("fs",), "position_ripple": ("rs", "rc"),
                  "load_dependent_friction": ("fl",), "torque_sensor_gain": ("gt",)}
#: candidates whose columns act on every joint's row
DENSE = ("payload", "base_tilt", "rigid_bodies", "motor_side_elasticity", "encoder_offset")
MEASUREMENT = ("motor_side_elasticity", "encoder_offset", "torque_sensor_gain")


#: the base tilt's two angles (rad): a tilt turns gravity, it does not change its magnitude (local
#: gravity is the description's to 0.3 %; a free gravity vector would let its magnitude stand in
#: for a torque gain or a payload, a common scale of the gravity torques)
TILT_NAMES = ("tilt_x", "tilt_y")


def tilt_axes(gravity) -> np.ndarray:
    """(2, 3): the unit axes the tilt angles turn gravity about, square to ``gravity``: the base
    axis least aligned with it made square to it, then that axis crossed with gravity's
    direction. For gravity along -z, the base x and y axes.

    >>> (tilt_axes([0, 0, -9.81]) + 0.0).round(12).tolist()
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    """
    g = np.asarray(gravity, float)
    d = g / np.linalg.norm(g)
    e = np.eye(3)[int(np.argmin(np.abs(d)))]
    u1 = e - (e @ d) * d
    u1 /= np.linalg.norm(u1)
    return np.array([u1, np.cross(u1, d)])


def tilted_gravity(gravity, angles) -> np.ndarray:
    """``gravity`` turned by the rotation vector ``angles[0] u1 + angles[1] u2`` (the
    :func:`tilt_axes`; Rodrigues' formula): its magnitude unchanged.

    >>> tilted_gravity([0, 0, -9.81], [0.1, 0.0]).round(3).tolist()
    [0.0, 0.979, -9.761]
    """
    g = np.asarray(gravity, float)
    w = np.asarray(angles, float) @ tilt_axes(g)
    theta = float(np.linalg.norm(w))
    if theta == 0.0:
        return g.copy()
    k = w / theta
    return g * np.cos(theta) + np.cross(k, g) * np.sin(theta) + k * (k @ g) * (1 - np.cos(theta))


def parameter_names(candidate: str, n: int, base_names=None) -> tuple[str, ...]:
    """The coefficient names of a candidate for ``n`` joints (``base_names``: the rigid bodies'
    base parameters, whose columns ``rigid_bodies`` folds).

    >>> parameter_names("position_ripple", 2), parameter_names("base_tilt", 2)
    (('rs1', 'rs2', 'rc1', 'rc2'), ('tilt_x', 'tilt_y'))
    """
    if candidate in JOINT_PREFIXES:
        return tuple(f"{p}{i + 1}" for p in JOINT_PREFIXES[candidate] for i in range(n))
    if candidate == "payload":
        return tuple(f"payload_{k}" for k in BARYCENTRIC_NAMES)
    if candidate == "base_tilt":
        return TILT_NAMES
    if candidate == "motor_side_elasticity":
        return tuple(f"ce{i + 1}" for i in range(n))
    if candidate == "encoder_offset":
        return tuple(f"dq{i + 1}" for i in range(n))
    if candidate == "rigid_bodies":
        return tuple(f"db_{name}" for name in base_names)
    raise ValueError(f"unknown candidate {candidate!r}")


def link_parameter_names(n: int) -> tuple[str, ...]:
    """``d_m1 .. d_Izzn``: the change of every link's barycentric parameters."""
    return tuple(f"d_{k}{i + 1}" for i in range(n) for k in BARYCENTRIC_NAMES)


class RigidBodies:
    """The rigid-body torques of one geometry (the nominal description's) for any inertial
    values and gravity, from its compiled regressor (:func:`torque_regressor`) and, when gravity
    changes, the regressors under unit gravity along the base axes (built on first use)."""

    def __init__(self, nominal: RobotModel):
        self.nominal = nominal
        self.R = torque_regressor(nominal)
        self.base_map = self.R.base_map
        self.base_names = self.R.names
        self.gravity = np.array([float(v) for v in nominal.gravity])
        self.n = nominal.n

    @cached_property
    def _unit(self):
        return [torque_regressor(replace(self.nominal, gravity=g)) for g in ((1, 0, 0), (0, 1, 0), (0, 0, 1))]

    def regressor(self, q, qd, qdd) -> np.ndarray:
        """Base regressor (N, n, b) under the nominal gravity."""
        return self.R(q, qd, qdd)

    def gravity_columns(self, q, values, which=slice(None)) -> np.ndarray:
        """(N, n, 3): the gravity torques of the full parameters ``values`` (or of their part
        ``which``, with ``values`` that part) under unit gravity along base x, y, z."""
        zero = np.zeros_like(q)
        out = []
        for R in self._unit:
            out.append(R(q, zero, zero) @ (R.base_map[:, which] @ values))
        return np.stack(out, axis=2)

    def torques(self, values, gravity, q, qd, qdd, Y=None) -> np.ndarray:
        """Rigid-body torques (N, n) of the full parameters ``values`` under ``gravity``."""
        Y = self.regressor(q, qd, qdd) if Y is None else Y
        tau = Y @ (self.base_map @ values)
        dg = np.asarray(gravity, float) - self.gravity
        if np.any(dg):
            tau = tau + self.gravity_columns(q, values) @ dg
        return tau


@dataclass(frozen=True, eq=False)
class Point:
    """One description as the numbers a reading needs: ``model``; ``values`` its full
    barycentric parameters (payload merged); ``gravity``; ``laws`` its joint effects; ``gain``,
    ``offset``, ``compliance`` (per joint; 1, 0, 0 where the description says nothing)."""

    model: RobotModel
    values: np.ndarray
    gravity: np.ndarray
    laws: JointLaws
    gain: np.ndarray
    offset: np.ndarray
    compliance: np.ndarray

    @property
    def n(self) -> int:
        return self.model.n


def point_of(model: RobotModel) -> Point:
    joints = model.joints
    return Point(model=model, values=full_values(model), gravity=np.array([float(v) for v in model.gravity]),
                 laws=joint_laws(model), gain=np.array([float(j.torque_gain or 1) for j in joints]),
                 offset=np.array([float(j.encoder_offset or 0) for j in joints]),
                 compliance=np.array([0.0 if j.stiffness is None else 1.0 / float(j.stiffness) for j in joints]))


@dataclass(frozen=True, eq=False)
class State:
    """A point's prediction along a window: the true motion ``q, qd, qdd`` (the logged one with
    the measurement effects undone), the base regressor ``Y`` there, the rigid-body torques
    ``rigid``, the transmitted ``y``, the Coulomb shape ``s``, the load factor ``load = 1 + fl s
    sign(y)``, the joint torques ``tau`` and the predicted ``reading = gain tau``; ``spring``:
    the joint torque and its derivatives (None without elasticity candidates or stiffness)."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    Y: np.ndarray
    rigid: np.ndarray
    y: np.ndarray
    s: np.ndarray
    load: np.ndarray
    tau: np.ndarray
    reading: np.ndarray
    spring: tuple | None


def joint_spring(point: Point, spring) -> tuple | None:
    """The joint torque (and its derivatives) from the low-passed *measured* torque: undone of
    the gain."""
    if spring is None:
        return None
    return tuple(x / point.gain for x in spring)


def joint_torques(point: Point, rigid: RigidBodies, q, qd, qdd, Y=None) -> np.ndarray:
    """The joint torques (N, n) of a point along the true motion (no measurement effects)."""
    r = rigid.torques(point.values, point.gravity, q, qd, qdd, Y)
    return applied_laws(point.laws, q, qd, qdd, r)[0]


def state(point: Point, rigid: RigidBodies, q_logged, qd_logged, qdd_logged, spring=None) -> State:
    """The prediction of ``point`` along logged motion (``spring``: the low-passed measured
    torque and its first two derivatives, :func:`kindyngen.measured.discovery.spring_of`; needed
    when the point has a stiffness or elasticity columns are wanted)."""
    q, qd, qdd = (np.asarray(a, float) for a in (q_logged, qd_logged, qdd_logged))
    joint = joint_spring(point, spring)
    if np.any(point.compliance):
        if joint is None:
            raise ValueError("an elastic joint's reading needs the spring torque")
        c = point.compliance
        q, qd, qdd = q - c * joint[0], qd - c * joint[1], qdd - c * joint[2]
    q = q - point.offset
    laws = point.laws
    Y = rigid.regressor(q, qd, qdd)
    r = rigid.torques(point.values, point.gravity, q, qd, qdd, Y)
    tau, y, s = applied_laws(laws, q, qd, qdd, r)
    load = 1.0 + laws.load * s * np.sign(y)
    return State(q=q, qd=qd, qdd=qdd, Y=Y, rigid=r, y=y, s=s, load=load, tau=tau, reading=point.gain * tau,
                 spring=joint)


def reading(point: Point, rigid: RigidBodies, q_logged, qd_logged, qdd_logged, spring=None) -> np.ndarray:
    """What the sensors of ``point`` read (N, n) along logged motion."""
    return state(point, rigid, q_logged, qd_logged, qdd_logged, spring).reading


def _directional(point, rigid, st: State, dq, dqd, dqdd) -> np.ndarray:
    """Derivative of the joint torques along a change ``(dq, dqd, dqdd)`` of the true motion, by
    central differences (exact in qdd; the step 1e-5 rad of the largest position change)."""
    size = float(np.max(np.abs(dq))) if np.any(dq) else float(np.max(np.abs(np.concatenate([dqd, dqdd]))))
    if size == 0:
        return np.zeros_like(st.q)
    h = 1e-5 / size
    plus = joint_torques(point, rigid, st.q + h * dq, st.qd + h * dqd, st.qdd + h * dqdd)
    minus = joint_torques(point, rigid, st.q - h * dq, st.qd - h * dqd, st.qdd - h * dqdd)
    return (plus - minus) / (2 * h)


def joint_columns(candidate: str, point: Point, st: State, stribeck_velocity=None, ripple_order=None) -> np.ndarray:
    """(N, n, m): the derivatives of the reading by a per-joint candidate's coefficients, column
    ``c * n + i`` (coefficient c of joint i) acting on joint i's row only, so held compactly:
    ``out[:, i, c]``.  ``stribeck_velocity`` / ``ripple_order``: per joint (or one for all)."""
    G = point.gain
    if candidate == "viscous_friction":
        values = [st.qd]
    elif candidate == "coulomb_friction":
        values = [st.s]
    elif candidate == "torque_offset":
        values = [np.ones_like(st.qd)]
    elif candidate == "armature":
        values = [st.load * st.qdd]
    elif candidate == "stribeck_friction":
        values = [np.exp(-(st.qd / np.asarray(stribeck_velocity, float)) ** 2) * st.s]
    elif candidate == "position_ripple":
        k = np.asarray(ripple_order, float)
        values = [np.sin(k * st.q), np.cos(k * st.q)]
    elif candidate == "load_dependent_friction":
        values = [np.abs(st.y) * st.s]
    elif candidate == "torque_sensor_gain":
        return st.tau[:, :, None]           # d(gain tau) / d gain
    else:
        raise ValueError(f"{candidate} is not a per-joint candidate")
    return np.stack([G * v for v in values], axis=2)


def dense_columns(candidate: str, point: Point, rigid: RigidBodies, st: State) -> np.ndarray:
    """(N, n, k): the derivatives of the reading by a candidate whose coefficients act on every
    joint (payload, base tilt, the rigid bodies' base parameters, the measurement offsets and
    compliances)."""
    factor = (point.gain * st.load)[:, :, None]
    if candidate == "payload":
        which = slice(rigid.base_map.shape[1] - 10, None)
        cols = st.Y @ rigid.base_map[:, which]
        dg = point.gravity - rigid.gravity
        if np.any(dg):        # the flange body's gravity torques under the gravity change too
            cols = cols + np.stack([rigid.gravity_columns(st.q, e, which) @ dg for e in np.eye(10)], axis=2)
        return factor * cols
    if candidate == "base_tilt":
        # turning gravity by a small angle about u moves it by u x g (square to g)
        turns = np.stack([np.cross(u, point.gravity) for u in tilt_axes(rigid.gravity)], axis=1)
        return factor * (rigid.gravity_columns(st.q, point.values) @ turns)
    if candidate == "rigid_bodies":
        return factor * st.Y
    n = point.n
    out = np.zeros(st.q.shape + (n,))
    zero = np.zeros_like(st.q)
    for i in range(n):
        dq = zero.copy()
        if candidate == "encoder_offset":
            # q_logged = q + dq_i: the true motion is the logged one minus dq_i e_i
            dq[:, i] = 1.0
            out[:, :, i] = -point.gain * _directional(point, rigid, st, dq, zero, zero)
        elif candidate == "motor_side_elasticity":
            # q_logged = q + ce_i tau_i: the true motion is the logged one minus ce_i (s, sd, sdd) e_i
            if st.spring is None:
                raise ValueError("motor_side_elasticity needs the spring torque")
            s, sd, sdd = st.spring
            dqd, dqdd = zero.copy(), zero.copy()
            dq[:, i], dqd[:, i], dqdd[:, i] = s[:, i], sd[:, i], sdd[:, i]
            out[:, :, i] = -point.gain * _directional(point, rigid, st, dq, dqd, dqdd)
        else:
            raise ValueError(f"{candidate} is not a dense candidate")
    return out


# ---------------------------------------------------------------------------------------------
# coefficients <-> the description

def _payload_link(nominal: RobotModel, delta):
    """The flange body: the nominal payload's barycentric values plus ``delta``, as a link."""
    from ..model.inertial_parameters import barycentric
    from .consistent import links_from_barycentric
    base = np.array([float(v) for v in barycentric(nominal.payload)]) if nominal.payload is not None else np.zeros(10)
    return links_from_barycentric(base + np.asarray(delta, float), 1)[0]


def description_data(nominal: RobotModel, source, values: dict, header: str = "", name: str | None = None) -> str:
    """The YAML text of ``nominal`` (its file ``source``) with the coefficients ``values``
    (names of the module text; absent ones: the description's defaults)."""
    from .consistent import links_from_barycentric
    from .identified_model import model_yaml
    n = nominal.n
    effects = {}
    for key, v in values.items():
        prefix = key[:2]
        if prefix in ("fv", "fc", "f0", "Ia", "fs", "vs", "fl", "rs", "rc", "rk", "dq", "gt") and key[2:].isdigit():
            effects[key] = v
        elif prefix == "ce" and key[2:].isdigit():
            # a compliance whose stiffness is beyond what a description may hold (1e12 N m/rad,
            # kindyngen.readers.input_bounds) deflects no encoder: the joint is written rigid
            if v > 1.0 / QUANTITIES["coefficient"][0]:
                effects[key] = v
    # a ripple or Stribeck term is written with its order or velocity, nothing without its amplitude
    for i in range(1, n + 1):
        if f"rs{i}" not in effects and f"rc{i}" not in effects:
            effects.pop(f"rk{i}", None)
        if f"fs{i}" not in effects:
            effects.pop(f"vs{i}", None)
    links = payload = gravity = None
    link_delta = [values.get(k, 0.0) for k in link_parameter_names(n)]
    if any(link_delta):
        links = links_from_barycentric(full_values(nominal) + np.array(link_delta), n)
    payload_delta = [values.get(f"payload_{k}", 0.0) for k in BARYCENTRIC_NAMES]
    if any(payload_delta):
        if links is not None:          # the written links hold the nominal payload: add it there
            full = full_values(nominal) + np.array(link_delta)
            full[-10:] += np.array(payload_delta)
            links = links_from_barycentric(full, n)
        else:
            payload = _payload_link(nominal, payload_delta)
    if any(values.get(k, 0.0) for k in TILT_NAMES):
        gravity = tilted_gravity([float(v) for v in nominal.gravity], [values.get(k, 0.0) for k in TILT_NAMES])
    return model_yaml(source, links, effects, header=header, name=name, model=nominal, payload=payload,
                      gravity=gravity)


def model_at(nominal: RobotModel, source, values: dict, header: str = "", name: str | None = None) -> RobotModel:
    """The description with ``values`` as written to YAML and read back (the loader's exact
    numbers: what ``model.yaml`` will hold).  Raises the loader's error when the values make no
    valid description."""
    from ..readers.yaml_description import parse_robot
    text = description_data(nominal, source, values, header, name)
    return parse_robot(yaml.safe_load(text), "model.yaml")
