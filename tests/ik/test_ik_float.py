"""The closed-form IK in float C (``generate --scalar float``), compiled on the host (strict
C99) and on the emulated Cortex-M4F: never NaN or Inf for finite input, no exactly singular
reachable target called unreachable or regular, and every branch not marked unreachable
reproducing its target to POSITION_TOL / ROTATION_TOL by the independent numpy FK (in
double) of tests/ik/test_ik.py. Targets: the FK (numpy double, rounded to float, and the
float C's own fk_hom) of random configurations and of exactly singular ones: wrist (q6 = 0),
elbow stretched (q4 = 0), wrist centre on the z0 axis, on the shoulder cylinder (r = 0), all
at once, q = 0, joints 5 and 7 anti-aligned. Before the float tolerances
(kindyngen/ik/lwr_common.py, TOLERANCES) the float build returned NaN on the z0 axis (its
guard 1e-150 printed as 0.0f) and called stretched arms unreachable."""
import json
import shutil

import numpy as np
import pytest

from kindyngen.codegen.pipeline import generate
from kindyngen.ik.lwr_common import ELBOW_SINGULAR, LIMITS, SHOULDER_SINGULAR, UNREACHABLE, WRIST_SINGULAR
from kindyngen.runtime import embedded
from kindyngen.runtime.evaluate import load_generated
from tests.harness import evaluate_symbolic, robot
from tests.ik.test_ik import D3, D5, FORMS, angle_diff, fk_batch, matrix_to_dq
from tests.reference import random_configurations

POSITION_TOL = 1e-4     # m: FK(q) against the target, every branch not marked unreachable
ROTATION_TOL = 1e-4     # rotation matrix entries (about rad)
N = 2000                # targets per battery
FLT_MAX = float(np.finfo(np.float32).max)


@pytest.fixture(scope="module")
def lwr():
    return robot("lwr4")


@pytest.fixture(scope="module")
def float_build(tmp_path_factory):
    """lwr4's ik_hom, ik_dq and fk_hom as float C (the folder, and the host library)."""
    folder = generate(robot("lwr4"), tmp_path_factory.mktemp("float_ik"), ("c",), progress=False,
                      only={"ik_hom", "ik_dq", "fk_hom"}, scalar="float", batch=False)
    return folder, load_generated(folder, "c")


def as_float(a):
    return np.asarray(a, np.float32).astype(float)


def ik_inputs(form, T, theta3, rng=None) -> dict:
    """The float inputs of one form for targets T (double, rounded to float here)."""
    theta3 = as_float(np.broadcast_to(np.asarray(theta3, float), (len(T),)))[:, None]
    if form == "ik_hom":
        return {"T": as_float(T), "theta3": theta3}
    return {"x": as_float(matrix_to_dq(T, rng)), "theta3": theta3}


def pose_errors(model, q, T):
    """Position (m) and largest rotation-entry errors of FK(q) (numpy, double) against T."""
    F = fk_batch(model, q)
    dp = np.linalg.norm(F[..., :3, 3] - T[:, None, :3, 3], axis=-1)
    dR = np.abs(F[..., :3, :3] - T[:, None, :3, :3]).max(axis=(-1, -2))
    return dp, dR


def check(model, q, status, T, theta3):
    """Finite, codes in range, theta3 passed through (as a float), status 1 exactly for rows
    outside the limits (1e-6 rad away from them: the C compares float angles with the limits
    rounded to float), every row not marked unreachable reproducing T."""
    assert np.isfinite(q).all()
    assert np.isin(status, [0, 1, 2, 3, 4, 5]).all()
    assert np.array_equal(q[:, :, 2], np.broadcast_to(as_float(theta3)[:, None], q.shape[:2]))
    reach = status != UNREACHABLE
    outside = ((q < model.lower) | (q > model.upper)).any(axis=-1)
    clear = (np.minimum(np.abs(q - model.lower), np.abs(q - model.upper)) > 1e-6).all(axis=-1) & reach
    np.testing.assert_array_equal((status == LIMITS)[clear], outside[clear])
    dp, dR = pose_errors(model, q, T)
    assert dp[reach].max(initial=0) < POSITION_TOL, dp[reach].max()
    assert dR[reach].max(initial=0) < ROTATION_TOL, dR[reach].max()


