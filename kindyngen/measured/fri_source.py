"""A stand-in for the KUKA LWR's control interface (FRI): the numbers the identification
paper (Gaz, Flacco, De Luca, ICRA 2014) reads from the robot, computed by an independent
implementation of the dynamics.

The reproduction (:mod:`kindyngen.measured.paper_reproduction`) needs a *data source*, not a
model: something that, like ``GetCurrentMassMatrix`` / ``GetCurrentGravityVector`` /
``GetMeasuredJointTorques``, reports numbers at configurations.  The interface is narrow
(:class:`DynamicsSource`), so logged data can be plugged in instead of the simulator:

* ``gravity(q) -> (N, n)``: the gravity vector g(q) the controller reports;
* ``inertia(q) -> (N, n, n)``: the link inertia matrix M(q) it reports;
* ``torque(q, qd, qdd) -> (N, n)``: joint torques tau = M qdd + c + g;
* optionally ``track(t, q_des) -> Motion``: a commanded motion executed, sampled (1 kHz in
  the paper): measured positions and joint torques.  Logged motions are plain
  :class:`Motion` objects (``reproduce(..., motion=Motion(t, q, tau))``).

:class:`FriSource` implements it with Pinocchio (``crba``, ``computeGeneralizedGravity``,
``rnea``) from a parameter set the identification never reads: the robot description's
links, or a perturbed "truth" drawn with a seed (:meth:`FriSource.perturbed`), optionally with
a tip mass on the flange (:meth:`FriSource.with_tip`), Gaussian noise and quantisation on the
reported M and g and a constant offset on g of joint 1 (the paper: "the supporting table may
not be perfectly horizontal").  Pinocchio is a test-only dependency of the package: it is
imported when a FriSource is built, with a clear error when missing.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> src = FriSource(load_robot("robots/lwr4.yaml"))                   # doctest: +SKIP
>>> src.gravity(np.zeros((3, 7))).shape, src.inertia(np.zeros(7)).shape  # doctest: +SKIP
((3, 7), (1, 7, 7))
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from ..model.robot_model import RobotModel


class MissingPinocchioError(ImportError):
    """Pinocchio (a test-only dependency) is not installed."""


def _pinocchio():
    try:
        import pinocchio as pin
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise MissingPinocchioError(
            "FriSource simulates the robot's controller with Pinocchio, which is not installed "
            "(it is a test-only dependency of kindyngen: pip install pin). To reproduce from "
            "recorded data instead, pass your own source with gravity(q), inertia(q), torque(q, qd, qdd) "
            "and a Motion(t, q, tau)") from error
    return pin


@runtime_checkable
class DynamicsSource(Protocol):
    """What the reproduction reads: the controller's reported g(q), M(q), and torques.

    Every method takes samples as rows (``q``: (N, n) or (n,)) and returns arrays with a
    leading sample axis."""

    n: int

    def gravity(self, q) -> np.ndarray: ...

    def inertia(self, q) -> np.ndarray: ...

    def torque(self, q, qd, qdd) -> np.ndarray: ...


@dataclass(frozen=True)
class Motion:
    """A sampled motion: time (N,), measured positions (N, n), measured joint torques (N, n);
    optionally the g (N, n) and M (N, n, n) the controller reported along it (else the
    reproduction asks the source at the measured q)."""

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    gravity: np.ndarray | None = None
    inertia: np.ndarray | None = None


@dataclass(frozen=True)
class LinkParameters:
    """One rigid body: mass (kg), CoM (m, link frame), inertia about the CoM (3x3, link axes)."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray

    def barycentric(self) -> np.ndarray:
        """m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz (inertia about the link origin), the
        order of :data:`kindyngen.model.inertial_parameters.NAMES`."""
        m, c = self.mass, np.asarray(self.com, float)
        I = np.asarray(self.inertia, float) + m * (c @ c * np.eye(3) - np.outer(c, c))
        return np.array([m, m * c[0], m * c[1], m * c[2], I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]])


def description_links(robot: RobotModel) -> tuple[LinkParameters, ...]:
    """The links of a robot description as floats (payload merged into the last link)."""
    links = [LinkParameters(float(l.mass), np.array(l.com, float), l.inertia_matrix()) for l in robot.links]
    if robot.payload is not None:
        p = robot.payload
        links[-1] = combine(links[-1], LinkParameters(float(p.mass), np.array(p.com, float), p.inertia_matrix()))
    return tuple(links)


