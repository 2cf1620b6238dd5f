"""The LWR closed form for every arm of LWR type, recognised from its exact geometry
(:func:`kindyngen.ik.lwr_common.lwr_geometry`), whatever its description: lwr4_hartl's DH table
(all alphas +pi/2, joint offsets of pi), lwr4 with a base and a tool placed by
:class:`kindyngen.model.placement.Placement`, and iiwa-like arms given by joint origins and axes
(``dh: none``, flipped axes, twisted frames, a tool).

ik_hom and ik_dq are derived and evaluated by symengine (as in tests/ik/test_ik.py). On many
random targets every branch not marked unreachable reproduces the target to 1e-10 with the
arm's own FK, computed independently here (numpy DH product, or numpy product of URDF
origins and axis rotations); statuses mean the arm's limits on the arm's angles; the arms
that are lwr4 under another description give lwr4's statuses and (mapped) angles.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import symengine as se
import sympy

from tests.harness import robot
from tests.reference import fk_numpy, origin_matrix, random_configurations
from tests.ik.test_ik import angle_diff, fk_batch, matrix_to_dq

from kindyngen.ik.lwr_common import ADMISSIBLE, LIMITS, UNREACHABLE, lwr_geometry
from kindyngen.ik.lwr_dualquat import ik_dq
from kindyngen.ik.lwr_homogeneous import ik_hom
from kindyngen.model.placement import rpy_xyz
from kindyngen.readers.yaml_description import parse_robot

N = 3000            # random targets per check
TOL = 1e-10         # FK(q) = target: position (m) and rotation entries
BUILDERS = {"ik_hom": ik_hom, "ik_dq": ik_dq}
HARTL_SHIFT = np.array([0, np.pi, 0, np.pi, 0, np.pi, np.pi])   # q_hartl = q_lwr4 + shift (mod 2 pi)


# --- evaluation ------------------------------------------------------------------------------------
_COMPILED: dict = {}


def solve(model, form, T, theta3, rng=None):
    """(q (N, 8, 7), status (N, 8)) of the derived IK of ``model`` for targets T (N, 4, 4)."""
    key = (model.name, id(model), form)
    if key not in _COMPILED:
        f = BUILDERS[form](model)
        assert f is not None, f"{model.name}: {form} not derived"
        args = [s for syms in f.input_symbols for s in syms]
        _COMPILED[key] = (model, se.Lambdify(args, [e for exprs in f.inlined_outputs() for e in exprs], cse=True))
    fn = _COMPILED[key][1]
    pose = T.reshape(len(T), 16) if form == "ik_hom" else matrix_to_dq(T, rng)
    theta3 = np.broadcast_to(np.asarray(theta3, float), (len(T),))
    out = np.array([fn(row) for row in np.concatenate([pose, theta3[:, None]], axis=1)])
    return out[:, :56].reshape(-1, 8, 7), out[:, 56:].astype(int)


# --- independent forward kinematics ---------------------------------------------------------------
def axis_rotation(axis, q):
    """(N, 4, 4) rotations by angles q (N,) about the unit ``axis`` (Rodrigues)."""
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    c, s = np.cos(q)[:, None, None], np.sin(q)[:, None, None]
    T = np.tile(np.eye(4), (len(q), 1, 1))
    T[:, :3, :3] = np.eye(3) * c + K * s + np.outer(u, u) * (1 - c)
    return T


def frames_fk(spec, Q):
    """Tool poses of a ``dh: none`` description (the dict given to parse_robot) at Q (N, 7)."""
    T = np.tile(np.eye(4), (len(Q), 1, 1))
    for i, joint in enumerate(spec["joints"]):
        origin = joint.get("origin", {})
        placed = origin_matrix(origin.get("xyz", (0, 0, 0)), origin.get("rpy", (0, 0, 0)))
        T = T @ placed @ axis_rotation(joint["axis"], Q[:, i])
    if "tool" in spec:
        T = T @ origin_matrix(spec["tool"].get("xyz", (0, 0, 0)), spec["tool"].get("rpy", (0, 0, 0)))
    return T


def pose_errors(F, T):
    dp = np.linalg.norm(F[..., :3, 3] - T[:, None, :3, 3], axis=-1)
    dR = np.abs(F[..., :3, :3] - T[:, None, :3, :3]).max(axis=(-1, -2))
    return np.maximum(dp, dR)


def check_arm(model, fk, q, status, T, theta3):
    """Every call: finite, q3 = theta3, status 1 exactly for reachable rows outside the arm's
    limits, admissible rows within them, every reachable row reproduces the target with the
    arm's own FK, angles in their windows."""
    assert np.isfinite(q).all()
    assert np.isin(status, [0, 1, 2, 3, 4, 5]).all()
    assert np.array_equal(q[:, :, 2], np.broadcast_to(np.asarray(theta3, float)[:, None], q.shape[:2]))
    reach = status != UNREACHABLE
    outside = ((q < model.lower) | (q > model.upper)).any(axis=-1)
    np.testing.assert_array_equal((status == LIMITS)[reach], outside[reach])
    error = pose_errors(fk(q.reshape(-1, 7)).reshape(q.shape[:2] + (4, 4)), T)
    assert error[reach].max(initial=0) < TOL
    geometry = lwr_geometry(model)
    for i in (0, 1, 3, 4, 5, 6):
        _, lo, hi, _ = geometry.angle_plan(i)
        assert hi - lo <= 2 * np.pi + 1e-12
        assert (q[..., i] >= lo - 1e-12).all() and (q[..., i] <= hi + 1e-12).all()
    return reach