def solve(lib, form, T, theta3, rng=None):
    out = lib.call(form, ik_inputs(form, T, theta3, rng))
    return out["q"], out["status"].astype(int)


# --- the targets ------------------------------------------------------------------------------
def configurations(lwr, kind: str, n: int = N) -> np.ndarray:
    """Random configurations within the limits, made exactly singular as ``kind`` says."""
    Q = random_configurations(lwr, n, seed=sum(map(ord, kind)))
    bent = np.where(np.abs(Q[:, 3]) < 0.1, 0.5, Q[:, 3])
    if kind in ("wrist", "elbow and wrist", "all three"):
        Q[:, 5] = 0.0
    if kind in ("elbow", "elbow and wrist"):
        Q[:, 3] = 0.0
    if kind in ("on the z0 axis", "all three"):          # q2 = q4 = 0
        Q[:, 1] = Q[:, 3] = 0.0
    if kind == "on the z0 axis, bent":                    # q3 = 0, the wrist centre on the axis
        Q[:, 2], Q[:, 3] = 0.0, bent
        Q[:, 1] = np.arctan2(D5 * np.sin(bent), D3 + D5 * np.cos(bent))
    if kind == "shoulder cylinder":                       # r = 0 with q3 != 0, |q4| >= 0.1
        Q[:, 3] = bent
        Q[:, 1] = np.arctan2(D5 * np.cos(Q[:, 2]) * np.sin(bent), D3 + D5 * np.cos(bent))
    if kind == "anti-aligned wrist":                      # q6 = pi, beyond the limits
        Q[:, 5] = np.pi
    if kind == "zero":
        Q[:] = 0.0
    return Q


KINDS = ("random", "wrist", "elbow", "on the z0 axis", "on the z0 axis, bent", "shoulder cylinder",
         "elbow and wrist", "all three", "zero", "anti-aligned wrist")
# a status an exactly singular target must report on some row (first match wins: shoulder
# before elbow before wrist), and the statuses none of its rows may report (on the z0 axis the
# member with q1 = 0 may put the wrist outside its limits: then every row can be status 1)
FLAGGED = {"elbow": {ELBOW_SINGULAR, SHOULDER_SINGULAR},
           "elbow and wrist": {ELBOW_SINGULAR, SHOULDER_SINGULAR}, "shoulder cylinder": {SHOULDER_SINGULAR},
           "all three": {SHOULDER_SINGULAR}, "zero": {SHOULDER_SINGULAR}}
NEVER = {"elbow": {0, 3}, "elbow and wrist": {0, 3}, "on the z0 axis": {0, 3, 4}, "on the z0 axis, bent": {0, 3, 4},
         "shoulder cylinder": {0, 3, 4}, "all three": {0, 3, 4}, "zero": {0, 3, 4}}


def targets(lwr, lib, kind: str, source: str):
    Q = configurations(lwr, kind)
    if source == "float fk_hom":          # a float controller's own FK (its rounding included)
        return Q, lib.call("fk_hom", {"q": Q})["T"]
    return Q, as_float(fk_batch(lwr, Q))


# --- tests ------------------------------------------------------------------------------------
@pytest.mark.parametrize("form", FORMS)
def test_the_targets_that_gave_nan(lwr, float_build, form):
    """T = identity (unreachable), the pose at q = 0 and Tz(0.5) (wrist centre on the z0 axis):
    finite, the statuses of the double derivation, reachable rows reproduce the target."""
    _, lib = float_build
    T = np.tile(np.eye(4), (5, 1, 1))
    T[2] = fk_batch(lwr, np.zeros((1, 7)))[0]
    T[3, 2, 3] = T[4, 2, 3] = 0.5
    theta3 = np.array([0.0, 0.5, 0.0, 0.0, 0.3])
    q, status = solve(lib, form, T, theta3, np.random.default_rng(0))
    check(lwr, q, status, T, theta3)
    double = evaluate_symbolic("lwr4", "ik_hom", T=T, theta3=theta3)["status"].astype(int)
    np.testing.assert_array_equal(status, double)
    assert (status[:2] == UNREACHABLE).all() and (status[2:4] != UNREACHABLE).all()