def combine(a: LinkParameters, b: LinkParameters) -> LinkParameters:
    """Two bodies in one frame as one (masses and first moments add, inertias by parallel axes)."""
    m = a.mass + b.mass
    c = (a.mass * np.asarray(a.com) + b.mass * np.asarray(b.com)) / m

    def about(body):
        d = np.asarray(body.com) - c
        return np.asarray(body.inertia) + body.mass * (d @ d * np.eye(3) - np.outer(d, d))
    return LinkParameters(m, c, about(a) + about(b))


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _rows(q, n):
    q = np.asarray(q, float)
    q = q.reshape(1, -1) if q.ndim == 1 else q
    if q.shape[1] != n:
        raise ValueError(f"expected {n} joint values per sample, got shape {q.shape}")
    return q


@dataclass
class FriSource:
    """The controller's reported dynamics, simulated with Pinocchio from ``links`` (default:
    the description's), which the identification never reads.

    ``g_noise``, ``m_noise``: standard deviation of Gaussian noise added to every reported g
    (N m; scalar or per joint) and M element (kg m^2; scalar, or an (n, n) array, symmetrised);
    ``g_step``, ``m_step``: quantisation steps of the reported values (0: none);
    ``g1_offset``: constant offset added to g of joint 1 (N m); ``q_noise``, ``tau_noise``:
    noise on measured positions (rad) and torques (N m) along a motion; ``seed``: the noise
    generator's seed (the draws continue across calls, reproducibly)."""

    robot: RobotModel
    links: tuple[LinkParameters, ...] | None = None
    g_noise: float | np.ndarray = 0.0
    m_noise: float | np.ndarray = 0.0
    g_step: float = 0.0
    m_step: float = 0.0
    g1_offset: float = 0.0
    q_noise: float = 0.0
    tau_noise: float | np.ndarray = 0.0
    seed: int = 0
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self):
        pin = _pinocchio()
        self.links = tuple(self.links) if self.links is not None else description_links(self.robot)
        if len(self.links) != self.robot.n:
            raise ValueError(f"{len(self.links)} links for a {self.robot.n}-joint robot")
        self.n = self.robot.n
        self.rng = np.random.default_rng(self.seed)
        self._pin = pin
        self._model = self._build(pin)
        self._data = self._model.createData()

    # ------------------------------------------------------------------ construction
    def _build(self, pin):
        robot = self.robot
        model = pin.Model()
        model.gravity = pin.Motion(np.array([float(g) for g in robot.gravity]), np.zeros(3))
        parent, placement = 0, pin.SE3.Identity()
        for i, joint in enumerate(robot.joints):
            a, alpha, d, off = (float(joint.a), float(joint.alpha), float(joint.d), float(joint.offset))
            if robot.convention == "standard":
                joint_placement = placement * pin.SE3(_rz(off), np.zeros(3))
                body_to_link = pin.SE3(_rx(alpha), np.array([a, 0, d]))
            else:
                joint_placement = placement * pin.SE3(_rx(alpha), np.array([a, 0, 0])) * pin.SE3(_rz(off), np.zeros(3))
                body_to_link = pin.SE3(np.eye(3), np.array([0, 0, d]))
            jid = model.addJoint(parent, pin.JointModelRZ(), joint_placement, f"joint{i + 1}")
            link = self.links[i]
            inertia = pin.Inertia(float(link.mass), np.asarray(link.com, float), np.asarray(link.inertia, float))
            model.appendBodyToJoint(jid, body_to_link.act(inertia), pin.SE3.Identity())
            parent, placement = jid, body_to_link
        return model

    @classmethod
    def perturbed(cls, robot: RobotModel, truth_seed: int, mass: float = 0.1, com: float = 0.01,
                  inertia: float = 0.1, **options) -> "FriSource":
        """A "truth" drawn around the description: masses scaled by 1 + U(-mass, mass), CoMs
        moved by N(0, com) m per axis, inertias about the CoM scaled per principal axis by
        1 + U(-inertia, inertia) and rotated slightly (kept positive definite and
        triangle-consistent), drawn with ``truth_seed`` (``options``: noise settings, their
        own ``seed``)."""
        rng = np.random.default_rng(truth_seed)
        out = []
        for link in description_links(robot):
            m = link.mass * (1 + rng.uniform(-mass, mass))
            c = link.com + rng.normal(0, com, 3)
            w, V = np.linalg.eigh(link.inertia)
            w = w * (1 + rng.uniform(-inertia, inertia, 3))
            w = np.minimum(w, 0.99 * (w.sum() - w))        # triangle inequality of principal moments
            small = rng.normal(0, 0.05, 3)
            K = np.array([[0, -small[2], small[1]], [small[2], 0, -small[0]], [-small[1], small[0], 0]])
            R = np.linalg.qr(np.eye(3) + K)[0]
            I = (R @ V) @ np.diag(w) @ (R @ V).T
            out.append(LinkParameters(m, c, 0.5 * (I + I.T)))
        return cls(robot, tuple(out), **options)

    def with_tip(self, mass: float = 0.25, distance: float = 0.0, **changes) -> "FriSource":
        """The same arm with a symmetric tip on the flange: a point mass ``mass`` (kg) on the
        flange axis (z of the last link frame) at ``distance`` (m) from the flange origin.
        Noise settings are kept (``changes`` overrides them, e.g. ``seed``)."""
        tip = LinkParameters(mass, np.array([0.0, 0.0, distance]), np.zeros((3, 3)))
        links = self.links[:-1] + (combine(self.links[-1], tip),)
        options = dict(g_noise=self.g_noise, m_noise=self.m_noise, g_step=self.g_step, m_step=self.m_step,
                       g1_offset=self.g1_offset, q_noise=self.q_noise, tau_noise=self.tau_noise,
                       seed=self.seed + 1)
        options.update(changes)
        return FriSource(self.robot, links, **options)

    def truth_parameters(self) -> np.ndarray:
        """The 10 n barycentric parameters of the simulated arm (for tests and reports only:
        the identification never reads them)."""
        return np.concatenate([link.barycentric() for link in self.links])

    # ------------------------------------------------------------------ reported quantities
    def _quantise(self, x, step):
        return np.round(x / step) * step if step else x

    def true_gravity(self, q) -> np.ndarray:
        q = _rows(q, self.n)
        pin = self._pin
        return np.array([pin.computeGeneralizedGravity(self._model, self._data, qi) for qi in q])

    def true_inertia(self, q) -> np.ndarray:
        q = _rows(q, self.n)
        pin = self._pin
        out = np.empty((len(q), self.n, self.n))
        for k, qi in enumerate(q):
            M = pin.crba(self._model, self._data, qi)
            out[k] = np.triu(M) + np.triu(M, 1).T
        return out

    def gravity(self, q) -> np.ndarray:
        """The reported g at each sample: truth + offset on joint 1 + noise, quantised."""
        g = self.true_gravity(q)
        g[:, 0] += self.g1_offset
        if np.any(np.asarray(self.g_noise) != 0):
            g = g + self.rng.normal(size=g.shape) * np.broadcast_to(self.g_noise, (self.n,))
        return self._quantise(g, self.g_step)

    def inertia(self, q) -> np.ndarray:
        """The reported M at each sample (symmetric): truth + noise, quantised."""
        M = self.true_inertia(q)
        if np.any(np.asarray(self.m_noise) != 0):
            e = self.rng.normal(size=M.shape) * np.broadcast_to(self.m_noise, (self.n, self.n))
            lower = np.tril(e)
            M = M + lower + np.swapaxes(np.tril(e, -1), 1, 2)
        return self._quantise(M, self.m_step)

    def torque(self, q, qd, qdd) -> np.ndarray:
        """Noise-free joint torques tau = M qdd + c + g (Pinocchio's RNEA)."""
        q, qd, qdd = (_rows(x, self.n) for x in (q, qd, qdd))
        pin = self._pin
        return np.array([pin.rnea(self._model, self._data, a, b, c) for a, b, c in zip(q, qd, qdd)])

    def track(self, t, q_des, qd_des=None, qdd_des=None) -> Motion:
        """The commanded motion executed by an ideal position controller: the arm follows
        ``q_des`` exactly; measured q = q_des + N(0, q_noise), measured torques = RNEA at the
        exact motion + N(0, tau_noise).  Velocities and accelerations default to central
        differences of ``q_des`` (pass them when known analytically)."""
        t = np.asarray(t, float)
        q_des = _rows(q_des, self.n)
        qd_des = np.gradient(q_des, t, axis=0, edge_order=2) if qd_des is None else _rows(qd_des, self.n)
        qdd_des = np.gradient(qd_des, t, axis=0, edge_order=2) if qdd_des is None else _rows(qdd_des, self.n)
        tau = self.torque(q_des, qd_des, qdd_des)
        if np.any(np.asarray(self.tau_noise) != 0):
            tau = tau + self.rng.normal(size=tau.shape) * np.broadcast_to(self.tau_noise, (self.n,))
        q = q_des + (self.rng.normal(0, self.q_noise, q_des.shape) if self.q_noise else 0.0)
        return Motion(t=t, q=q, tau=tau)
