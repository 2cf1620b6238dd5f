"""examples/mpc_sqp.py (the tracking MPC of examples/mpc.py --solver sqp | rti), checked by
independent computations:

- the compiled RK4 step's Jacobians A, B equal central finite differences of its own step F;
- the MPC's prediction (the compiled RK4 step of the generated fd, 2 steps per 50 ms
  interval) agrees with the plant (Pinocchio's ABA, RK4 at 1 kHz, no payload) after the first
  interval within 1e-3 (rad, rad/s; measured 2.7e-4 from the reach's start), also from the
  converged SQP solution;
- the condensed QP (G, c by the recursion, H = G' Wx G + Wu) gives the same step as the
  sparse multiple-shooting KKT system written here in numpy (states and torques as unknowns,
  the linearised dynamics with their gaps as equality rows): unconstrained, and with DAQP's
  active set made equality rows;
- the speed rows inside the intervals (the joint speeds at the RK4 substep ends): their values
  equal Pinocchio's ABA integrated by a numpy RK4 over the first substep, their Jacobians Av,
  Bv central finite differences of the compiled values, and the condensed rows Gv dU + cv the
  linearised speeds propagated interval by interval in a plain loop here; the QP's step keeps
  them within the tightened bound (1 - speed_margin) qd_max;
- a short closed loop (sqp, lwr4 and panda) writes the documented fields with no failed solve.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pinocchio")
pytest.importorskip("daqp")
ROOT = Path(__file__).resolve().parents[2]
for _p in (str(ROOT / "examples"), str(ROOT / "tests")):
    if _p not in sys.path:
        sys.path.insert(0, _p)
import mpc  # noqa: E402
import mpc_sqp  # noqa: E402


@pytest.fixture(scope="module")
def lwr():
    funcs = mpc_sqp.load("lwr4")
    ref = mpc_sqp.reference("lwr4", 20, 2, funcs)
    ctl = mpc_sqp.TrackingMPC(funcs, ref["limits"], ref["X"], ref["U"], ref["h"], 20, substeps=2)
    return funcs, ref, ctl


def _perturbed(ctl, ref, seed=0):
    """A linearisation point off the reference (so the gaps and the residuals are not zero)."""
    rng = np.random.default_rng(seed)
    x0 = ref["x0"] + np.concatenate([0.01 * rng.standard_normal(7), 0.05 * rng.standard_normal(7)])
    X, U = ctl.initial_guess(0)
    X = X + 0.01 * rng.standard_normal(X.shape)
    U = U + 0.5 * rng.standard_normal(U.shape)
    return x0, X, U


def test_step_jacobians_by_finite_differences(lwr):
    _, ref, ctl = lwr
    x0, X, U = _perturbed(ctl, ref)
    F, A, B = ctl.linearise(x0, X, U)[:3]
    eps = 1e-6
    for k in (0, 7, 19):
        xk = x0 if k == 0 else X[k - 1]
        def f(x, u):
            XX, UU = X.copy(), U.copy()
            UU[k] = u
            if k == 0:
                return ctl.linearise(x, XX, UU)[0][0]
            XX[k - 1] = x
            return ctl.linearise(x0, XX, UU)[0][k]
        Afd = np.array([(f(xk + eps * e, U[k]) - f(xk - eps * e, U[k])) / (2 * eps) for e in np.eye(14)]).T
        Bfd = np.array([(f(xk, U[k] + eps * e) - f(xk, U[k] - eps * e)) / (2 * eps) for e in np.eye(7)]).T
        assert np.abs(A[k] - Afd).max() < 1e-5 * max(1.0, np.abs(Afd).max())
        assert np.abs(B[k] - Bfd).max() < 1e-5 * max(1.0, np.abs(Bfd).max())


def test_prediction_matches_plant_first_step(lwr):
    funcs, ref, ctl = lwr
    step, _ = mpc.plant(funcs["robot"], 0.0)
    X, U = ctl.initial_guess(0)
    F = ctl.linearise(ref["x0"], X, U)[0]
    x1, _ = step(ref["x0"], U[0], ref["h"])
    assert np.abs(x1 - F[0]).max() < 1e-3
    # from a state off the reference, the converged SQP's node 1 against the plant
    x0 = ref["x0"] + np.concatenate([np.zeros(7), 0.02 * np.ones(7)])
    r = ctl.solve(x0, X, U, 0)
    assert r["converged"], r
    x1, _ = step(x0, r["U"][0], ref["h"])
    assert np.abs(x1 - r["X"][0]).max() < 1e-3


def test_inner_speed_rows(lwr):
    """The speed rows between the nodes: values, Jacobians and condensing, each against an
    independent computation."""
    import pinocchio as pin
    from reference import pinocchio_model
    funcs, ref, ctl = lwr
    n, N = ctl.n, ctl.N
    assert ctl.nv == n          # 2 RK4 substeps per interval: one inner state, its n speeds
    x0, X, U = _perturbed(ctl, ref, seed=1)
    F, A, B, V, Av, Bv = ctl.linearise(x0, X, U)
    # values: one RK4 substep (h / 2) of Pinocchio's ABA from the interval's start node
    model, data, _ = pinocchio_model(funcs["robot"])
    hs = ref["h"] / 2
    def f(x, u):
        return np.concatenate([x[n:], pin.aba(model, data, x[:n], x[n:], u)])
    for k in (0, 9, 19):
        x = x0 if k == 0 else X[k - 1]
        k1 = f(x, U[k]); k2 = f(x + hs / 2 * k1, U[k]); k3 = f(x + hs / 2 * k2, U[k]); k4 = f(x + hs * k3, U[k])
        v_pin = (x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4))[n:]
        assert np.abs(V[k] - v_pin).max() < 1e-8 * max(1.0, np.abs(v_pin).max())
    # Jacobians: central finite differences of the compiled inner speeds
    eps = 1e-6
    for k in (0, 12):
        xk = x0 if k == 0 else X[k - 1]
        def v(x, u):
            XX, UU = X.copy(), U.copy()
            UU[k] = u
            if k == 0:
                return ctl.linearise(x, XX, UU)[3][0]
            XX[k - 1] = x
            return ctl.linearise(x0, XX, UU)[3][k]
        Afd = np.array([(v(xk + eps * e, U[k]) - v(xk - eps * e, U[k])) / (2 * eps) for e in np.eye(2 * n)]).T
        Bfd = np.array([(v(xk, U[k] + eps * e) - v(xk, U[k] - eps * e)) / (2 * eps) for e in np.eye(n)]).T
        assert np.abs(Av[k] - Afd).max() < 1e-5 * max(1.0, np.abs(Afd).max())
        assert np.abs(Bv[k] - Bfd).max() < 1e-5 * max(1.0, np.abs(Bfd).max())
        # the inner speed rows are the speed rows of the chained A, B halfway (a wrong slice
        # of the chain, e.g. the node's own rows, differs by the second substep's change)
        assert np.abs(Av[k] - A[k][n:]).max() > 1e-3
    # condensing: dv_k = Av_k dx_k + Bv_k du_k, dx_{k+1} = A_k dx_k + B_k du_k + d_k, dx_0 = 0
    q = ctl.qp(x0, X, U, 0)
    dU = 0.3 * np.random.default_rng(2).standard_normal((N, n))
    dx, dv = np.zeros(2 * n), []
    for k in range(N):
        dv.append(Av[k] @ dx + Bv[k] @ dU[k])
        dx = A[k] @ dx + B[k] @ dU[k] + q["d"][k]
    assert np.abs(q["Gv"] @ dU.ravel() + q["cv"] - np.concatenate(dv)).max() < 1e-9 * max(1.0, np.abs(dv).max())


def test_qp_step_keeps_inner_speeds_in_margin(lwr):
    """With a 10 % margin the QP's step keeps the linearised inner speeds (and the node speeds)
    within 0.9 qd_max, up to DAQP's soft-row slack, from the reference plan at its limits."""
    funcs, ref, _ = lwr
    ctl = mpc_sqp.TrackingMPC(funcs, ref["limits"], ref["X"], ref["U"], ref["h"], 20, substeps=2, speed_margin=0.1)
    assert np.allclose(ctl.xhi[7:], 0.9 * np.asarray(ref["limits"]["qd_max"]))
    X, U = ctl.initial_guess(0)
    q = ctl.qp(ref["x0"], X, U, 0)
    assert (q["v_hi"] < 0).any() or (q["v_lo"] > 0).any(), "the plan at its limits should pass 0.9 qd_max inside"
    du, flag, _, _ = ctl.solve_qp(q)
    assert flag in (1, 2), flag         # 2: optimal with soft rows relaxed (by DAQP's slack, ~1e-6 here)
    v = (q["V"].ravel() + q["cv"] + q["Gv"] @ du).reshape(ctl.N, 7)
    qd = (X.ravel() + q["c"] + q["G"] @ du).reshape(ctl.N, 14)[:, 7:]
    vmax = 0.9 * np.asarray(ref["limits"]["qd_max"])
    assert np.all(np.abs(v) <= vmax * (1 + 1e-3)), np.max(np.abs(v) / vmax)
    assert np.all(np.abs(qd) <= vmax * (1 + 1e-3)), np.max(np.abs(qd) / vmax)