@pytest.mark.parametrize("source", ("numpy fk, rounded", "float fk_hom"))
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("form", FORMS)
def test_reachable_targets(lwr, float_build, form, kind, source):
    """Targets the FK of configurations, their own q3 as theta3: every row reachable and
    reproducing the target; an exactly singular target reported singular."""
    _, lib = float_build
    Q, T = targets(lwr, lib, kind, source)
    q, status = solve(lib, form, T, Q[:, 2], np.random.default_rng(1))
    check(lwr, q, status, T, Q[:, 2])
    assert (status != UNREACHABLE).all()
    if kind in FLAGGED:
        flagged = np.isin(status, list(FLAGGED[kind])).any(axis=1)
        assert flagged.all(), (kind, np.unique(status[~flagged], return_counts=True))
    if kind in NEVER:
        assert not np.isin(status, list(NEVER[kind])).any(), (kind, np.unique(status, return_counts=True))
    if kind == "wrist":
        # the original's branch (its arm angles q1..q4) is never called regular: status 3, or
        # a code that takes precedence (1 outside the limits, 4 or 5 an elbow or shoulder near
        # singular as well)
        best = angle_diff(q[..., :4], Q[:, None, :4]).max(axis=-1).argmin(axis=1)
        own = status[np.arange(len(Q)), best]
        assert (own != 0).all() and (own == WRIST_SINGULAR).mean() > 0.9
    if kind == "random":
        # the original configuration is a row (to float's conditioning: 99 % within 1e-3 rad)
        diff = angle_diff(q, Q[:, None, :]).max(axis=-1).min(axis=1)
        assert np.quantile(diff, 0.99) < 1e-3, np.quantile(diff, 0.99)


@pytest.mark.parametrize("form", FORMS)
def test_random_theta3(lwr, float_build, form):
    """Other theta3: reachable rows reproduce the target, and unreachable exactly where the
    independent test says so, 1e-4 m and 1e-3 in cos q4 away from the boundary."""
    _, lib = float_build
    rng = np.random.default_rng(2)
    Q = random_configurations(lwr, N, seed=11)
    T = as_float(fk_batch(lwr, Q))
    theta3 = as_float(rng.uniform(lwr.lower[2], lwr.upper[2], N))
    q, status = solve(lib, form, T, theta3, rng)
    check(lwr, q, status, T, theta3)
    p = T[:, :3, 3]
    c4 = (np.sum(p * p, axis=1) - D3 ** 2 - D5 ** 2) / (2 * D3 * D5)
    s4 = np.sqrt(np.clip(1 - c4 ** 2, 0, None))
    margin = np.hypot(p[:, 0], p[:, 1]) - np.abs(D5 * np.sin(theta3) * s4)
    clear = (np.abs(c4) < 1 - 1e-3) & (np.abs(margin) > 1e-4)
    assert (margin[clear] < 0).any() and (margin[clear] > 0).any()
    np.testing.assert_array_equal((status[clear] == UNREACHABLE).all(axis=1), margin[clear] < 0)
    np.testing.assert_array_equal((status[clear] == UNREACHABLE).any(axis=1), margin[clear] < 0)


def extreme_inputs(form, n=3000):
    """Finite float inputs of every size: zeros, -0, denormals, FLT_MAX, identity, entries
    whose sum of squares lies just below the float bounds, theta3 up to 3e38."""
    rng = np.random.default_rng(12)
    size = 10.0 ** rng.integers(-45, 39, size=(n, 1))
    theta3 = rng.uniform(-1e3, 1e3, n)
    theta3[:10] = [0, -0.0, np.pi, -np.pi, 3e38, -3e38, 1e-45, 1e-38, 2 * np.pi, 7]
    shape = (n, 4, 4) if form == "ik_hom" else (n, 8)
    base = rng.normal(size=shape)
    with np.errstate(over="ignore"):
        a = np.clip(base * size.reshape((n,) + (1,) * (len(shape) - 1)), -FLT_MAX, FLT_MAX)
    # sums of squares of the used entries just below the bounds (1e36, 1e17)
    used = base[80:200, :3] if form == "ik_hom" else base[80:200]
    axes = tuple(range(1, used.ndim))
    norm = np.sqrt(np.sum(used ** 2, axis=axes)).reshape((120,) + (1,) * (len(shape) - 1))
    a[80:200] = base[80:200] / norm * (1e18 if form == "ik_hom" else np.sqrt(1e17)) * rng.uniform(0.5, 1.0, norm.shape)
    if form == "ik_hom":
        a[60:80] = np.eye(4)
    else:
        a[60:80] = [1, 0, 0, 0, 0, 0, 0, 0]
    a[:20], a[20:40] = 0.0, -0.0
    a[40:60] = np.sign(a[40:60]) * FLT_MAX
    return {"T" if form == "ik_hom" else "x": a.astype(np.float32), "theta3": theta3.astype(np.float32)[:, None]}


