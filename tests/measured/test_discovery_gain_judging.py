"""discover's not-determined rule (kindyngen.measured.discovery.unneeded) beside a torque-sensor
gain. The reading is the gain times the joint's torque, so a joint's coefficients are bilinear
with its gain: at a fitted gain of 0.5 with Coulomb friction 0.5 N m at the joint (the sensor
reads 0.25 of it), a first-order refit without the friction lets the gain's column (the torque,
friction included) take it up, and one without both cancels them. On the real Panda log the
rule dropped joint 7's friction and gain together that way, and the model written was worse
than the nominal one on that joint (0.285 N m against 0.276).

The problem here is a single joint fitted by ordinary least squares with contiguous-fold
cross-validation in plain numpy (no code of discover's fitting): the reading at the point
``g (r + fc sign(v))`` linearised in ``gt`` and ``fc``, the log made by the same law at the point
plus white noise, its rigid-body torque ``r`` small beside the friction (a wrist joint)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from kindyngen.measured import discovery

N, FOLDS = 3000, 5
RNG = np.random.default_rng(7)
T = np.linspace(0.0, 30.0, N)
VELOCITY = np.sin(0.9 * T) + 0.4 * np.sin(2.3 * T + 1.0)
NOISE = 0.002


class LinearisedJoint:
    """Columns ``d reading / d gt = r + fc sign(v)`` and ``d reading / d fc = g sign(v)`` at the
    point, scaled to unit norm like discover's problems; ``fit(idx, fixed)`` solves for the
    free columns with the fixed ones at their scaled values."""

    def __init__(self, gain, coulomb, rigid_scale):
        rigid = rigid_scale * np.cos(0.7 * T)
        tau = rigid + coulomb * np.sign(VELOCITY)
        self.X = np.column_stack([tau, gain * np.sign(VELOCITY)])
        self.residual = RNG.normal(0.0, NOISE, N)             # the log minus the reading at the point
        self.scale = 1.0 / np.linalg.norm(self.X, axis=0)
        self.layout = SimpleNamespace(slices={"gain": np.array([0]), "coulomb": np.array([1])})

    def fit(self, idx, fixed=None):
        cols, theta = (np.asarray(fixed[0], int), np.asarray(fixed[1], float)) if fixed else (np.zeros(0, int), ())
        Xs = self.X * self.scale
        target = self.residual - Xs[:, cols] @ np.asarray(theta, float)
        free = np.array([c for c in idx if c not in cols], int)
        folds = np.array_split(np.arange(N), FOLDS)
        errors = []
        for held in folds:
            train = np.setdiff1d(np.arange(N), held)
            beta = np.linalg.lstsq(Xs[np.ix_(train, free)], target[train], rcond=None)[0] if free.size else ()
            errors.append(target[held] - (Xs[np.ix_(held, free)] @ beta if free.size else 0.0))
        heldout = np.sqrt(np.mean(np.concatenate(errors) ** 2))
        return {"idx": np.asarray(idx, int), "theta": np.zeros(len(idx)), "heldout": np.array([heldout])}


BLOCKS = [SimpleNamespace(candidate="torque_sensor_gain", names=("gt1",), key="gain"),
          SimpleNamespace(candidate="coulomb_friction", names=("fc1",), key="coulomb")]


@pytest.mark.parametrize("rigid_scale", [0.0, 1e-3])
def test_a_gain_far_from_one_does_not_take_its_joints_friction_with_it(rigid_scale):
    """Gain 0.5 and friction 0.5 at the point, the rigid torque nil or well below the noise: the
    gain is not determined (the friction at half its value reads the same), the friction is."""
    problem = LinearisedJoint(gain=0.5, coulomb=0.5, rigid_scale=rigid_scale)
    fit = problem.fit(np.array([0, 1]))
    out = discovery.unneeded(problem, fit, BLOCKS, {"gt1": -0.5, "fc1": 0.5}, np.array([NOISE]))
    assert "fc1" not in out, out
    assert "gt1" in out, out


def test_a_gain_the_rigid_torque_needs_is_kept():
    """With a rigid-body torque 50 times the noise the gain is needed too (the friction cannot
    scale it)."""
    problem = LinearisedJoint(gain=0.5, coulomb=0.5, rigid_scale=0.1)
    fit = problem.fit(np.array([0, 1]))
    assert discovery.unneeded(problem, fit, BLOCKS, {"gt1": -0.5, "fc1": 0.5}, np.array([NOISE])) == {}
