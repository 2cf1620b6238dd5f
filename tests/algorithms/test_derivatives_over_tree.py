"""The derivative sweeps of :mod:`kindyngen.algorithms.derivatives_sweeps` run over ``parents[]``: on
a branched fixed-base tree (a revolute chain of two on one side, a prismatic joint and a
revolute child on the other), ``tau_derivatives`` and ``fd_derivatives`` against
Pinocchio's ``computeRNEADerivatives`` and ``computeABADerivatives``."""
import numpy as np
import pinocchio as pin
import pytest

from kindyngen.algorithms.derivatives_sweeps import fd_derivatives, tau_derivatives
from kindyngen.readers.urdf import parse_urdf
from tests.harness import evaluate_function

BRANCHED = """<robot name="branched">
  <link name="body"><inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.3"/></inertial></link>
  <link name="upper"><inertial><mass value="1.2"/><origin xyz="0.02 0 -0.3" rpy="0.1 0 0"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.025" iyz="0.002" izz="0.01"/></inertial></link>
  <link name="lower"><inertial><mass value="0.8"/><origin xyz="0 0.01 -0.25"/>
    <inertia ixx="0.01" ixy="0" ixz="0.001" iyy="0.012" iyz="0" izz="0.002"/></inertial></link>
  <link name="slider"><inertial><mass value="0.5"/><origin xyz="0.05 0 0"/>
    <inertia ixx="0.003" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.005"/></inertial></link>
  <link name="tip"><inertial><mass value="0.3"/><origin xyz="0 0 0.1"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <joint name="a_shoulder" type="revolute"><parent link="body"/><child link="upper"/>
    <origin xyz="0 0.2 0" rpy="0 0.3 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="a_elbow" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 -0.6"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="b_slide" type="prismatic"><parent link="body"/><child link="slider"/>
    <origin xyz="0 -0.2 0"/><axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="b_turn" type="revolute"><parent link="slider"/><child link="tip"/>
    <origin xyz="0.1 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def models():
    tree = parse_urdf(BRANCHED, tree=True)
    assert tree.parents == (-1, 0, -1, 2)          # two branches from the fixed root
    model = pin.buildModelFromXML(BRANCHED)
    assert [model.names[k] for k in range(1, model.njoints)] == [j.name for j in tree.joints]
    return tree, model, model.createData()


def test_tau_derivatives_on_a_tree_equal_pinocchio(models):
    tree, model, data = models
    f = tau_derivatives(tree)
    rng = np.random.default_rng(26)
    for _ in range(5):
        q, v, a = rng.uniform(-1, 1, 4), rng.normal(size=4), rng.normal(size=4)
        dq, dv = evaluate_function(f, q, v, a)
        pin.computeRNEADerivatives(model, data, q, v, a)
        np.testing.assert_allclose(dq, data.dtau_dq, atol=1e-10)
        np.testing.assert_allclose(dv, data.dtau_dv, atol=1e-10)


def test_fd_derivatives_on_a_tree_equal_pinocchio(models):
    tree, model, data = models
    f = fd_derivatives(tree)
    rng = np.random.default_rng(27)
    for _ in range(5):
        q, v, tau = rng.uniform(-1, 1, 4), rng.normal(size=4), rng.normal(size=4)
        dq, dv, minv = evaluate_function(f, q, v, tau)
        pin.computeABADerivatives(model, data, q, v, tau)
        np.testing.assert_allclose(dq, data.ddq_dq, atol=1e-9)
        np.testing.assert_allclose(dv, data.ddq_dv, atol=1e-9)
        np.testing.assert_allclose(minv, np.triu(data.Minv) + np.triu(data.Minv, 1).T, atol=1e-9)
