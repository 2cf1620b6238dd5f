"""The native stage library: the shooting intervals of a robot's optimal-control problems in
C (kindyngen/control/stage_library.c over the robot's generated fd, fd_derivatives and tau),
compiled per robot, horizon N, interval length h and integrator, cached by content.

What it serves:
- the reach NLP's constraints, their Jacobian and the exact Hessian of its Lagrangian as CasADi
  external functions (``kdg_nlp_g``, ``kdg_nlp_jac_g``, ``kdg_nlp_hess``) for IPOPT; the
  Hessian of each interval's integrator step comes from the inverse dynamics' Hessian
  (docs/control.md): the stage multipliers by back substitution through the mass matrices
  (M^-1 and the Jacobians from the analytic fd_derivatives), then sum_i dY_i' H_i dY_i;
- ``linearise`` (ctypes): every interval's end state, [A B] and the inner substep states with
  their Jacobians, for the tracking MPC; ``hessians``: every interval's Hessian of a weighted
  sum of its substep ends (the exact-Hessian SQP, kindyngen/control/reach_sqp.py); ``terminal``:
  the terminal rows with their Jacobian and Hessian; ``fd``, ``tau``, ``step`` for observers and
  rollouts.

Every entry point is re-entrant (no state between calls: each call computes its intervals'
forward chains on its own stack), so any number of libraries and solvers live in one process.

Building: the robot's part (its generated C and CasADi's C of four small helpers: the
Hessian of m' tau, the terminal rows, their Jacobian and Hessian) is compiled once per robot
into an object file; the part that depends on N, h and the integrator (a few kB of tables and
the stage code) is compiled and linked in about a second. Both are cached under
``<robot folder>/lib`` by the hash of their source and command.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .integrators import Integrator, stage_tables
from .robot import ControlError, ControlRobot

TEMPLATE = Path(__file__).resolve().parent / "stage_library.c"
# clang -O2: as fast as gcc -O2 on this code and quicker to compile (docs/optimal_control.md)
CFLAGS = ("-O2", "-std=c99", "-fPIC")


def compiler() -> str:
    cc = os.environ.get("CC")
    if cc:
        return cc
    for name in ("clang", "gcc", "cc"):
        if shutil.which(name):
            return name
    raise ControlError("no C compiler found (clang, gcc or cc; or set $CC): the native stage library needs one")


def _build(target: Path, source_text: str, command: list[str], suffix: str) -> Path:
    """Compile ``source_text`` with ``command + [-o out, src]`` into ``target`` unless it exists
    (atomic rename: a concurrent build of the same key finds a whole file)."""
    if target.is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        src = Path(tmp) / f"source{suffix}"
        src.write_text(source_text)
        out = Path(tmp) / target.name
        done = subprocess.run([*command, "-o", str(out), str(src)], capture_output=True, text=True)
        if done.returncode != 0:
            raise ControlError(f"compiling the native stage library failed: {' '.join(command)}\n{done.stderr[-2000:]}")
        os.replace(out, target)
    return target


def helper_functions(robot: ControlRobot):
    """The CasADi Functions compiled beside the robot's C: kdg_idh(y, m) the Hessian of m' tau(y)
    over y = (q, qd, qdd); kdg_term(x, goal) = (flange position - goal, qd); kdg_jterm its
    Jacobian in x; kdg_hterm(x, l) the Hessian of l' term."""
    import casadi as ca
    n = robot.n
    y, m = ca.SX.sym("y", 3 * n), ca.SX.sym("m", n)
    Hid = ca.hessian(ca.dot(m, robot.tau(y[:n], y[n:2 * n], y[2 * n:])), y)[0]
    # the stage code reads only the blocks qq, qv, qa, vv: tau is linear in qdd, without qd-qdd terms
    if Hid[2 * n:, n:].nnz() != 0:
        raise ControlError(f"{robot.name}: tau has qd-qdd or qdd-qdd second derivatives; the stage library assumes none")
    xN, goal, lamT = ca.SX.sym("xN", 2 * n), ca.SX.sym("goal", 3), ca.SX.sym("lamT", 3 + n)
    term = ca.vertcat(robot.fk_hom(xN[:n])[:3, 3] - goal, xN[n:])
    return [ca.Function("kdg_idh", [y, m], [ca.densify(Hid)]),
            ca.Function("kdg_term", [xN, goal], [ca.densify(term)]),
            ca.Function("kdg_jterm", [xN, goal], [ca.densify(ca.jacobian(term, xN))]),
            ca.Function("kdg_hterm", [xN, lamT], [ca.densify(ca.hessian(ca.dot(lamT, term), xN)[0])])]