# --- the arms --------------------------------------------------------------------------------------
LINKS = [{"mass": 1.0, "com": [0, 0, 0], "inertia": [0.01, 0.01, 0.01, 0, 0, 0]}] * 7
IIWA_LIMITS = [170, 120, 170, 120, 170, 120, 175]     # deg, KUKA LBR iiwa 14 R820


def iiwa_spec(changes=None):
    """An iiwa-like arm (KUKA LBR iiwa 14 kinematics): shoulder 0.36 m above the base, links
    0.42 and 0.40 m, flange 0.126 m beyond the wrist, axes z, y, z, -y, z, y, z.
    ``changes``: joint index -> dict merged into that joint, "tool", "name"."""
    changes = dict(changes or {})
    heights = [0.1575, 0.2025, 0.2045, 0.2155, 0.1845, 0.2155, 0.081]
    axes = [[0, 0, 1], [0, 1, 0], [0, 0, 1], [0, -1, 0], [0, 0, 1], [0, 1, 0], [0, 0, 1]]
    joints = [{"origin": {"xyz": [0, 0, h]}, "axis": a, "lower": -math.radians(lim), "upper": math.radians(lim)}
              for h, a, lim in zip(heights, axes, IIWA_LIMITS)]
    spec = {"name": changes.pop("name", "iiwa_like"), "dh": "none", "gravity": [0, 0, -9.81],
            "joints": joints, "links": LINKS, "tool": {"xyz": [0, 0, 0.045]}}
    for key, value in changes.items():
        if key == "tool":
            spec["tool"] = value
        else:
            joints[key] = {**joints[key], **value}
    return spec


# base turned by a non-special angle, a twisted joint frame, a flipped axis, a tilted tool,
# limits beyond (-pi, pi]
TWISTED = {"name": "iiwa_twisted",
           0: {"origin": {"xyz": [0.05, -0.02, 0.1575], "rpy": [0, 0, 0.3]}},
           2: {"origin": {"xyz": [0, 0, 0.2045], "rpy": [0, 0, "pi/2"]}},
           4: {"axis": [0, 0, -1], "lower": -1.0, "upper": 5.0},
           6: {"lower": 0.2, "upper": 6.0},
           "tool": {"xyz": [0.01, 0.05, 0.045], "rpy": ["pi", 0, "pi/6"]}}