def _sparse_kkt(ctl, x0, X, U, q, active_rows=()):
    """The Gauss-Newton QP in (dx_1..dx_N, du_0..du_N-1) with the dynamics as equality rows
    dx_{k+1} - A_k dx_k - B_k du_k = F_k - x_{k+1} (dx_0 = 0) and the given active bound rows
    (index into [box on du; rows on dx; inner speed rows], value) as equalities, an inner row of
    interval k being Av_k dx_k + Bv_k du_k; solved by one numpy KKT solve."""
    N, n, nx = ctl.N, ctl.n, ctl.nx
    nX, nU = N * nx, N * n
    Xr, Ur = q["Xr"], q["Ur"]
    Hs = np.diag(np.concatenate([ctl.wx, ctl.wu]))
    gs = np.concatenate([ctl.wx * (X - Xr).ravel(), ctl.wu * (U - Ur).ravel()])
    E = np.zeros((nX, nX + nU))
    rhs = np.zeros(nX)
    for k in range(N):
        E[k * nx:(k + 1) * nx, k * nx:(k + 1) * nx] = np.eye(nx)
        if k > 0:
            E[k * nx:(k + 1) * nx, (k - 1) * nx:k * nx] = -q["A"][k]
        E[k * nx:(k + 1) * nx, nX + k * n:nX + (k + 1) * n] = -q["B"][k]
        rhs[k * nx:(k + 1) * nx] = q["F"][k] - X[k]
    rows, vals = [], []
    for idx, val in active_rows:
        r = np.zeros(nX + nU)
        if idx < nU:
            r[nX + idx] = 1.0
        elif idx < nU + nX:
            r[idx - nU] = 1.0
        else:
            k, j = divmod(idx - nU - nX, ctl.nv)
            if k > 0:
                r[(k - 1) * nx:k * nx] = q["Av"][k][j]
            r[nX + k * n:nX + (k + 1) * n] = q["Bv"][k][j]
        rows.append(r)
        vals.append(val)
    C = np.vstack([E] + ([np.array(rows)] if rows else []))
    b = np.concatenate([rhs, np.array(vals)])
    m = C.shape[0]
    K = np.block([[Hs, C.T], [C, np.zeros((m, m))]])
    sol = np.linalg.solve(K, np.concatenate([-gs, b]))
    return sol[nX:nX + nU], sol[:nX]