@functools.lru_cache(maxsize=32)
def _robot_object(robot: ControlRobot, cc: str) -> tuple[Path, tuple[int, int, int, int]]:
    """The robot's generated C and the helpers, compiled once: (object file, helper work sizes)."""
    import casadi as ca
    helpers = helper_functions(robot)
    cg = ca.CodeGenerator("kdg_helpers.c", {"with_header": False})
    for f in helpers:
        cg.add(f)
    text = robot.c_source.read_text() + "\n" + cg.dump()
    sizes = (max(f.sz_arg() for f in helpers), max(f.sz_res() for f in helpers), max(f.sz_iw() for f in helpers) + 1,
             max(f.sz_w() for f in helpers) + 1)
    command = [cc, *CFLAGS, f"-I{robot.c_source.parent}", "-c"]
    key = hashlib.sha256((text + "\0".join(command)).encode()).hexdigest()[:16]
    return _build(robot.folder / "lib" / f"robot_{key}.o", text, command, ".c"), sizes


def _c_array(name: str, values, ctype: str = "double") -> str:
    vals = np.asarray(values)
    if ctype == "double":
        body = ", ".join(repr(float(v)) for v in vals.ravel())
    else:
        body = ", ".join(str(int(v)) for v in vals.ravel())
    dims = "".join(f"[{d}]" for d in vals.shape)
    return f"static const {ctype} {name}{dims} = {{{body}}};"


def _c_matrix(name: str, values) -> str:
    rows = ", ".join("{" + ", ".join(repr(float(v)) for v in row) + "}" for row in np.asarray(values))
    shape = np.asarray(values).shape
    return f"static const double {name}[{shape[0]}][{shape[1]}] = {{{rows}}};"


