"""Explicit Runge-Kutta integrators of xdot = (qd, fd(q, qd, u)) over one shooting interval,
torque held: the step as CasADi expressions, and the step's linear structure as tables for the
native stage library.

With the stage accelerations a_i taken as unknowns, every stage state (q_i, v_i) and every
substep end is *linear* in (q, v, a_0..a_{S-1}) with scalar coefficients (the same for every
joint): q_i = q + gq_i v + sum_j aq_ij a_j, v_i = v + sum_j bv_ij a_j. The native library
(:mod:`kindyngen.control.native`) chains the sensitivities and back-substitutes the stage
multipliers through these tables, for any tableau and number of substeps.

>>> t = stage_tables(Integrator("rk4", 1), 0.1)
>>> round(float(t["ogq"][-1]), 12), [round(float(c), 12) for c in t["oaq"][-1]]   # q + h v + h^2/6 (a0 + a1 + a2)
(0.1, [0.001666666667, 0.001666666667, 0.001666666667, 0.0])
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction as Fr

import numpy as np

#: Butcher tableaux (A strictly lower triangular, b) of the explicit methods offered
TABLEAUX = {
    "euler": ([[0]], [1]),
    "midpoint": ([[0, 0], [Fr(1, 2), 0]], [0, 1]),
    "rk4": ([[0, 0, 0, 0], [Fr(1, 2), 0, 0, 0], [0, Fr(1, 2), 0, 0], [0, 0, 1, 0]],
            [Fr(1, 6), Fr(1, 3), Fr(1, 3), Fr(1, 6)]),
}


@dataclass(frozen=True)
class Integrator:
    """``method`` (one of TABLEAUX) applied ``substeps`` times per shooting interval."""
    method: str = "rk4"
    substeps: int = 1

    def __post_init__(self):
        if self.method not in TABLEAUX:
            raise ValueError(f"integrator {self.method!r}: one of {', '.join(TABLEAUX)}")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ValueError(f"integrator substeps {self.substeps!r}: a positive integer")

    @property
    def stages(self) -> int:
        """Evaluations of fd per interval."""
        return len(TABLEAUX[self.method][1]) * self.substeps

    @property
    def tag(self) -> str:
        return f"{self.method}x{self.substeps}"

    def step(self, fd, n: int, h: float, x, u):
        """The interval's end state and the states at the ends of the inner substeps (a list of
        substeps - 1), as expressions of x = (q, qd) and u (CasADi or numpy arrays)."""
        A, b = TABLEAUX[self.method]
        hs = h / self.substeps
        inner = []
        for m in range(self.substeps):
            if m:
                inner.append(x)
            k = []
            for i in range(len(b)):
                z = x
                for j in range(i):
                    if A[i][j]:
                        z = z + hs * float(A[i][j]) * k[j]
                k.append(_vertcat(z[n:], fd(z[:n], z[n:], u)))
            x = x + hs * sum(float(b[i]) * k[i] for i in range(len(b)) if b[i])
        return x, inner


def _vertcat(a, b):
    try:
        import casadi as ca
        if isinstance(a, (ca.SX, ca.MX, ca.DM)) or isinstance(b, (ca.SX, ca.MX, ca.DM)):
            return ca.vertcat(a, b)
    except ImportError:           # pragma: no cover - casadi is a dependency
        pass
    return np.concatenate([np.ravel(a), np.ravel(b)])


def stage_tables(integrator: Integrator, h: float) -> dict:
    """Coefficients of the stage states and substep ends in (q, v, a_0..a_{S-1}), exact fractions
    of powers of h rounded once to doubles: gq[S], aq[S, S], bv[S, S] for the stages and ogq[M],
    oaq[M, S], obv[M, S] for the ends of substeps 1..M (the last one the interval's end)."""
    A, b = TABLEAUX[integrator.method]
    s, M = len(b), integrator.substeps
    S = s * M
    hs = Fr(1, M)          # in units of h; powers of h applied at the end

    # a linear form: (coefficient of v [power 1 of h], coefficients of a [power 2 for q, 1 for v])
    def zero():
        return [Fr(0), [Fr(0)] * S]
    gq, aq, bv = [], [], []
    oq, ov = [], []
    qm, vm = zero(), [Fr(0), [Fr(0)] * S]        # q_m - q, v_m - v (substep start)
    for m in range(M):
        vs = []                                   # stage speeds (coefficient of v is 1)
        for i in range(s):
            vi = [Fr(0), list(vm[1])]
            qi = [qm[0], list(qm[1])]
            for j in range(i):
                if A[i][j]:
                    c = hs * A[i][j]
                    vi[1][m * s + j] += c
                    qi[0] += c                     # v_j has v with coefficient 1
                    qi[1] = [x + c * y for x, y in zip(qi[1], vs[j][1])]
            vs.append(vi)
            gq.append(qi[0])
            aq.append(qi[1])
            bv.append(vi[1])
        nq = [qm[0], list(qm[1])]
        nv = [Fr(0), list(vm[1])]
        for i in range(s):
            if b[i]:
                c = hs * b[i]
                nq[0] += c
                nq[1] = [x + c * y for x, y in zip(nq[1], vs[i][1])]
                nv[1][m * s + i] += c
        qm, vm = nq, nv
        oq.append(qm)
        ov.append(vm)
    h = float(h)
    return {"gq": np.array([float(g) * h for g in gq]),
            "aq": np.array([[float(c) * h * h for c in row] for row in aq]),
            "bv": np.array([[float(c) * h for c in row] for row in bv]),
            "ogq": np.array([float(o[0]) * h for o in oq]),
            "oaq": np.array([[float(c) * h * h for c in o[1]] for o in oq]),
            "obv": np.array([[float(c) * h for c in o[1]] for o in ov])}