def test_condensed_qp_equals_sparse_kkt(lwr):
    _, ref, ctl = lwr
    x0, X, U = _perturbed(ctl, ref)
    q = ctl.qp(x0, X, U, 0)
    du_c = np.linalg.solve(q["H"], -q["g"])
    du_s, dx_s = _sparse_kkt(ctl, x0, X, U, q)
    # 1e-4 relative: the condensed Hessian's condition number is ~1e12 (terminal speed weight
    # against the wrist's torque weight), so both solves carry errors of ~1e-6 relative here;
    # a wrong block in the condensing moves the step by O(1)
    rel = 1e-4
    assert np.abs(du_c - du_s).max() < rel * max(1.0, np.abs(du_s).max())
    assert np.abs(q["G"] @ du_c + q["c"] - dx_s).max() < rel * max(1.0, np.abs(dx_s).max())
    # with the bounds: DAQP's solution equals the KKT solution with its active set as equalities
    du_d, flag, _, active = ctl.solve_qp(q)
    assert flag in (1, 2), flag
    nU = ctl.N * ctl.n
    lo = np.concatenate([q["box_lo"], q["row_lo"], q["v_lo"]])
    hi = np.concatenate([q["box_hi"], q["row_hi"], q["v_hi"]])
    act = [(i, hi[i] if active[i] > 0 else lo[i]) for i in np.flatnonzero(active)]
    # the rows' targets are on dx = G du + c and dv = Gv du + cv: move c, cv to the right-hand side
    offset = np.concatenate([np.zeros(nU), q["c"], q["cv"]])
    act = [(i, v + offset[i]) for i, v in act]
    assert act, "the perturbed point should make some bound active"
    du_a, _ = _sparse_kkt(ctl, x0, X, U, q, act)
    assert np.abs(du_d - du_a).max() < rel * max(1.0, np.abs(du_a).max())


@pytest.mark.parametrize("problem", ["lwr4", "panda"])
def test_mpc_sqp_short_run(tmp_path, problem):
    out = tmp_path / problem
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "mpc.py"), "--problem", problem, "--out", str(out),
                        "--steps", "3", "--solver", "sqp"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "mpc.json").read_text())
    assert len(doc["solve_ms"]) == 3 and len(doc["iterations"]) == 3
    for key in ("tracking_rms", "reference_rms", "violations", "solve_ms_median", "solve_cpu_ms_p95", "disturbance"):
        assert key in doc
    kinds = doc["violations_by_kind"]
    assert kinds["tau"] == 0 and kinds["q"] == 0 and kinds["failed_solves"] == 0
    assert all(s == "converged" for s in doc["status"])
    assert (out / "mpc.png").exists()


@pytest.mark.parametrize("args", [["--problem", "panda", "--solver", "stages"],
                                  ["--problem", "lwr4", "--solver", "sqp", "--payload", "-1"],
                                  ["--problem", "lwr4", "--solver", "sqp", "--substeps", "0"],
                                  ["--problem", "lwr4", "--solver", "sqp", "--speed-margin", "1.5"]])
def test_bad_sqp_arguments(args, tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "mpc.py"), *args, "--out", "x"], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:")