def placed_lwr4():
    """lwr4 with a base placement (rotated, offset) in front of joint 1 and a tool."""
    lwr4 = robot("lwr4")
    R = sympy.Rational
    base = rpy_xyz((R(1, 10), R(-1, 5), R(3, 10)), (sympy.pi / 2, 0, sympy.pi / 4))
    tool = rpy_xyz((R(1, 100), R(1, 50), R(1, 10)), (0, sympy.pi / 2, R(3, 10)))
    joints = (dataclasses.replace(lwr4.joints[0], before=base * lwr4.joints[0].before),) + lwr4.joints[1:]
    model = dataclasses.replace(lwr4, name="lwr4_placed", joints=joints, tool=tool)
    B, F = origin_matrix((0.1, -0.2, 0.3), (np.pi / 2, 0, np.pi / 4)), origin_matrix((0.01, 0.02, 0.1), (0, np.pi / 2, 0.3))
    return model, (lambda Q: B @ fk_batch(lwr4, Q) @ F)


@pytest.fixture(scope="module")
def lwr4_targets():
    lwr4 = robot("lwr4")
    Q = random_configurations(lwr4, N, seed=21)
    return Q, fk_batch(lwr4, Q)


# --- recognition -----------------------------------------------------------------------------------
def test_lwr4_is_the_canonical_table():
    g = lwr_geometry(robot("lwr4"))
    assert (g.d3, g.d5) == (se.Rational(2, 5), se.Rational(39, 100))
    assert g.is_canonical and g.map_text() == "" and g.base is None and g.flange is None


def test_hartl_recognised_with_its_map():
    g = lwr_geometry(robot("lwr4_hartl"))
    assert g is not None
    assert (g.d3, g.d5) == (se.Rational(2, 5), se.Rational(39, 100))
    assert g.signs == (1,) * 7
    assert tuple(g.offsets) == (0, sympy.pi, 0, sympy.pi, 0, sympy.pi, sympy.pi)    # = HARTL_SHIFT mod 2 pi
    assert g.base is None and g.flange is None
    # joints 2, 4, 6 ([60, 300] deg) and 7 ([10, 350] deg) are returned as theta + pi in [0, 2 pi]
    # (no wrapping needed: that window holds their limits), the others in (-pi, pi]
    for i in range(7):
        shift, lo, hi, wrap = g.angle_plan(i)
        if i in (1, 3, 5, 6):
            assert (shift, lo, hi, wrap) == (sympy.pi, 0.0, 2 * np.pi, False)
        else:
            assert (shift, lo, hi, wrap) == (0, -np.pi, np.pi, False)
    assert "o = (0, pi, 0, pi, 0, pi, pi)" in g.map_text()


def test_iiwa_like_recognised():
    g = lwr_geometry(parse_robot(iiwa_spec()))
    assert g is not None
    assert (g.d3, g.d5) == (se.Rational(21, 50), se.Rational(2, 5))
    # the shoulder is 0.36 m above the base, the flange 0.126 m beyond the wrist
    assert g.base is not None and g.base[0] == sympy.eye(3) and list(g.base[1]) == [0, 0, sympy.Rational(9, 25)]
    assert g.flange is not None and g.flange[0] == sympy.eye(3)
    assert list(g.flange[1]) == [0, 0, sympy.Rational(63, 500)]
    assert lwr_geometry(parse_robot(iiwa_spec(TWISTED))) is not None


def test_not_lwr_type():
    assert lwr_geometry(robot("panda")) is None
    # the elbow axis 1 cm off the shoulder-wrist line
    assert lwr_geometry(parse_robot(iiwa_spec({3: {"origin": {"xyz": [0.01, 0, 0.2155]}}}))) is None
    # the wrist not spherical (joint 7 axis 1 cm off joint 6's)
    assert lwr_geometry(parse_robot(iiwa_spec({6: {"origin": {"xyz": [0, 0.01, 0.081]}}}))) is None
    # joints 2 and 3 not perpendicular
    assert lwr_geometry(parse_robot(iiwa_spec({2: {"axis": [0, 1, 1]}}))) is None
    # no upper arm (elbow at the shoulder)
    at_shoulder = {"origin": {"xyz": [0, 0, 0]}}
    assert lwr_geometry(parse_robot(iiwa_spec({2: at_shoulder, 3: at_shoulder}))) is None
    # a prismatic joint, six joints
    spec = iiwa_spec()
    spec["joints"][6] = {**spec["joints"][6], "type": "prismatic"}
    assert lwr_geometry(parse_robot(spec)) is None
    spec = iiwa_spec()
    spec["joints"], spec["links"] = spec["joints"][:6], LINKS[:6]
    assert lwr_geometry(parse_robot(spec)) is None


