"""Closed-form IK of the LWR (ik_hom, ik_dq): all eight branches against an independent
numpy FK, special targets (wrist, elbow, shoulder singularities, outside the workspace),
robustness (no NaN/Inf for any finite input), applicability, op counts, and the numpy
helpers (closest branch, theta3 intervals).

Evaluated through :func:`harness.evaluate_symbolic` (the derived expressions); the
generated-code runs of the same checks are for the all-language tests.
"""
import numpy as np
import pytest
import symengine as se

from tests.harness import evaluate_symbolic, robot
from tests.reference import dh_numbers, fk_numpy, random_configurations

from kindyngen.codegen.catalog import derive_all
from kindyngen.ik.lwr_common import (ADMISSIBLE, ELBOW_SINGULAR, LIMITS, SHOULDER_SINGULAR, UNREACHABLE,
                                     WRIST_SINGULAR, lwr_geometry)
from tests.ik.lwr_numeric import closest_solution, theta3_intervals
from kindyngen.ik.lwr_dualquat import ik_dq
from kindyngen.ik.lwr_homogeneous import ik_hom
from kindyngen.codegen.optimize import optimize
from kindyngen.codegen.printer import C, CASADI, NUMPY
from kindyngen.readers.yaml_description import parse_robot

N = 10_000          # random targets per test (the brief's 10,000)
TOL = 1e-10         # FK(q) = target, position (m) and rotation entries
FORMS = ("ik_hom", "ik_dq")
D3, D5 = 0.40, 0.39


# --- independent numpy helpers ------------------------------------------------------------------
def fk_batch(model, Q):
    """Flange poses for configurations Q (..., n): the DH product, vectorised."""
    a, alpha, d, off = dh_numbers(model)
    Q = np.asarray(Q, float)
    T = np.broadcast_to(np.eye(4), Q.shape[:-1] + (4, 4)).copy()
    for i in range(Q.shape[-1]):
        th = Q[..., i] + off[i]
        c, s = np.cos(th), np.sin(th)
        ca, sa = np.cos(alpha[i]), np.sin(alpha[i])
        A = np.zeros(Q.shape[:-1] + (4, 4))
        A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = c, -s * ca, s * sa, a[i] * c
        A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = s, c * ca, -c * sa, a[i] * s
        A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = sa, ca, d[i]
        A[..., 3, 3] = 1.0
        T = T @ A
    return T


