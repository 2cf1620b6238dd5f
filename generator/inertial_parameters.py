"""Inertial parameters of the links, numeric (from the YAML) or symbolic (for identification
and run-time payloads), in the standard barycentric form that dynamics is linear in.

Per link, 10 numbers in Pinocchio's order (so regressors compare column by column):
``m, m*cx, m*cy, m*cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz`` with the inertia taken about the link
frame origin (not the CoM), in link-frame axes.  The YAML (and the identification paper)
gives the CoM and the inertia about the CoM; :func:`barycentric` maps one to the other
(parallel-axis theorem), :func:`from_barycentric` back.

Example:

>>> from generator.robot import Link
>>> p = barycentric(Link(mass=2.0, com=(0.0, 0.0, 0.5), inertia=(1, 1, 1, 0, 0, 0)))
>>> [round(float(v), 6) for v in p]
[2.0, 0.0, 0.0, 1.0, 1.5, 0.0, 1.5, 0.0, 0.0, 1.0]
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import symengine as se

from .robot import Link, RobotModel

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


def barycentric(link: Link) -> np.ndarray:
    """The 10 barycentric numbers of a YAML link (inertia moved from the CoM to the origin)."""
    m, c = link.mass, np.array(link.com)
    I = link.inertia_matrix() + m * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]])


def from_barycentric(p) -> Link:
    """Inverse of :func:`barycentric` (mass must be non-zero)."""
    m = float(p[0])
    c = np.array(p[1:4], float) / m
    I = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]], float)
    Ic = I - m * (c @ c * np.eye(3) - np.outer(c, c))
    return Link(mass=m, com=tuple(c), inertia=(Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]))


def numeric_inertials(model: RobotModel) -> tuple[LinkInertials, ...]:
    """Each link's YAML parameters as numeric LinkInertials."""
    out = []
    for link in model.links:
        v = [se.RealDouble(float(x)) for x in barycentric(link)]
        out.append(LinkInertials(mass=v[0], first_moment=tuple(v[1:4]), inertia=tuple(v[4:10])))
    return tuple(out)


def parameter_symbols(n: int) -> tuple[se.Symbol, ...]:
    """The 10 n barycentric symbols, link by link in :data:`NAMES` order (``m1, mx1, ...``)."""
    return tuple(se.Symbol(f"{name}{i + 1}") for i in range(n) for name in NAMES)


def symbolic_inertials(n: int, symbols=None) -> tuple[LinkInertials, ...]:
    """LinkInertials whose entries are the given (or fresh barycentric) symbols."""
    s = tuple(symbols) if symbols is not None else parameter_symbols(n)
    return tuple(LinkInertials(mass=s[10 * i], first_moment=tuple(s[10 * i + 1:10 * i + 4]),
                               inertia=tuple(s[10 * i + 4:10 * i + 10])) for i in range(n))


def parameter_vector(model: RobotModel) -> np.ndarray:
    """All links' barycentric numbers stacked (10 n), the values for symbolic mode."""
    return np.concatenate([barycentric(link) for link in model.links])