# --- lwr4_hartl: the lwr4 solution under the change of coordinates -----------------------------------
@pytest.mark.parametrize("form", BUILDERS)
@pytest.mark.parametrize("own_theta3", [True, False])
def test_hartl_ik(lwr4_targets, form, own_theta3):
    lwr4, hartl = robot("lwr4"), robot("lwr4_hartl")
    Q, T = lwr4_targets
    np.testing.assert_allclose(fk_batch(hartl, Q + HARTL_SHIFT), T, rtol=0, atol=1e-12)   # the same arm
    theta3 = Q[:, 2] if own_theta3 else np.random.default_rng(22).uniform(lwr4.lower[2], lwr4.upper[2], N)
    q_h, status_h = solve(hartl, form, T, theta3, np.random.default_rng(23))
    q_l, status_l = solve(lwr4, form, T, theta3, np.random.default_rng(23))
    reach = check_arm(hartl, lambda q: fk_batch(hartl, q), q_h, status_h, T, theta3)
    # the same rows, the same statuses, the angles shifted
    np.testing.assert_array_equal(status_h, status_l)
    assert angle_diff(q_h, q_l + HARTL_SHIFT).max() < 1e-12
    if own_theta3:
        assert reach.all()
        diff = angle_diff(q_h, (Q + HARTL_SHIFT)[:, None, :]).max(axis=-1)
        best = diff.argmin(axis=1)
        assert diff[np.arange(N), best].max() < 1e-7
        assert np.isin(status_h[np.arange(N), best], ADMISSIBLE).all()
    else:
        assert (status_h == 0).any() and (status_h == UNREACHABLE).any() and (status_h == LIMITS).any()


# --- lwr4 with a base and a tool: lwr4's angles --------------------------------------------------------
@pytest.mark.parametrize("form", BUILDERS)
def test_placed_lwr4_ik(lwr4_targets, form):
    lwr4 = robot("lwr4")
    model, fk = placed_lwr4()
    g = lwr_geometry(model)
    assert g is not None and g.base is not None and g.flange is not None
    assert (g.d3, g.d5) == (se.Rational(2, 5), se.Rational(39, 100))
    Q, T_lwr4 = lwr4_targets
    n = N // 3
    T = fk(Q[:n])
    rng = np.random.default_rng(24)
    for theta3 in (Q[:n, 2], rng.uniform(lwr4.lower[2], lwr4.upper[2], n)):
        q, status = solve(model, form, T, theta3, rng)
        check_arm(model, fk, q, status, T, theta3)
        q_l, status_l = solve(lwr4, form, T_lwr4[:n], theta3, rng)
        np.testing.assert_array_equal(status, status_l)
        assert angle_diff(q, q_l).max() < 1e-9


# --- iiwa-like arms by origins and axes ----------------------------------------------------------------
@pytest.mark.parametrize("form", BUILDERS)
@pytest.mark.parametrize("changes", [{}, TWISTED], ids=["iiwa", "iiwa_twisted"])
def test_iiwa_like_ik(form, changes):
    spec = iiwa_spec(changes)
    model = parse_robot(spec)
    fk = lambda Q: frames_fk(spec, Q)                       # noqa: E731
    n = N // 3
    Q = random_configurations(model, n, seed=25)
    T = fk(Q)
    q, status = solve(model, form, T, Q[:, 2], np.random.default_rng(26))
    reach = check_arm(model, fk, q, status, T, Q[:, 2])
    assert reach.all()
    diff = angle_diff(q, Q[:, None, :]).max(axis=-1)
    best = diff.argmin(axis=1)
    assert diff[np.arange(n), best].max() < 1e-7
    assert np.isin(status[np.arange(n), best], ADMISSIBLE).all()
    # within the limits the original itself is returned (not another turn of it)
    assert np.abs(q[np.arange(n), best] - Q).max() < 1e-7
    theta3 = np.random.default_rng(27).uniform(model.lower[2], model.upper[2], n)
    q, status = solve(model, form, T, theta3, np.random.default_rng(28))
    check_arm(model, fk, q, status, T, theta3)
    assert (status == 0).any() and (status == UNREACHABLE).any()


