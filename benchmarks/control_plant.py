"""The plant of the control benchmark and tests: Pinocchio's ABA on the arm's own Pinocchio
model (benchmarks/control_robots.py; no code shared with the controllers), RK4 at the sample
rate, with the disturbances of the suite:

- ``noise``: Gaussian measurement noise (rad, rad/s) on what the controller sees;
- ``payload``: a point mass at the flange from time ``start`` on (the model does not know it);
- ``mass_error``: every link's mass and inertia scaled (the model keeps the nominal ones);
- ``push``: a force (N, base frame) at the flange for [start, start + duration);
- ``torque``: a torque (N m) on one joint for [start, start + duration).

>>> Disturbance("push", start=0.4, duration=0.3, force=(0.0, 60.0, 0.0)).active(0.5)
True
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.control_robots import pinocchio_plant_model


@dataclass(frozen=True)
class Disturbance:
    kind: str = "none"                 # none | noise | payload | mass_error | push | torque
    start: float = 0.0
    duration: float = float("inf")
    noise: tuple = (0.0, 0.0)          # rad, rad/s (std)
    mass_kg: float = 0.0
    mass_scale: float = 1.0
    force: tuple = (0.0, 0.0, 0.0)
    joint: int = 0                     # 0-based
    torque: float = 0.0
    seed: int = 0

    def active(self, t: float) -> bool:
        return self.start <= t < self.start + self.duration

    @property
    def end(self) -> float:
        return self.start + self.duration if np.isfinite(self.duration) else self.start


class PinocchioPlant:
    def __init__(self, name: str, model, disturbance: Disturbance = Disturbance()):
        import pinocchio as pin
        self.pin = pin
        self.n = model.n
        self.dist = disturbance
        pm, self.frame = pinocchio_plant_model(name, model)
        if disturbance.kind == "mass_error":
            for i in range(1, pm.njoints):
                I = pm.inertias[i]
                pm.inertias[i] = pin.Inertia(I.mass * disturbance.mass_scale, I.lever,
                                             I.inertia * disturbance.mass_scale)
        self.model, self.data = pm, pm.createData()
        self.loaded = None
        if disturbance.kind == "payload":
            lm = pin.Model(pm)
            fr = lm.frames[self.frame]
            lm.appendBodyToJoint(fr.parentJoint, fr.placement.act(pin.Inertia(disturbance.mass_kg, np.zeros(3),
                                                                             np.zeros((3, 3)))), pin.SE3.Identity())
            self.loaded = (lm, lm.createData())
        self.rng = np.random.default_rng(disturbance.seed)

    def _model(self, t):
        if self.loaded is not None and t >= self.dist.start:
            return self.loaded
        return self.model, self.data

    def external_torque(self, q, t) -> np.ndarray:
        d = self.dist
        tau = np.zeros(self.n)
        if d.kind == "torque" and d.active(t):
            tau[d.joint] = d.torque
        elif d.kind == "push" and d.active(t):
            pin = self.pin
            m, data = self.model, self.data
            J = pin.computeFrameJacobian(m, data, q, self.frame, pin.LOCAL_WORLD_ALIGNED)
            tau = J[:3].T @ np.asarray(d.force, float)
        return tau

    def accel(self, x, u, t):
        n = self.n
        m, data = self._model(t)
        return self.pin.aba(m, data, x[:n], x[n:], u + self.external_torque(x[:n], t))

    def step(self, x, u, dt, t):
        n = self.n

        def f(z, tt):
            return np.concatenate([z[n:], self.accel(z, u, tt)])
        k1 = f(x, t)
        k2 = f(x + dt / 2 * k1, t + dt / 2)
        k3 = f(x + dt / 2 * k2, t + dt / 2)
        k4 = f(x + dt * k3, t + dt)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def measure(self, x, t):
        if self.dist.kind != "noise":
            return x
        sq, sv = self.dist.noise
        n = self.n
        return x + np.concatenate([sq * self.rng.standard_normal(n), sv * self.rng.standard_normal(n)])

    def flange(self, q) -> np.ndarray:
        self.pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.frame].translation.copy()

    def mass_matrix_inverse(self, q) -> np.ndarray:
        m, data = self.model, self.data
        return self.pin.computeMinverse(m, data, q).copy()