@pytest.mark.parametrize("form", FORMS)
def test_no_nan_for_any_finite_float_input(float_build, form):
    _, lib = float_build
    inputs = extreme_inputs(form)
    out = lib.call(form, inputs)
    assert np.isfinite(out["q"]).all()
    assert np.isin(out["status"], [0, 1, 2, 3, 4, 5]).all()
    assert (out["status"][:80] == UNREACHABLE).all()


def board_cases(lwr, lib):
    """{name: (form, inputs of one call)} for the board: the targets that gave NaN, one of
    each singular kind, and extreme inputs."""
    cases = {}
    T = np.tile(np.eye(4), (3, 1, 1))
    T[1] = fk_batch(lwr, np.zeros((1, 7)))[0]
    T[2, 2, 3] = 0.5
    theta3 = [0.0, 0.0, 0.0]
    for kind in ("wrist", "elbow", "on the z0 axis", "on the z0 axis, bent", "shoulder cylinder", "all three"):
        Q, Tk = targets(lwr, lib, kind, "numpy fk, rounded")
        T, theta3 = np.concatenate([T, Tk[:2]]), theta3 + list(Q[:2, 2])
    for form in FORMS:
        inputs = ik_inputs(form, T, theta3, np.random.default_rng(5))
        for k in range(len(T)):
            cases[f"{form}_{k}"] = (form, {name: v[k] for name, v in inputs.items()})
        extreme = extreme_inputs(form)
        for k in (0, 25, 45, 65, 100, 2500):
            cases[f"{form}_extreme_{k}"] = (form, {name: v[k].astype(float) for name, v in extreme.items()})
    return cases, T


@pytest.mark.skipif(embedded.missing_tools() is not None, reason=str(embedded.missing_tools()))
def test_on_emulated_cortex_m4f(lwr, float_build, tmp_path):
    """The same float C on the emulated Cortex-M4F (QEMU mps2-an386, newlib's libm): the
    board harness calls each entry of functions.json once, so a copy of the folder lists the
    IK once per target. Finite everywhere, the host's statuses, the targets reproduced."""
    folder, lib = float_build
    cases, T = board_cases(lwr, lib)
    manifest = json.loads((folder / "functions.json").read_text())
    specs = {f["name"]: f for f in manifest["functions"]}
    manifest["functions"] = [dict(specs[form], name=name) for name, (form, _) in cases.items()]
    board_folder = tmp_path / "lwr4"
    shutil.copytree(folder / "c", board_folder / "c")
    (board_folder / "functions.json").write_text(json.dumps(manifest))
    inputs = {name: {k: np.asarray(v, np.float32) for k, v in args.items()} for name, (_, args) in cases.items()}
    result = embedded.build_and_run(board_folder, embedded.TARGETS["m4f"], tmp_path / "work", inputs)
    for name, (form, args) in cases.items():
        board = result["outputs"][name]
        q, status = board["q"].astype(float), board["status"].astype(int)
        assert np.isfinite(q).all(), name
        host = lib.call(form, {k: np.asarray(v, float)[None] for k, v in args.items()})
        np.testing.assert_array_equal(status, host["status"][0].ravel(), err_msg=name)
        if "extreme" not in name:
            k = int(name.rsplit("_", 1)[1])
            reach = status != UNREACHABLE
            dp, dR = pose_errors(lwr, q.reshape(1, 8, 7), T[k:k + 1])
            assert dp[0, reach].max(initial=0) < POSITION_TOL and dR[0, reach].max(initial=0) < ROTATION_TOL, name
