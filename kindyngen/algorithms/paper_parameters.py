"""The identification paper's inertial parameters (mass, CoM, inertia about the CoM) against
the barycentric ones the regressors use (identification paper, Sect. V): for the paper
comparison only (:mod:`kindyngen.measured.paper_reproduction` and its tests).

The paper's parameters map to the barycentric ones by :func:`barycentric_in_paper`
(parallel-axis theorem) and back by :func:`paper_in_barycentric`.

Example:

>>> barycentric_in_paper(1)[4]
I1xx + m1*(c1y**2 + c1z**2)
"""
from __future__ import annotations

import sympy

from ..model.inertial_parameters import NAMES
from ..model.robot_model import RobotModel
from .regressors import base_parameters

def paper_symbols(n: int) -> tuple[sympy.Symbol, ...]:
    """The paper's parameters per link: ``m1, c1x, c1y, c1z, I1xx, I1yy, I1zz, I1xy, I1xz,
    I1yz`` (mass, CoM in link frame i, inertia about the CoM in link-frame axes)."""
    out = []
    for i in range(1, n + 1):
        out.append(sympy.Symbol(f"m{i}"))
        out += [sympy.Symbol(f"c{i}{a}") for a in "xyz"]
        out += [sympy.Symbol(f"I{i}{a}") for a in ("xx", "yy", "zz", "xy", "xz", "yz")]
    return tuple(out)


def barycentric_symbols(n: int) -> tuple[sympy.Symbol, ...]:
    """sympy twins of :func:`kindyngen.model.inertial_parameters.parameter_symbols`."""
    return tuple(sympy.Symbol(f"{name}{i + 1}") for i in range(n) for name in NAMES)


def barycentric_in_paper(n: int) -> tuple[sympy.Expr, ...]:
    """The 10 n barycentric parameters as expressions of the paper's (parallel-axis theorem):
    ``mx = m cx``, ``Ixx = I_xx + m (cy^2 + cz^2)``, ``Ixy = I_xy - m cx cy``, ..."""
    s = paper_symbols(n)
    out = []
    for i in range(n):
        m, cx, cy, cz, ixx, iyy, izz, ixy, ixz, iyz = s[10 * i:10 * i + 10]
        out += [m, m * cx, m * cy, m * cz,
                ixx + m * (cy ** 2 + cz ** 2), ixy - m * cx * cy, iyy + m * (cx ** 2 + cz ** 2),
                ixz - m * cx * cz, iyz - m * cy * cz, izz + m * (cx ** 2 + cy ** 2)]
    return tuple(out)


def paper_in_barycentric(n: int) -> tuple[sympy.Expr, ...]:
    """Inverse of :func:`barycentric_in_paper`: ``cx = mx / m``, ``I_xx = Ixx - (my^2 + mz^2)
    / m``, ``I_xy = Ixy + mx my / m``, ... (in :func:`paper_symbols` order)."""
    s = barycentric_symbols(n)
    out = []
    for i in range(n):
        m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = s[10 * i:10 * i + 10]
        out += [m, hx / m, hy / m, hz / m,
                ixx - (hy ** 2 + hz ** 2) / m, iyy - (hx ** 2 + hz ** 2) / m, izz - (hx ** 2 + hy ** 2) / m,
                ixy + hx * hy / m, ixz + hx * hz / m, iyz + hy * hz / m]
    return tuple(out)


def base_expressions_in_paper(model: RobotModel, kind: str) -> tuple[sympy.Expr, ...]:
    """The base parameters of ``kind`` as polynomials in the paper's parameters."""
    b = base_parameters(model, kind)
    subs = dict(zip(barycentric_symbols(model.n), barycentric_in_paper(model.n)))
    return tuple(sympy.expand(e.xreplace(subs)) for e in b.expressions(barycentric_symbols(model.n)))
