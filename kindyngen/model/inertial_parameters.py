"""Inertial parameters of the links, numeric (from the YAML) or symbolic (for identification
and run-time payloads), in the standard barycentric form that dynamics is linear in.

Per link, 10 numbers in Pinocchio's order (so regressors compare column by column):
``m, m*cx, m*cy, m*cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz`` with the inertia taken about the link
frame origin (not the CoM), in link-frame axes.  The YAML (and the identification paper)
gives the CoM and the inertia about the CoM; :func:`barycentric` maps one to the other
(parallel-axis theorem).

The numbers are computed exactly (sympy rationals from the description's decimals): they
are baked into generated code, which must not depend on the processor's rounding.

Example:

>>> from sympy import Rational as R
>>> from kindyngen.model.robot_model import Link
>>> barycentric(Link(mass=R(2), com=(R(0), R(0), R(1, 2)), inertia=(R(1), R(1), R(1), 0, 0, 0)))
(2, 0, 0, 1, 3/2, 0, 3/2, 0, 0, 1)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import symengine as se
import sympy

from .robot_model import Link, RobotModel

NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


@dataclass(frozen=True)
class LinkInertials:
    """One link's parameters as symengine expressions (numbers or symbols)."""

    mass: se.Basic
    first_moment: tuple[se.Basic, se.Basic, se.Basic]          # m * c
    inertia: tuple[se.Basic, se.Basic, se.Basic, se.Basic, se.Basic, se.Basic]  # Ixx Ixy Iyy Ixz Iyz Izz about origin

    def inertia_matrix(self) -> se.Matrix:
        ixx, ixy, iyy, ixz, iyz, izz = self.inertia
        return se.Matrix([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])

    def as_vector(self) -> tuple[se.Basic, ...]:
        return (self.mass,) + tuple(self.first_moment) + tuple(self.inertia)


def barycentric(link: Link) -> tuple[sympy.Rational, ...]:
    """The 10 barycentric numbers of a YAML link (inertia moved from the CoM to the origin
    by the parallel-axis theorem), exact."""
    m = sympy.Rational(link.mass)
    c = sympy.Matrix(link.com)
    ixx, iyy, izz, ixy, ixz, iyz = link.inertia
    I = sympy.Matrix([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]) + m * ((c.T * c)[0] * sympy.eye(3) - c * c.T)
    return (m, m * c[0], m * c[1], m * c[2], I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2])


def numeric_inertials(model: RobotModel) -> tuple[LinkInertials, ...]:
    """Each link's YAML parameters (the payload merged into the last link) as numeric
    LinkInertials."""
    p = exact_parameter_vector(model)
    out = []
    for i in range(model.n):
        v = [se.sympify(x) for x in p[10 * i:10 * i + 10]]
        out.append(LinkInertials(mass=v[0], first_moment=tuple(v[1:4]), inertia=tuple(v[4:10])))
    return tuple(out)


def parameter_symbols(n: int, first: int = 1) -> tuple[se.Symbol, ...]:
    """The 10 n barycentric symbols, link by link in :data:`NAMES` order (``m1, mx1, ...``);
    ``first=0``: body 0 (a floating base's root) first, then the n links (10 (n + 1))."""
    return tuple(se.Symbol(f"{name}{i}") for i in range(first, n + 1) for name in NAMES)


def symbolic_inertials(n: int, symbols=None) -> tuple[LinkInertials, ...]:
    """LinkInertials whose entries are the given (or fresh barycentric) symbols."""
    s = tuple(symbols) if symbols is not None else parameter_symbols(n)
    return tuple(LinkInertials(mass=s[10 * i], first_moment=tuple(s[10 * i + 1:10 * i + 4]),
                               inertia=tuple(s[10 * i + 4:10 * i + 10])) for i in range(n))


def exact_parameter_vector(model: RobotModel) -> tuple[sympy.Rational, ...]:
    """All links' barycentric numbers stacked (10 n), exact.  A payload (a rigid body fixed to
    the flange, given in the flange frame, which is the last link's frame) is part of the last
    link: barycentric parameters of bodies in one frame add."""
    values = [v for link in model.links for v in barycentric(link)]
    if model.payload is not None:
        for k, v in enumerate(barycentric(model.payload)):
            values[10 * (model.n - 1) + k] += v
    return tuple(values)


def parameter_vector(model: RobotModel) -> np.ndarray:
    """All links' barycentric numbers stacked (10 n; the payload merged into the last link;
    a floating base's root body first) as floats: the values of the input ``p`` that
    reproduce the numeric build in symbolic mode."""
    root = barycentric(model.root) if model.floating_base else ()
    return np.array([float(v) for v in root + exact_parameter_vector(model)])
