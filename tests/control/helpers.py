"""Shared by the control tests: the three arms (benchmarks/control_robots.py) and a Pinocchio
plant step (RK4 of pin.aba), which shares no code with the controllers."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import control_robots


def arm(name: str):
    if not control_robots.available(name):
        pytest.skip(f"{name}: {control_robots.ROBOTS[name].description} not installed")
    return control_robots.load(name)


def pinocchio_step(name: str, model):
    """step(x, u, dt): one RK4 step of Pinocchio's ABA."""
    import pinocchio as pin
    pm, _ = control_robots.pinocchio_plant_model(name, model)
    pd = pm.createData()
    n = model.n

    def f(x, u):
        return np.concatenate([x[n:], pin.aba(pm, pd, x[:n], x[n:], u)])

    def step(x, u, dt):
        k1 = f(x, u)
        k2 = f(x + dt / 2 * k1, u)
        k3 = f(x + dt / 2 * k2, u)
        k4 = f(x + dt * k3, u)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return step
