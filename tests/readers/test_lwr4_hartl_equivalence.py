"""robots/lwr4.yaml (identification paper's DH table) and robots/lwr4_hartl.yaml (kinematics
paper's table) describe the same arm: same flange pose, same gravity torques and mass matrix
under the change of joint coordinates below."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from kindyngen.readers.yaml_description import load_robot
from tests.reference import fk_numpy, pinocchio_model, random_configurations

ROBOTS = Path(__file__).resolve().parents[2] / "robots"
N = 1000


def lwr4_to_hartl(q):
    """Joint coordinates of robots/lwr4.yaml -> those of robots/lwr4_hartl.yaml.

    q_hartl = q_lwr4 + (0, pi, 0, pi, 0, pi, pi): a pure offset, so its Jacobian is the
    identity. Works on one configuration (shape (7,)) or a batch (shape (k, 7)).
    """
    return np.asarray(q, float) + np.array([0, np.pi, 0, np.pi, 0, np.pi, np.pi])


@pytest.fixture(scope="module")
def lwr4():
    return load_robot(ROBOTS / "lwr4.yaml")


@pytest.fixture(scope="module")
def hartl():
    return load_robot(ROBOTS / "lwr4_hartl.yaml")


@pytest.fixture(scope="module")
def configurations(lwr4):
    """N random configurations within the lwr4 limits, plus both corners of the limit box."""
    return np.vstack([random_configurations(lwr4, N, seed=7), lwr4.lower, lwr4.upper])


def map_jacobian(q):
    """d q_hartl / d q_lwr4 at q, by differences of the map itself (exact for an affine map
    up to rounding), rounded to the signed identity it must be."""
    q = np.asarray(q, float)
    J = np.column_stack([lwr4_to_hartl(q + e) - lwr4_to_hartl(q) for e in np.eye(len(q))])
    S = np.round(J)
    assert np.abs(J - S).max() < 1e-12
    assert np.array_equal(np.abs(S), np.eye(len(q))), "the map must be a signed offset map"
    return S


def test_tables_differ(lwr4, hartl):
    """Guard against comparing a file with itself."""
    assert [j.alpha for j in lwr4.joints] != [j.alpha for j in hartl.joints]
    assert hartl.name == "lwr4_hartl" and hartl.n == lwr4.n == 7


def test_flange_poses_identical(lwr4, hartl, configurations):
    worst = 0.0
    for q in configurations:
        worst = max(worst, np.abs(fk_numpy(lwr4, q) - fk_numpy(hartl, lwr4_to_hartl(q))).max())
    assert worst < 1e-12


def test_mapped_configurations_within_limits(lwr4, hartl, configurations):
    mapped = lwr4_to_hartl(configurations)
    assert np.all(mapped >= hartl.lower) and np.all(mapped <= hartl.upper)
    # and the hartl limits are exactly the image of the lwr4 limits, not a larger box
    np.testing.assert_allclose(hartl.lower, lwr4_to_hartl(lwr4.lower), rtol=0, atol=1e-12)
    np.testing.assert_allclose(hartl.upper, lwr4_to_hartl(lwr4.upper), rtol=0, atol=1e-12)


def _gravity_and_mass(robot, qs):
    model, data, _ = pinocchio_model(robot)
    g, M = [], []
    for q in qs:
        g.append(pin.computeGeneralizedGravity(model, data, q).copy())
        m = pin.crba(model, data, q).copy()
        M.append(np.triu(m) + np.triu(m, 1).T)
    return np.array(g), np.array(M)


def test_gravity_and_mass_matrix_identical(lwr4, hartl, configurations):
    """tau_lwr4 = J^T tau_hartl and M_lwr4 = J^T M_hartl J for q_hartl = phi(q_lwr4), J = dphi/dq.
    This holds only if the inertial parameters of lwr4_hartl.yaml are lwr4's links expressed
    in the other table's link frames."""
    g_l, M_l = _gravity_and_mass(lwr4, configurations)
    g_h, M_h = _gravity_and_mass(hartl, lwr4_to_hartl(configurations))
    J = np.array([map_jacobian(q) for q in configurations])
    g_h_pulled = np.einsum("kji,kj->ki", J, g_h)
    M_h_pulled = np.einsum("kai,kab,kbj->kij", J, M_h, J)
    assert np.abs(g_l).max() > 1.0                      # gravity torques are not trivially zero
    assert np.abs(g_l - g_h_pulled).max() < 1e-10
    assert np.abs(M_l - M_h_pulled).max() < 1e-10


def test_untransformed_inertia_would_be_detected(lwr4, hartl, configurations):
    """Negative control: copying lwr4's link parameters into the hartl table verbatim (without
    the frame change) gives different dynamics, so the test above can fail."""
    naive = dataclasses.replace(hartl, links=lwr4.links)
    qs = configurations[:50]
    g_l, M_l = _gravity_and_mass(lwr4, qs)
    g_n, M_n = _gravity_and_mass(naive, lwr4_to_hartl(qs))
    assert max(np.abs(g_l - g_n).max(), np.abs(M_l - M_n).max()) > 1e-3
