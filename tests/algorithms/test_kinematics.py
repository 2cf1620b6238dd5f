"""Forward kinematics (homogeneous and dual quaternion) and the Jacobian, in every generated
language, against Pinocchio, a plain-numpy DH product and finite differences."""
import numpy as np
import pinocchio as pin
import pytest

from tests.harness import LANGS, evaluate, robot
from tests.reference import dh_numbers, fk_numpy, pinocchio_model, random_configurations

ROBOTS = ("lwr4", "lwr4_hartl", "panda")
N = 1000


@pytest.fixture(scope="module", params=ROBOTS)
def case(request):
    name = request.param
    model, data, frame = pinocchio_model(robot(name))
    return name, model, data, frame, random_configurations(robot(name), N, seed=1)


def pin_pose_and_jacobian(model, data, frame, q):
    pin.computeJointJacobians(model, data, q)
    pin.framesForwardKinematics(model, data, q)
    J = pin.getFrameJacobian(model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    return data.oMf[frame].homogeneous.copy(), J.copy()


def dq_to_matrix(x):
    """Unit dual quaternion (rw, rx, ry, rz, dw, dx, dy, dz) -> 4x4, independently of the generator."""
    w, a, b, c = x[:4]
    R = np.array([[1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)],
                  [2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)],
                  [2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)]])
    r_conj = np.array([w, -a, -b, -c])
    d = x[4:]
    # t = 2 d (x) r*
    t = 2 * np.array([d[0] * r_conj[0] - d[1] * r_conj[1] - d[2] * r_conj[2] - d[3] * r_conj[3],
                      d[0] * r_conj[1] + d[1] * r_conj[0] + d[2] * r_conj[3] - d[3] * r_conj[2],
                      d[0] * r_conj[2] - d[1] * r_conj[3] + d[2] * r_conj[0] + d[3] * r_conj[1],
                      d[0] * r_conj[3] + d[1] * r_conj[2] - d[2] * r_conj[1] + d[3] * r_conj[0]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t[1:]
    return T


@pytest.mark.parametrize("lang", LANGS)
def test_fk_hom_matches_pinocchio_and_numpy(case, lang):
    name, model, data, frame, Q = case
    T = evaluate(name, lang, "fk_hom", q=Q)["T"]
    assert T.shape == (N, 4, 4)
    for k, q in enumerate(Q):
        expected, _ = pin_pose_and_jacobian(model, data, frame, q)
        np.testing.assert_allclose(T[k], expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(T[k], fk_numpy(robot(name), q), rtol=0, atol=1e-12)


@pytest.mark.parametrize("lang", LANGS)
def test_jacobian_matches_pinocchio(case, lang):
    name, model, data, frame, Q = case
    J = evaluate(name, lang, "jacobian", q=Q)["J"]
    for k, q in enumerate(Q):
        _, expected = pin_pose_and_jacobian(model, data, frame, q)
        np.testing.assert_allclose(J[k], expected, rtol=0, atol=1e-12)


def test_jacobian_matches_finite_differences(case):
    name, _, _, _, Q = case
    h = 1e-6
    for q in Q[:50]:
        J = evaluate(name, "c", "jacobian", q=q)["J"]
        T0 = fk_numpy(robot(name), q)
        for i in range(len(q)):
            dq = np.zeros(len(q))
            dq[i] = h
            Tp, Tm = fk_numpy(robot(name), q + dq), fk_numpy(robot(name), q - dq)
            dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T0[:3, :3].T   # skew(omega)
            omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
            np.testing.assert_allclose(J[:3, i], dp, atol=1e-8)
            np.testing.assert_allclose(J[3:, i], omega, atol=1e-8)


@pytest.mark.parametrize("lang", LANGS)
def test_fk_dq_is_unit_and_equals_fk_hom(case, lang):
    name, _, _, _, Q = case
    X = evaluate(name, lang, "fk_dq", q=Q)["x"]
    T = evaluate(name, lang, "fk_hom", q=Q)["T"]
    real, dual = X[:, :4], X[:, 4:]
    np.testing.assert_allclose(np.sum(real * real, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(real * dual, axis=1), 0.0, atol=1e-12)
    for k in range(N):
        np.testing.assert_allclose(dq_to_matrix(X[k]), T[k], atol=1e-12)


def _qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def dq_product_numpy(rob, q):
    """The documented sign convention, computed plainly: x = u_1 ... u_n with
    u_i = r_i + e/2 t_i r_i, r_i the half-angle quaternion of the joint's DH rotation
    (scalar part cos(theta/2) cos(alpha/2)) and t_i its DH translation."""
    a, alpha, d, off = dh_numbers(rob)
    real, dual = np.array([1.0, 0, 0, 0]), np.zeros(4)
    for i, qi in enumerate(q):
        th = qi + off[i]
        rz = np.array([np.cos(th / 2), 0, 0, np.sin(th / 2)])
        rx = np.array([np.cos(alpha[i] / 2), np.sin(alpha[i] / 2), 0, 0])
        if rob.convention == "standard":
            r = _qmul(rz, rx)
            t = np.array([0, a[i] * np.cos(th), a[i] * np.sin(th), d[i]])
        else:
            r = _qmul(rx, rz)
            t = np.array([0, a[i], -np.sin(alpha[i]) * d[i], np.cos(alpha[i]) * d[i]])
        u_dual = 0.5 * _qmul(t, r)
        real, dual = _qmul(real, r), _qmul(real, u_dual) + _qmul(dual, r)
    return np.concatenate([real, dual])


@pytest.mark.parametrize("lang", LANGS)
def test_fk_dq_sign_is_the_product_of_joint_dual_quaternions(case, lang):
    name, _, _, _, Q = case
    X = evaluate(name, lang, "fk_dq", q=Q[:200])["x"]
    for k in range(200):
        np.testing.assert_allclose(X[k], dq_product_numpy(robot(name), Q[k]), atol=1e-12)


def test_python_batch_equals_single_calls(case):
    name, _, _, _, Q = case
    batch = evaluate(name, "python", "fk_hom", q=Q[:20])["T"]
    for k in range(20):
        np.testing.assert_array_equal(evaluate(name, "python", "fk_hom", q=Q[k])["T"], batch[k])