def matrix_to_dq(T, rng=None):
    """Unit dual quaternion (fk_dq layout) of poses T (..., 4, 4), Shepperd's method, with a
    random overall sign when ``rng`` is given (x and -x are the same pose)."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    tr = np.trace(R, axis1=-2, axis2=-1)
    cand = np.stack([1 + tr, 1 + R[..., 0, 0] - R[..., 1, 1] - R[..., 2, 2],
                     1 - R[..., 0, 0] + R[..., 1, 1] - R[..., 2, 2],
                     1 - R[..., 0, 0] - R[..., 1, 1] + R[..., 2, 2]], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.zeros(T.shape[:-2] + (4,))
    for i in range(4):
        m = k == i
        Rm, s = R[m], np.sqrt(cand[m, i])
        if i == 0:
            q[m] = np.stack([s, (Rm[:, 2, 1] - Rm[:, 1, 2]) / s, (Rm[:, 0, 2] - Rm[:, 2, 0]) / s,
                             (Rm[:, 1, 0] - Rm[:, 0, 1]) / s], -1) / 2
        elif i == 1:
            q[m] = np.stack([(Rm[:, 2, 1] - Rm[:, 1, 2]) / s, s, (Rm[:, 0, 1] + Rm[:, 1, 0]) / s,
                             (Rm[:, 0, 2] + Rm[:, 2, 0]) / s], -1) / 2
        elif i == 2:
            q[m] = np.stack([(Rm[:, 0, 2] - Rm[:, 2, 0]) / s, (Rm[:, 0, 1] + Rm[:, 1, 0]) / s, s,
                             (Rm[:, 1, 2] + Rm[:, 2, 1]) / s], -1) / 2
        else:
            q[m] = np.stack([(Rm[:, 1, 0] - Rm[:, 0, 1]) / s, (Rm[:, 0, 2] + Rm[:, 2, 0]) / s,
                             (Rm[:, 1, 2] + Rm[:, 2, 1]) / s, s], -1) / 2
    if rng is not None:
        q *= rng.choice([-1.0, 1.0], size=q.shape[:-1])[..., None]
    w, v = q[..., :1], q[..., 1:]
    # d = 1/2 (0, t) (x) r
    dw = -0.5 * np.sum(t * v, axis=-1, keepdims=True)
    dv = 0.5 * (t * w + np.cross(t, v))
    return np.concatenate([q, dw, dv], axis=-1)


def solve(form, T, theta3, rng=None):
    """(q (N, 8, 7), status (N, 8) int) of one IK form for targets T (N, 4, 4)."""
    theta3 = np.broadcast_to(np.asarray(theta3, float), (len(T),))
    if form == "ik_hom":
        out = evaluate_symbolic("lwr4", "ik_hom", T=T, theta3=theta3)
    else:
        out = evaluate_symbolic("lwr4", "ik_dq", x=matrix_to_dq(T, rng), theta3=theta3)
    return out["q"], out["status"].astype(int)


def pose_errors(model, q, T):
    """Position and rotation errors of FK(q) (N, 8, 7) against T (N, 4, 4)."""
    F = fk_batch(model, q)
    dp = np.linalg.norm(F[..., :3, 3] - T[:, None, :3, 3], axis=-1)
    dR = np.abs(F[..., :3, :3] - T[:, None, :3, :3]).max(axis=(-1, -2))
    return dp, dR


def angle_diff(a, b):
    return np.abs((np.asarray(a) - b + np.pi) % (2 * np.pi) - np.pi)


def outside_limits(model, q):
    return ((q < model.lower) | (q > model.upper)).any(axis=-1)


def check_common(model, q, status, T, theta3):
    """Invariants of every call: finite, codes in range, theta3 passed through, branch
    signs, status 1 exactly for reachable rows outside the limits, every reachable row
    reproduces the target."""
    assert np.isfinite(q).all()
    assert np.isin(status, [0, 1, 2, 3, 4, 5]).all()
    assert np.array_equal(q[:, :, 2], np.broadcast_to(np.asarray(theta3, float)[..., None], q.shape[:2]))
    reach = status != UNREACHABLE
    np.testing.assert_array_equal((status == LIMITS)[reach], outside_limits(model, q)[reach])
    dp, dR = pose_errors(model, q, T)
    assert dp[reach].max(initial=0) < TOL and dR[reach].max(initial=0) < TOL
    rows = np.arange(8)
    elbow, wrist = (rows >> 1) & 1, rows & 1
    theta = (q + dh_numbers(model)[3] + np.pi) % (2 * np.pi) - np.pi     # DH angles
    half_turn = np.abs(theta) > np.pi - 1e-12                              # +-pi: either sign
    assert (theta[:, elbow == 0, 3] >= 0).all() and (theta[:, elbow == 1, 3] <= 0).all()
    assert ((theta[:, wrist == 0, 5] >= 0) | half_turn[:, wrist == 0, 5]).all()
    assert ((theta[:, wrist == 1, 5] <= 0) | half_turn[:, wrist == 1, 5]).all()
    return reach


@pytest.fixture(scope="module")
def lwr():
    return robot("lwr4")


@pytest.fixture(scope="module")
def targets(lwr):
    Q = random_configurations(lwr, N, seed=11)
    return Q, fk_batch(lwr, Q)


# --- random reachable targets ----------------------------------------------------------------------
def test_fk_batch_matches_reference(lwr, targets):
    Q, T = targets
    for k in range(0, N, 997):
        np.testing.assert_allclose(T[k], fk_numpy(lwr, Q[k]), rtol=0, atol=1e-14)
    x = matrix_to_dq(T[:100])
    x_gen = evaluate_symbolic("lwr4", "fk_dq", q=Q[:100])["x"]
    sign = np.sign(np.sum(x[:, :4] * x_gen[:, :4], axis=1, keepdims=True))   # either sign
    np.testing.assert_allclose(x, sign * x_gen, rtol=0, atol=1e-12)


@pytest.mark.parametrize("form", FORMS)
def test_own_theta3_recovers_configuration(lwr, targets, form):
    Q, T = targets
    q, status = solve(form, T, Q[:, 2], np.random.default_rng(1))
    reach = check_common(lwr, q, status, T, Q[:, 2])
    assert reach.all(), "targets from FK with their own q3 are reachable"
    diff = angle_diff(q, Q[:, None, :]).max(axis=-1)           # (N, 8)
    best = diff.argmin(axis=1)
    assert diff[np.arange(N), best].max() < 1e-7
    assert np.isin(status[np.arange(N), best], ADMISSIBLE).all()
    # many targets have several admissible branches
    assert (np.isin(status, ADMISSIBLE).sum(axis=1) >= 2).mean() > 0.5


@pytest.mark.parametrize("form", FORMS)
def test_random_theta3(lwr, targets, form):
    Q, T = targets
    rng = np.random.default_rng(2)
    theta3 = rng.uniform(lwr.lower[2], lwr.upper[2], N)
    q, status = solve(form, T, theta3, rng)
    check_common(lwr, q, status, T, theta3)
    assert (status == 0).any() and (status == UNREACHABLE).any()
    # unreachable exactly where the independent test says so (away from the boundary)
    p = T[:, :3, 3]
    c4 = (np.sum(p * p, axis=1) - D3 ** 2 - D5 ** 2) / (2 * D3 * D5)
    s4 = np.sqrt(np.clip(1 - c4 ** 2, 0, None))
    margin = np.hypot(p[:, 0], p[:, 1]) - np.abs(D5 * np.sin(theta3) * s4)
    clear = (np.abs(c4) < 1 - 1e-9) & (np.abs(margin) > 1e-9)
    np.testing.assert_array_equal((status[clear] == UNREACHABLE).all(axis=1), margin[clear] < 0)
    np.testing.assert_array_equal((status[clear] == UNREACHABLE).any(axis=1), margin[clear] < 0)


@pytest.mark.parametrize("form", FORMS)
def test_twin_structure(lwr, targets, form):
    """Rows 4s+2+w are the elbow twins of rows 4s+w, rows 4s+2e+1 the wrist twins."""
    Q, T = targets
    n = 2000
    q, status = solve(form, T[:n], Q[:n, 2])
    # shoulder bit: r = c1 px + s1 py has the sign of +q4 (s = 0) or -q4 (s = 1)
    r = np.cos(q[..., 0]) * T[:n, None, 0, 3] + np.sin(q[..., 0]) * T[:n, None, 1, 3]
    shoulder = np.arange(8) >> 2
    assert (r[:, shoulder == 0] * q[:, shoulder == 0, 3] >= -1e-12).all()
    assert (r[:, shoulder == 1] * q[:, shoulder == 1, 3] <= 1e-12).all()
    regular = (status != WRIST_SINGULAR).all(axis=1)
    for s in (0, 1):
        for w in (0, 1):
            a, b = q[regular, 4 * s + w], q[regular, 4 * s + 2 + w]
            expected = np.stack([a[:, 0] + np.pi, -a[:, 1], a[:, 2], -a[:, 3], a[:, 4] + np.pi, a[:, 5], a[:, 6]], -1)
            assert angle_diff(b, expected).max() < 1e-12
        for e in (0, 1):
            a, b = q[regular, 4 * s + 2 * e], q[regular, 4 * s + 2 * e + 1]
            expected = np.stack([a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4] + np.pi, -a[:, 5], a[:, 6] + np.pi], -1)
            assert angle_diff(b, expected).max() < 1e-12


def test_forms_agree(lwr, targets):
    Q, T = targets
    rng = np.random.default_rng(3)
    theta3 = rng.uniform(-3, 3, N)
    qh, sh = solve("ik_hom", T, theta3)
    qd, sd = solve("ik_dq", T, theta3, rng)
    assert (sh == sd).mean() > 0.999
    both = (sh == sd) & (sh != UNREACHABLE)
    assert angle_diff(qh, qd)[both].max() < 1e-8


# --- special targets -----------------------------------------------------------------------------
def special(lwr, form, Q, theta3=None):
    T = fk_batch(lwr, Q)
    theta3 = Q[:, 2] if theta3 is None else theta3
    q, status = solve(form, T, theta3, np.random.default_rng(4))
    check_common(lwr, q, status, T, theta3)
    return q, status


@pytest.mark.parametrize("form", FORMS)
def test_wrist_singular(lwr, form):
    Q = random_configurations(lwr, 300, seed=5)
    Q[:, 5] = 0.0
    q, status = special(lwr, form, Q)
    # the original's arm branch: q1..q4 match (q5 and q7 are a family at q6 = 0)
    diff = angle_diff(q[..., :4], Q[:, None, :4]).max(axis=-1)
    best = diff.argmin(axis=1)
    rows = np.arange(len(Q))
    assert diff[rows, best].max() < 1e-7
    # wrist singular (and admissible), identical to its wrist twin, the rotation about the
    # common axis of joints 5 and 7 split equally: q5 = q7 within +-135 deg
    assert (status[rows, best] == WRIST_SINGULAR).all()
    assert (status[rows, best ^ 1] == WRIST_SINGULAR).all()
    np.testing.assert_array_equal(q[rows, best & ~1], q[rows, best | 1])
    assert (np.abs(q[rows, best, 5]) < 1e-12).all()
    assert np.abs(q[rows, best, 4] - q[rows, best, 6]).max() < 1e-12
    assert np.abs(q[rows, best, 4]).max() <= 0.75 * np.pi + 1e-12
    assert angle_diff(q[rows, best, 4] + q[rows, best, 6], Q[:, 4] + Q[:, 6]).max() < 1e-9


@pytest.mark.parametrize("form", FORMS)
def test_wrist_antialigned(lwr, form):
    """q6 = +-pi (beyond the limits, joints 5 and 7 anti-aligned): a valid member, status 1."""
    Q = random_configurations(lwr, 200, seed=16)
    Q[:100, 5], Q[100:, 5] = np.pi, -np.pi
    q, status = special(lwr, form, Q)
    diff = angle_diff(q[..., :4], Q[:, None, :4]).max(axis=-1)
    best = diff.argmin(axis=1)
    rows = np.arange(len(Q))
    assert (status[rows, best] == LIMITS).all()
    assert angle_diff(q[rows, best, 5], np.pi).max() < 1e-7
    # exactly anti-aligned inputs (zeros where the formulas divide): still reproduced
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, :3, :3] = [np.diag([1, -1, -1]), np.diag([-1, 1, -1]), np.diag([-1, -1, 1]), np.eye(3)]
    T[:, :3, 3] = [0.3, 0.2, 0.4]
    for theta3 in (0.0, 0.7):
        q, status = solve(form, T, theta3)
        check_common(lwr, q, status, T, np.full(len(T), theta3))


@pytest.mark.parametrize("form", FORMS)
def test_elbow_singular(lwr, form):
    Q = random_configurations(lwr, 300, seed=6)
    Q[:, 3] = 0.0                         # stretched: the boundary of the workspace
    q, status = special(lwr, form, Q)
    assert np.isin(status, [ELBOW_SINGULAR, LIMITS]).all()
    assert (status == ELBOW_SINGULAR).any(axis=1).all()
    assert (q[:, :, 3] == 0).all()
    diff = angle_diff(q, Q[:, None, :]).max(axis=-1)
    assert diff.min(axis=1).max() < 1e-7


@pytest.mark.parametrize("form", FORMS)
def test_shoulder_singular(lwr, form):
    # the brief's case: q2 = 0 with the wrist centre on the z0 axis (then also q4 = 0)
    Q = random_configurations(lwr, 200, seed=7)
    Q[:, 1] = Q[:, 3] = 0.0
    q, status = special(lwr, form, Q)
    # (the member with q1 = 0 can put the wrist outside its limits: then status 1)
    assert np.isin(status, [SHOULDER_SINGULAR, LIMITS]).all()
    assert (status == SHOULDER_SINGULAR).any(axis=1).mean() > 0.5
    assert (q[:, [0, 1, 4, 5], 0] == 0).all()                  # q1 = 0 chosen (q1 free)
    # wrist centre on the z0 axis with the elbow bent: q3 = 0, q2 = atan2(d5 s4, d3 + d5 c4)
    Q = random_configurations(lwr, 200, seed=8)
    Q[:, 2] = 0.0
    Q[:, 3] = np.where(np.abs(Q[:, 3]) < 0.1, 0.5, Q[:, 3])
    Q[:, 1] = np.arctan2(D5 * np.sin(Q[:, 3]), D3 + D5 * np.cos(Q[:, 3]))
    q, status = special(lwr, form, Q)
    assert np.isin(status, [SHOULDER_SINGULAR, LIMITS]).all()
    assert (status == SHOULDER_SINGULAR).any(axis=1).mean() > 0.5
    # ... which no other theta3 reaches (|v| = d5 |sin q3 sin q4| > 0)
    _, status = special(lwr, form, Q, theta3=np.full(len(Q), 0.5))
    assert (status == UNREACHABLE).all()
    # the shoulder cylinder: r = 0 with q3 != 0 (both shoulder branches coincide)
    Q = random_configurations(lwr, 200, seed=9)
    Q[:, 3] = np.where(np.abs(Q[:, 3]) < 0.1, 0.5, Q[:, 3])
    u, w = D5 * np.cos(Q[:, 2]) * np.sin(Q[:, 3]), D3 + D5 * np.cos(Q[:, 3])
    Q[:, 1] = np.arctan2(u, w)
    q, status = special(lwr, form, Q)
    assert np.isin(status, [SHOULDER_SINGULAR, LIMITS]).all()
    assert (status == SHOULDER_SINGULAR).any(axis=1).all()      # the original is a member
    assert angle_diff(q[:, 0:4], q[:, 4:8]).max() < 1e-4   # coincide (to ~sqrt(eps): r = sqrt(r^2))


@pytest.mark.parametrize("form", FORMS)
def test_outside_workspace(lwr, form):
    rng = np.random.default_rng(10)
    Q = random_configurations(lwr, 500, seed=10)
    T = fk_batch(lwr, Q)
    direction = T[:, :3, 3] / np.linalg.norm(T[:, :3, 3], axis=1, keepdims=True)
    radius = np.concatenate([rng.uniform(D3 + D5 + 1e-9, 0.8, 200), rng.uniform(0.8, 1e3, 200),
                             rng.uniform(0, D3 - D5 - 1e-9, 100)])       # beyond reach, or inside the hole
    T[:, :3, 3] = direction * radius[:, None]
    for theta3 in (Q[:, 2], rng.uniform(-3, 3, len(Q))):
        q, status = solve(form, T, theta3, rng)
        assert np.isfinite(q).all()
        assert (status == UNREACHABLE).all()


@pytest.mark.parametrize("form", FORMS)
def test_no_nan_for_any_finite_input(form):
    rng = np.random.default_rng(12)
    n = 3000
    size = 10.0 ** rng.integers(-320, 308, size=(n, 1))   # times normal(0, 1): clipped below
    theta3 = rng.uniform(-1e3, 1e3, n)
    theta3[:10] = [0, -0.0, np.pi, -np.pi, 1e300, -1e300, 5e-324, 1e-300, 2 * np.pi, 7]
    if form == "ik_hom":
        with np.errstate(over="ignore"):
            T = np.clip(rng.normal(size=(n, 4, 4)) * size[:, :, None], -1.7e308, 1.7e308)
        T[:20] = 0.0
        T[20:40] = -0.0
        T[40:60] = np.sign(T[40:60]) * 1.7976931348623157e308
        T[60:80] = np.eye(4)                                      # target at the base origin
        out = evaluate_symbolic("lwr4", "ik_hom", T=T, theta3=theta3)
    else:
        with np.errstate(over="ignore"):
            x = np.clip(rng.normal(size=(n, 8)) * size, -1.7e308, 1.7e308)
        x[:20] = 0.0
        x[20:40] = -0.0
        x[40:60] = np.sign(x[40:60]) * 1.7976931348623157e308
        x[60:80] = [1, 0, 0, 0, 0, 0, 0, 0]
        out = evaluate_symbolic("lwr4", "ik_dq", x=x, theta3=theta3)
    assert np.isfinite(out["q"]).all()
    assert np.isin(out["status"], [0, 1, 2, 3, 4, 5]).all()
    assert (out["status"][:80] == UNREACHABLE).all()


def test_dq_sign_does_not_matter(lwr, targets):
    Q, T = targets
    x = matrix_to_dq(T[:500])
    a = evaluate_symbolic("lwr4", "ik_dq", x=x, theta3=Q[:500, 2])
    b = evaluate_symbolic("lwr4", "ik_dq", x=-x, theta3=Q[:500, 2])
    np.testing.assert_array_equal(a["status"], b["status"])
    assert angle_diff(a["q"], b["q"]).max() < 1e-12


# --- applicability, other LWR-like tables ------------------------------------------------------
def test_only_lwr_like_arms():
    # the Hartl table (all alphas +pi/2) is the same arm: LWR type too (tests/ik/test_ik_geometry.py)
    for name in ("lwr4", "lwr4_hartl"):
        assert lwr_geometry(robot(name)) is not None
        assert [f.name for f in derive_all(robot(name), only={"ik_hom", "ik_dq"})] == ["ik_hom", "ik_dq"]
    assert lwr_geometry(robot("panda")) is None
    assert derive_all(robot("panda"), only={"ik_hom", "ik_dq"}) == []


def lwr_variant(d3, d5, offsets=(0,) * 7, lower=None, upper=None, alphas=None, a=None):
    alphas = alphas or ["pi/2", "-pi/2", "-pi/2", "pi/2", "pi/2", "-pi/2", 0]
    lower = lower or [-2.9, -2.0, -2.9, -2.0, -2.9, -2.0, -2.9]
    upper = upper or [2.9, 2.0, 2.9, 2.0, 2.9, 2.0, 2.9]
    joints = [{"a": 0 if a is None else a[i], "alpha": alphas[i], "d": [0, 0, d3, 0, d5, 0, 0][i],
               "offset": offsets[i], "lower": lower[i], "upper": upper[i]} for i in range(7)]
    links = [{"mass": 1.0, "com": [0, 0, 0], "inertia": [0.01, 0.01, 0.01, 0, 0, 0]}] * 7
    return parse_robot({"name": "lwr_like", "dh": "standard", "gravity": [0, 0, -9.81],
                        "joints": joints, "links": links})


def test_applicability_checks():
    assert lwr_geometry(lwr_variant(0.3, 0.5)) is not None
    assert lwr_geometry(lwr_variant(0.3, 0)) is None
    assert lwr_geometry(lwr_variant(0.3, 0.5, a=[0, 0, 0.01, 0, 0, 0, 0])) is None
    assert lwr_geometry(lwr_variant(0.3, 0.5, alphas=["pi/2"] * 6 + [0])) is not None   # Hartl's table
    assert lwr_geometry(lwr_variant(0.3, 0.5, alphas=["pi/2", "pi/3"] + ["pi/2"] * 4 + [0])) is None
    assert lwr_geometry(lwr_variant(0.3, 0.5, alphas=["pi/2", 0] + ["pi/2"] * 4 + [0])) is None


def evaluate_function(f, **inputs):
    args = [s for syms in f.input_symbols for s in syms]
    fn = se.Lambdify(args, [e for exprs in f.inlined_outputs() for e in exprs], backend="lambda", cse=True)
    flat = np.concatenate([np.asarray(inputs[p.name], float).reshape(len(inputs[p.name]), -1) for p in f.inputs], axis=1)
    out = np.array([fn(row) for row in flat])
    return out[:, :56].reshape(-1, 8, 7), out[:, 56:].astype(int)


@pytest.mark.parametrize("builder", [ik_hom, ik_dq])
def test_other_lwr_like_arm_with_offsets(builder):
    """Other lengths (d3 < d5), negative d, and joint offsets: FK(q) = target, original found."""
    model = lwr_variant(-0.31, 0.45, offsets=[0.3, "pi/2", 0, -1.0, 0, "pi", 0.2],
                        lower=[-3.0] * 7, upper=[3.0] * 7)
    Q = random_configurations(model, 400, seed=13)
    T = fk_batch(model, Q)
    f = builder(model)
    if f.name == "ik_hom":
        q, status = evaluate_function(f, T=T, theta3=Q[:, 2])
    else:
        q, status = evaluate_function(f, x=matrix_to_dq(T), theta3=Q[:, 2])
    reach = check_common(model, q, status, T, Q[:, 2])
    assert reach.all()
    assert angle_diff(q, Q[:, None, :]).max(axis=-1).min(axis=1).max() < 1e-7
    assert (np.abs(q) <= np.pi + 1e-15).all()


@pytest.mark.parametrize("builder", [ik_hom, ik_dq])
def test_symbolic_lengths(builder):
    """d3, d5 as names in the YAML: one function for a family of arms (extra inputs)."""
    model = lwr_variant("l1", "l2")
    f = builder(model)
    symbols = sorted({str(s) for exprs in f.inlined_outputs() for e in exprs for s in e.free_symbols} - {
        str(s) for syms in f.input_symbols for s in syms})
    assert symbols == ["l1", "l2"]
    numeric = lwr_variant(0.40, 0.39)
    Q = random_configurations(numeric, 200, seed=14)
    T = fk_batch(numeric, Q)
    args = [s for syms in f.input_symbols for s in syms] + [se.Symbol("l1"), se.Symbol("l2")]
    fn = se.Lambdify(args, [e for exprs in f.inlined_outputs() for e in exprs], backend="lambda", cse=True)
    pose = T.reshape(len(T), -1) if f.name == "ik_hom" else matrix_to_dq(T)
    out = np.array([fn(np.concatenate([pose[k], [Q[k, 2], 0.40, 0.39]])) for k in range(len(Q))])
    q, status = out[:, :56].reshape(-1, 8, 7), out[:, 56:].astype(int)
    check_common(numeric, q, status, T, Q[:, 2])


# --- cost and printability -----------------------------------------------------------------------
@pytest.mark.parametrize("builder", [ik_hom, ik_dq])
def test_op_counts_and_printing(builder):
    f = builder(robot("lwr4"))
    program = optimize(f)
    assert program.after.mul < 400                     # the paper: 2570 (hom), 2258 (dq)
    assert program.after.add < 400                     # the paper: 1461 (hom), 1070 (dq)
    names = {s: str(s) for syms in f.input_symbols for s in syms}
    names.update({t: str(t) for t, _ in program.assignments})
    for dialect in (C, NUMPY, CASADI):
        for _, e in program.assignments:
            dialect.expr(e, names)
        for port in program.outputs:
            for e in port:
                dialect.expr(e, names)
    # no boolean common subexpressions (a comparison shared by two selects) and no logic nodes
    for _, e in program.assignments:
        assert not isinstance(e, (se.StrictLessThan, se.LessThan, se.And, se.Or, se.Not))


# --- numpy helpers ---------------------------------------------------------------------------------
def test_closest_solution(lwr, targets):
    Q, T = targets
    n = 2000
    q, status = solve("ik_hom", T[:n], Q[:n, 2])
    rng = np.random.default_rng(15)
    index, best, found = closest_solution(q, status, Q[:n] + rng.normal(scale=1e-3, size=(n, 7)))
    assert found.all()
    assert angle_diff(best, Q[:n]).max() < 1e-7
    np.testing.assert_array_equal(best, q[np.arange(n), index])
    # nothing admissible: index -1, q_ref returned
    index, best, found = closest_solution(q[:3], np.full((3, 8), UNREACHABLE), Q[:3])
    assert (index == -1).all() and not found.any() and np.array_equal(best, Q[:3])


def test_theta3_intervals(lwr, targets):
    Q, T = targets

    def ik(targets_, theta3):
        out = evaluate_symbolic("lwr4", "ik_hom", T=targets_, theta3=theta3)
        return out["q"], out["status"]

    lo, hi = lwr.lower[2], lwr.upper[2]
    for k in range(3):
        target, q_orig = T[k], Q[k]
        per_branch, union = theta3_intervals(ik, target, lo, hi, samples=361, tol=1e-10)
        q_k, _ = solve("ik_hom", T[k:k + 1], q_orig[2])
        branch = int(np.argmin(angle_diff(q_k[0], q_orig).max(axis=1)))
        assert any(a <= q_orig[2] <= b for a, b in per_branch[branch])
        assert any(a <= q_orig[2] <= b for a, b in union)
        # every interval end is a true boundary: admissible inside, not outside
        for b_index, intervals in enumerate(per_branch):
            for a, b in intervals:
                assert a <= b
                probe = [x for x in (a - 1e-8, b + 1e-8) if lo <= x <= hi]
                inside = [x for x in (a + 1e-8, b - 1e-8) if a + 1e-8 <= b - 1e-8] or [0.5 * (a + b)]
                _, st = ik(np.broadcast_to(target, (len(probe) + len(inside), 4, 4)), np.array(probe + inside))
                ok = np.isin(st[:, b_index], ADMISSIBLE)
                assert not ok[:len(probe)].any() and ok[len(probe):].all()
        # dense sampling agrees with the intervals
        dense = np.linspace(lo, hi, 2001)
        _, st = ik(np.broadcast_to(target, (dense.size, 4, 4)), dense)
        ok = np.isin(st, ADMISSIBLE)
        for b_index, intervals in enumerate(per_branch):
            inside = np.zeros(dense.size, bool)
            for a, b in intervals:
                inside |= (dense >= a) & (dense <= b)
            assert np.array_equal(inside, ok[:, b_index])