@pytest.mark.parametrize("form", BUILDERS)
def test_mapped_arm_finite_for_any_input(form):
    """The map (base and tool) in front of the closed form keeps every output finite
    (T = 0 is no pose: its image B^-1 0 F^-1 has the translation -R_B^T p_B, any status)."""
    model = parse_robot(iiwa_spec(TWISTED))
    rng = np.random.default_rng(29)
    n = 600
    size = 10.0 ** rng.integers(-320, 308, size=(n, 1))
    with np.errstate(over="ignore"):
        raw = np.clip(rng.normal(size=(n, 16 if form == "ik_hom" else 8)) * size, -1.7e308, 1.7e308)
    raw[:20] = 0.0
    raw[20:40] = np.sign(raw[20:40]) * 1.7976931348623157e308
    f = BUILDERS[form](model)
    fn = se.Lambdify([s for syms in f.input_symbols for s in syms], [e for exprs in f.inlined_outputs() for e in exprs],
                     cse=True)
    theta3 = rng.uniform(-1e3, 1e3, n)
    out = np.array([fn(row) for row in np.concatenate([raw, theta3[:, None]], axis=1)])
    assert np.isfinite(out).all()
    assert np.isin(out[:, 56:], [0, 1, 2, 3, 4, 5]).all()
    # inputs too large are replaced by the zero pose of the canonical arm: unreachable
    assert (out[20:40, 56:] == UNREACHABLE).all()


# --- a modified (Craig) DH table ---------------------------------------------------------------------
MODIFIED = {"lwr": ["0", "pi/2", "-pi/2", "-pi/2", "pi/2", "pi/2", "-pi/2"],
            "all_plus": ["0", "pi/2", "pi/2", "pi/2", "pi/2", "pi/2", "pi/2"]}


@pytest.mark.parametrize("form", BUILDERS)
@pytest.mark.parametrize("table", MODIFIED)
def test_modified_dh_tables(form, table):
    """The LWR as a modified DH table (alpha_{i-1} before each joint), with the canonical signs
    of alpha or all of them +pi/2: recognised, targets reproduced (Craig's product, numpy)."""
    joints = [{"a": 0, "alpha": alpha, "d": d, "lower": lo, "upper": up}
              for alpha, d, lo, up in zip(MODIFIED[table], [0, 0, 0.4, 0, 0.39, 0, 0],
                                          [-2.9, 0.5, -2.9, 0.5, -2.9, 0.5, -2.9], [2.9, 5.8, 2.9, 5.8, 2.9, 5.8, 2.9])]
    model = parse_robot({"name": f"lwr_modified_{table}", "dh": "modified", "gravity": [0, 0, -9.81],
                         "joints": joints, "links": LINKS})
    g = lwr_geometry(model)
    assert g is not None and (g.d3, g.d5) == (se.Rational(2, 5), se.Rational(39, 100))

    def fk(Q):
        return np.array([fk_numpy(model, q) for q in Q])

    n = 300
    Q = random_configurations(model, n, seed=30)
    T = fk(Q)
    q, status = solve(model, form, T, Q[:, 2], np.random.default_rng(31))
    assert check_arm(model, fk, q, status, T, Q[:, 2]).all()
    diff = angle_diff(q, Q[:, None, :]).max(axis=-1)
    best = diff.argmin(axis=1)
    assert diff[np.arange(n), best].max() < 1e-7
    assert np.abs(q[np.arange(n), best] - Q).max() < 1e-7      # the in-limits representative
