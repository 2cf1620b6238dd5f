"""Which functions are generated for a robot: one entry per derivation, in output order.

Each builder takes the robot model and the inertial-parameter mode ("numeric": the YAML
values baked in; "symbolic": an extra input ``p`` of 10 n barycentric parameters) and returns
a SymbolicFunction, or None where the derivation does not apply to that arm.
"""
from __future__ import annotations

from typing import Callable, Optional

from .kinematics_dualquat import fk_dq
from .kinematics_homogeneous import fk_hom, jacobian
from .robot import RobotModel
from .symbolic import SymbolicFunction

Builder = Callable[[RobotModel, str], Optional[SymbolicFunction]]

BUILDERS: tuple[tuple[str, Builder], ...] = (
    ("fk_hom", lambda model, params: fk_hom(model)),
    ("fk_dq", lambda model, params: fk_dq(model)),
    ("jacobian", lambda model, params: jacobian(model)),
    # further derivations (dynamics, regressors, IK) register here
)


def derive_all(model: RobotModel, params: str = "numeric", only=None) -> list[SymbolicFunction]:
    """All applicable functions for ``model`` (optionally only the named ones)."""
    out = []
    for name, build in BUILDERS:
        if only is not None and name not in only:
            continue
        function = build(model, params)
        if function is not None:
            out.append(function)
    return out