@dataclass(frozen=True)
class Layout:
    """The reach NLP's sizes and the CasADi sparsity patterns of its Jacobian and Hessian."""
    n: int
    N: int
    substeps: int
    inner: bool

    @property
    def nx(self):
        return 2 * self.n

    @property
    def nw(self):
        return 3 * self.n

    @property
    def nin(self):
        return self.nx * (self.substeps - 1) if self.inner else 0

    @property
    def nz(self):
        return self.N * self.nw + self.nx

    @property
    def sb(self):
        return self.nx + self.nin

    @property
    def ng(self):
        return self.N * self.sb + self.nx + 3 + self.n

    def row_gap(self, k: int) -> int:
        return k * self.sb + (self.nx if k > 0 else 0)

    def row_inner(self, k: int) -> int:
        return self.row_gap(k) + self.nx + (self.nx if k == 0 else 0)

    def jacobian_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(colind, row) of dg/dz, in the order the C writes the values."""
        colind, rows = [0], []
        nt = 3 + self.n
        for k in range(self.N):
            for col in range(self.nw):
                if col < self.nx and k >= 1:
                    rows.append(self.row_gap(k - 1) + col)
                rows.extend(self.row_gap(k) + r for r in range(self.nx))
                if col < self.nx and k == 0:
                    rows.append(self.nx + col)
                rows.extend(self.row_inner(k) + r for r in range(self.nin))
                colind.append(len(rows))
        for col in range(self.nx):
            rows.append(self.row_gap(self.N - 1) + col)
            rows.extend(self.ng - nt + r for r in range(nt))
            colind.append(len(rows))
        return np.array(colind), np.array(rows)

    def hessian_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        colind, rows = [0], []
        for k in range(self.N):
            for o in range(self.nw):
                rows.extend(k * self.nw + r for r in range(o + 1))
                colind.append(len(rows))
        base = self.N * self.nw
        for o in range(self.nx):
            rows.extend(base + r for r in range(o + 1))
            colind.append(len(rows))
        return np.array(colind), np.array(rows)

    def parameter_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """dg/dp: x_0 - x_init (-I), flange position - goal (-I)."""
        rows = list(range(self.nx, 2 * self.nx)) + [self.ng - 3 - self.n + r for r in range(3)]
        return np.arange(len(rows) + 1), np.array(rows)


def _sparsity(name: str, nrow: int, ncol: int, pattern) -> str:
    colind, rows = pattern
    return _c_array(name, np.concatenate([[nrow, ncol], colind, rows]), "casadi_int")


@dataclass(frozen=True)
class StageLibrary:
    """A compiled stage library (see the module docstring). ``inner``: the inner substep states
    are NLP rows (limits between the nodes)."""
    robot: ControlRobot
    N: int
    h: float
    integrator: Integrator
    inner: bool
    path: Path
    layout: Layout = field(repr=False)

    @functools.cached_property
    def _cdll(self):
        lib = ctypes.CDLL(str(self.path))
        dp = ctypes.POINTER(ctypes.c_double)
        lib.kdg_linearise.argtypes = [dp] * 8
        lib.kdg_linearise.restype = None
        for name in ("kdg_fd", "kdg_tau"):
            getattr(lib, name).argtypes = [dp] * 4
            getattr(lib, name).restype = None
        lib.kdg_step.argtypes = [dp] * 3
        lib.kdg_step.restype = None
        lib.kdg_hessians.argtypes = [dp] * 6
        lib.kdg_hessians.restype = None
        lib.kdg_terminal.argtypes = [dp] * 6
        lib.kdg_terminal.restype = None
        return lib

    @functools.cached_property
    def externals(self) -> dict:
        """{name: casadi external Function} of the reach NLP's functions."""
        import casadi as ca
        return {name: ca.external(name, str(self.path)) for name in ("kdg_nlp_g", "kdg_nlp_jac_g", "kdg_nlp_hess")}

    def linearise(self, x0, X, U, d=None):
        """F (N x 2n), A (N x 2n x 2n), B (N x 2n x n), XI (N x nin), AXI (N x nin x 3n): the
        intervals' ends from x_0 = x0, x_k = X[k-1] under U[k] + d, their Jacobians, the inner
        substep states and theirs (nin = 2n (substeps - 1) for a library built with inner
        rows, else 0)."""
        L = self.layout
        n, N, nx, nw, nin = L.n, L.N, L.nx, L.nw, L.nin
        x0 = np.ascontiguousarray(x0, float)
        X = np.ascontiguousarray(X, float)
        U = np.ascontiguousarray(U, float)
        d = np.zeros(n) if d is None else np.ascontiguousarray(d, float)
        F = np.empty((N, nx))
        AB = np.empty((N, nx, nw))
        XI = np.empty((N, max(nin, 1)))
        AXI = np.empty((N, max(nin, 1), nw))
        p = ctypes.POINTER(ctypes.c_double)
        self._cdll.kdg_linearise(*(a.ctypes.data_as(p) for a in (x0, X, U, d, F, AB, XI, AXI)))
        return F, AB[:, :, :nx], AB[:, :, nx:], XI[:, :nin], AXI[:, :nin]

    def hessians(self, x0, X, U, MU, d=None) -> np.ndarray:
        """H (N x 3n x 3n): per interval the Hessian over (x_k, u_k) of sum_o MU[k, o]' x_o, the
        substep ends x_o of the interval from x_k (x0, then X[k-1]) under U[k] + d, MU (N x substeps
        x 2n) their multipliers (the last: the interval's end)."""
        L = self.layout
        n, N, nw = L.n, L.N, L.nw
        MU = np.ascontiguousarray(np.broadcast_to(np.asarray(MU, float).reshape(N, -1, L.nx), (N, L.substeps, L.nx)))
        H = np.empty((N, nw, nw))
        d = np.zeros(n) if d is None else np.ascontiguousarray(d, float)
        p = ctypes.POINTER(ctypes.c_double)
        args = [np.ascontiguousarray(a, float) for a in (x0, X, U)] + [d, MU, H]
        self._cdll.kdg_hessians(*(a.ctypes.data_as(p) for a in args))
        return H

    def terminal(self, xN, goal, lt):
        """The terminal rows t = (flange position - goal, qd) at xN, their Jacobian (3 + n x 2n) and
        the Hessian (2n x 2n) of lt' t."""
        n = self.layout.n
        t, J, H = np.empty(3 + n), np.empty((3 + n, 2 * n)), np.empty((2 * n, 2 * n))
        p = ctypes.POINTER(ctypes.c_double)
        args = [np.ascontiguousarray(a, float) for a in (xN, goal, lt)] + [t, J, H]
        self._cdll.kdg_terminal(*(a.ctypes.data_as(p) for a in args))
        return t, J, H

    def step(self, x, u) -> np.ndarray:
        out = np.empty(2 * self.robot.n)
        p = ctypes.POINTER(ctypes.c_double)
        self._cdll.kdg_step(np.ascontiguousarray(x, float).ctypes.data_as(p),
                            np.ascontiguousarray(u, float).ctypes.data_as(p), out.ctypes.data_as(p))
        return out

    def _call4(self, name, a, b, c) -> np.ndarray:
        out = np.empty(self.robot.n)
        p = ctypes.POINTER(ctypes.c_double)
        getattr(self._cdll, name)(*(np.ascontiguousarray(v, float).ctypes.data_as(p) for v in (a, b, c)),
                                  out.ctypes.data_as(p))
        return out

    def fd(self, q, qd, tau) -> np.ndarray:
        return self._call4("kdg_fd", q, qd, tau)

    def tau(self, q, qd, qdd) -> np.ndarray:
        return self._call4("kdg_tau", q, qd, qdd)


@functools.lru_cache(maxsize=64)
def stage_library(robot: ControlRobot, N: int, h: float, integrator: Integrator = Integrator(),
                  inner: bool = False, progress=None) -> StageLibrary:
    """Compile (or load from the cache) the stage library of ``robot`` for N intervals of h
    seconds and ``integrator``; ``inner``: the states at the inner substep ends as NLP rows."""
    if N < 1:
        raise ControlError(f"N = {N}: at least one interval")
    if not h > 0:
        raise ControlError(f"h = {h}: the interval length must be positive")
    cc = compiler()
    if progress:
        progress(f"native stage library for {robot.name}, N = {N}, h = {h:g} s, {integrator.tag} (compiled once, cached)")
    obj, (szarg, szres, sziw, szw) = _robot_object(robot, cc)
    n = robot.n
    layout = Layout(n, N, integrator.substeps, inner and integrator.substeps > 1)
    t = stage_tables(integrator, h)
    ident = robot.name
    decl = "int {0}(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);"
    glue = "\n".join([
        "#define casadi_real double", "#define casadi_int long long int",
        '#define CASADI_SYMBOL_EXPORT __attribute__((visibility("default")))',
        *(decl.format(f) for f in ("kdg_idh", "kdg_term", "kdg_jterm", "kdg_hterm")),
        f"void {ident}_fd(const double *q, const double *qd, const double *tau, double *qdd);",
        f"void {ident}_fd_derivatives(const double *q, const double *qd, const double *tau, double *dq, double *dqd, "
        "double *Minv);",
        f"void {ident}_tau(const double *q, const double *qd, const double *qdd, double *tau);",
        f"#define NDOF {n}", f"#define NINT {N}", f"#define NSTAGE {integrator.stages}",
        f"#define NSUB {integrator.substeps}", f"#define NIN {layout.nin}", f"#define HSTEP {float(h)!r}",
        f"#define KDG_FD {ident}_fd", f"#define KDG_FDD {ident}_fd_derivatives", f"#define KDG_TAU {ident}_tau",
        f"#define KDG_SZARG {max(szarg, 2)}", f"#define KDG_SZRES {max(szres, 1)}",
        f"#define KDG_SZIW {sziw}", f"#define KDG_SZW {szw}",
        _c_array("kdg_gq", t["gq"]), _c_matrix("kdg_aq", t["aq"]), _c_matrix("kdg_bv", t["bv"]),
        _c_array("kdg_ogq", t["ogq"]), _c_matrix("kdg_oaq", t["oaq"]), _c_matrix("kdg_obv", t["obv"]),
        _sparsity("kdg_sp_jac", layout.ng, layout.nz, layout.jacobian_pattern()),
        _sparsity("kdg_sp_hess", layout.nz, layout.nz, layout.hessian_pattern()),
        _sparsity("kdg_sp_jp", layout.ng, layout.nx + 3, layout.parameter_pattern()),
        TEMPLATE.read_text(), ""])
    command = [cc, *CFLAGS, "-c"]
    key = hashlib.sha256((obj.name + glue + "\0".join(command)).encode()).hexdigest()[:16]
    glue_obj = _build(robot.folder / "lib" / f"stages_{key}.o", glue, command, ".c")
    so = robot.folder / "lib" / f"stages_{key}.so"
    if not so.is_file():
        with tempfile.TemporaryDirectory(dir=so.parent) as tmp:
            out = Path(tmp) / so.name
            done = subprocess.run([cc, "-shared", "-Wl,-Bsymbolic", "-o", str(out), str(obj), str(glue_obj), "-lm"],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                raise ControlError(f"linking the native stage library failed:\n{done.stderr[-2000:]}")
            os.replace(out, so)
    return StageLibrary(robot, N, float(h), integrator, layout.inner, so, layout)


TIME_TEMPLATE = Path(__file__).resolve().parent / "time_library.c"


@dataclass(frozen=True)
class TimeLayout:
    """The time-optimal NLP's sizes (kindyngen/control/time_optimal.py) and the CasADi sparsity
    patterns of its Jacobian and Hessian, in the order kindyngen/control/time_library.c writes
    them: V = (T, vec X, vec U); rows: the gaps of every interval, then the inner substep states.

    >>> L = TimeLayout(n=1, N=2, substeps=1)
    >>> L.nv, L.ng, L.jacobian_pattern()[0].tolist()
    (9, 4, [0, 4, 6, 8, 11, 14, 15, 16, 18, 20])
    """
    n: int
    N: int
    substeps: int

    @property
    def nx(self):
        return 2 * self.n

    @property
    def nin(self):
        return self.nx * (self.substeps - 1)

    @property
    def nv(self):
        return 1 + self.nx * (self.N + 1) + self.n * self.N

    @property
    def ng(self):
        return self.N * (self.nx + self.nin)

    def x_index(self, k: int) -> int:
        return 1 + self.nx * k

    def u_index(self, k: int) -> int:
        return 1 + self.nx * (self.N + 1) + self.n * k

    def interval_rows(self, k: int) -> list[int]:
        return [k * self.nx + r for r in range(self.nx)] + [self.N * self.nx + k * self.nin + r for r in range(self.nin)]

    def jacobian_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        colind, rows = [0], list(range(self.ng))          # the column of T: every row
        colind.append(len(rows))
        for k in range(self.N + 1):
            for col in range(self.nx):
                if k > 0:
                    rows.append((k - 1) * self.nx + col)
                if k < self.N:
                    rows.extend(self.interval_rows(k))
                colind.append(len(rows))
        for k in range(self.N):
            for col in range(self.n):
                rows.extend(self.interval_rows(k))
                colind.append(len(rows))
        return np.array(colind), np.array(rows)

    def hessian_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """Upper triangle: (T, T); x_k's columns: T and x_k's rows up to the diagonal; x_N's none;
        u_k's: T, all of x_k and u_k's up to the diagonal."""
        colind, rows = [0, 1], [0]
        for k in range(self.N + 1):
            for col in range(self.nx):
                if k < self.N:
                    rows.append(0)
                    rows.extend(self.x_index(k) + r for r in range(col + 1))
                colind.append(len(rows))
        for k in range(self.N):
            for col in range(self.n):
                rows.append(0)
                rows.extend(self.x_index(k) + r for r in range(self.nx))
                rows.extend(self.u_index(k) + r for r in range(col + 1))
                colind.append(len(rows))
        return np.array(colind), np.array(rows)


@dataclass(frozen=True)
class TimeLibrary:
    """A compiled time-optimal library: CasADi external functions topt_nlp_g(V, p),
    topt_nlp_jac_g(V, p), topt_nlp_hess(V, p, lam_f, lam_g)."""
    robot: ControlRobot
    N: int
    integrator: Integrator
    path: Path
    layout: TimeLayout = field(repr=False)

    @functools.cached_property
    def externals(self) -> dict:
        import casadi as ca
        return {name: ca.external(name, str(self.path)) for name in ("topt_nlp_g", "topt_nlp_jac_g", "topt_nlp_hess")}


@functools.lru_cache(maxsize=32)
def time_optimal_library(robot: ControlRobot, N: int, integrator: Integrator = Integrator("rk4", 4),
                         progress=None) -> TimeLibrary:
    """Compile (or load from the cache) the time-optimal NLP's library of ``robot`` for N
    intervals and ``integrator`` (the inner substep states are rows)."""
    if N < 1:
        raise ControlError(f"N = {N}: at least one interval")
    cc = compiler()
    if progress:
        progress(f"native time-optimal library for {robot.name}, N = {N}, {integrator.tag} (compiled once, cached)")
    obj, (szarg, szres, sziw, szw) = _robot_object(robot, cc)
    n = robot.n
    layout = TimeLayout(n, N, integrator.substeps)
    t = stage_tables(integrator, 1.0)
    ident = robot.name
    decl = "int {0}(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);"
    glue = "\n".join([
        "#define casadi_real double", "#define casadi_int long long int",
        '#define CASADI_SYMBOL_EXPORT __attribute__((visibility("default")))',
        decl.format("kdg_idh"),
        f"void {ident}_fd(const double *q, const double *qd, const double *tau, double *qdd);",
        f"void {ident}_fd_derivatives(const double *q, const double *qd, const double *tau, double *dq, double *dqd, "
        "double *Minv);",
        f"#define NDOF {n}", f"#define NINT {N}", f"#define NSTAGE {integrator.stages}",
        f"#define NSUB {integrator.substeps}", f"#define NIN {layout.nin}",
        f"#define KDG_FD {ident}_fd", f"#define KDG_FDD {ident}_fd_derivatives",
        f"#define KDG_SZARG {max(szarg, 2)}", f"#define KDG_SZRES {max(szres, 1)}",
        f"#define KDG_SZIW {sziw}", f"#define KDG_SZW {szw}",
        _c_array("kdg_gq", t["gq"]), _c_matrix("kdg_aq", t["aq"]), _c_matrix("kdg_bv", t["bv"]),
        _c_array("kdg_ogq", t["ogq"]), _c_matrix("kdg_oaq", t["oaq"]), _c_matrix("kdg_obv", t["obv"]),
        _sparsity("kdg_sp_jac", layout.ng, layout.nv, layout.jacobian_pattern()),
        _sparsity("kdg_sp_hess", layout.nv, layout.nv, layout.hessian_pattern()),
        _sparsity("kdg_sp_jp", layout.ng, n, (np.zeros(n + 1, int), np.zeros(0, int))),
        TIME_TEMPLATE.read_text(), ""])
    command = [cc, *CFLAGS, "-c"]
    key = hashlib.sha256((obj.name + glue + "\0".join(command)).encode()).hexdigest()[:16]
    glue_obj = _build(robot.folder / "lib" / f"time_{key}.o", glue, command, ".c")
    so = robot.folder / "lib" / f"time_{key}.so"
    if not so.is_file():
        with tempfile.TemporaryDirectory(dir=so.parent) as tmp:
            out = Path(tmp) / so.name
            done = subprocess.run([cc, "-shared", "-Wl,-Bsymbolic", "-o", str(out), str(obj), str(glue_obj), "-lm"],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                raise ControlError(f"linking the native time-optimal library failed:\n{done.stderr[-2000:]}")
            os.replace(out, so)
    return TimeLibrary(robot, N, integrator, so, layout)
