"""Which functions are generated for a robot: one entry per derivation, in output order.

Each builder takes the robot model and the inertial-parameter mode ("numeric": the YAML
values baked in; "symbolic": an extra input ``p`` of 10 n barycentric parameters) and returns
a SymbolicFunction, or None where the derivation does not apply to that arm.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable, Optional

import symengine as se

from .dynamics_derivatives import fd_derivatives, tau_derivatives
from .dynamics_dualquat import coriolis_dq, gravity_dq, inverse_dynamics_dq, mass_matrix_dq, regressor_dq
from .dynamics_lagrange import coriolis_christoffel, coriolis_matrix, gravity_lagrange, mass_matrix_lagrange
from .dynamics_newton_euler import coriolis_rnea, gravity_rnea, inverse_dynamics, mass_matrix_crba
from .forward_dynamics import forward_dynamics
from .ik_lwr_dualquat import ik_dq
from .ik_lwr_homogeneous import ik_hom
from .kinematics_dualquat import fk_dq, jacobian_dq, pose_jacobian_dq
from .kinematics_homogeneous import fk_hom, jacobian
from .regressors import base_params_document as arm_base_params_document, regressor
from .regressors import undecided_notes as arm_undecided_notes
from .robot import RobotModel
from .symbolic import Port, SymbolicFunction
from .tree_dynamics import (centre_of_mass_tree, coriolis_tree, forward_dynamics_tree, gravity_tree,
                            inverse_dynamics_tree, mass_matrix_tree)
from .tree_articulated import forward_dynamics_aba
from .tree_kinematics import fk_hom_tree, jacobian_tree
from .tree_derivatives import fd_derivatives_tree, tau_derivatives_tree
from .tree_model import TreeModel
from .tree_regressors import tree_base_params_document, tree_regressor, unavailable as tree_regressor_unavailable

Builder = Callable[[RobotModel, str], Optional[SymbolicFunction]]

BUILDERS: tuple[tuple[str, Builder], ...] = (
    ("fk_hom", lambda model, params: fk_hom(model)),
    ("fk_dq", lambda model, params: fk_dq(model)),
    ("jacobian", lambda model, params: jacobian(model)),
    ("pose_jacobian_dq", lambda model, params: pose_jacobian_dq(model)),
    ("jacobian_dq", lambda model, params: jacobian_dq(model)),
    # dynamics: public names by the route with fewer operations after CSE (numeric LWR),
    # the other route under a suffixed name (kindyngen/dynamics_*.py, forward_dynamics.py)
    ("M", lambda model, params: mass_matrix_crba(model, params, "M")),
    ("g", lambda model, params: gravity_rnea(model, params, "g")),
    ("c", lambda model, params: coriolis_rnea(model, params, "c")),
    ("S", lambda model, params: coriolis_matrix(model, params, "S")),
    ("tau", lambda model, params: inverse_dynamics(model, params, "tau")),
    ("fd", lambda model, params: forward_dynamics(model, params, "fd")),
    # their partial derivatives, for optimal control (kindyngen/dynamics_derivatives.py)
    ("tau_derivatives", lambda model, params: tau_derivatives(model, params, "tau_derivatives")),
    ("fd_derivatives", lambda model, params: fd_derivatives(model, params, "fd_derivatives")),
    ("M_lagrange", lambda model, params: mass_matrix_lagrange(model, params, "M_lagrange")),
    ("g_lagrange", lambda model, params: gravity_lagrange(model, params, "g_lagrange")),
    ("c_christoffel", lambda model, params: coriolis_christoffel(model, params, "c_christoffel")),
    # the same dynamics in dual-quaternion form (kindyngen/dynamics_dualquat.py); Y_dq: the
    # regressor of tau_dq on Y's base parameters, the same function in both params modes
    ("M_dq", lambda model, params: mass_matrix_dq(model, params, "M_dq")),
    ("g_dq", lambda model, params: gravity_dq(model, params, "g_dq")),
    ("c_dq", lambda model, params: coriolis_dq(model, params, "c_dq")),
    ("tau_dq", lambda model, params: inverse_dynamics_dq(model, params, "tau_dq")),
    ("Y_dq", lambda model, params: regressor_dq(model, "Y_dq")),
    # closed-form IK of LWR-like arms (None for other arms): kindyngen/ik_lwr_*.py
    ("ik_hom", lambda model, params: ik_hom(model)),
    ("ik_dq", lambda model, params: ik_dq(model)),
    # regressors on base parameters (kindyngen/regressors.py): same functions in both params modes
    ("Y_g", lambda model, params: regressor(model, "Y_g")),
    ("Y_m", lambda model, params: regressor(model, "Y_m")),
    ("Y", lambda model, params: regressor(model, "Y")),
)


def forward_dynamics_routes(model: TreeModel) -> SymbolicFunction:
    """fd of a tree by the sparse L^T D L route, with the articulated-body route as its
    alternative: optimisation keeps whichever has fewer operations after CSE on this tree."""
    return replace(forward_dynamics_tree(model), alternatives=(forward_dynamics_aba(model),))


# the functions of a kinematic tree (kindyngen/tree_*.py): numeric parameters only
TREE_BUILDERS: tuple[tuple[str, Callable[[TreeModel], SymbolicFunction]], ...] = (
    ("fk_hom", fk_hom_tree),
    ("jacobian", jacobian_tree),
    ("M", mass_matrix_tree),
    ("g", gravity_tree),
    ("c", coriolis_tree),
    ("tau", inverse_dynamics_tree),
    ("fd", forward_dynamics_routes),
    # partial derivatives in the world-frame formulation (kindyngen/tree_derivatives.py)
    ("tau_derivatives", tau_derivatives_tree),
    ("fd_derivatives", fd_derivatives_tree),
    # the same without Minv, for callers that do not need it (each column through the factor)
    ("fd_derivatives_no_minv", lambda model: fd_derivatives_tree(model, "fd_derivatives_no_minv", with_minv=False)),
    ("com", centre_of_mass_tree),
    ("Y", tree_regressor),          # None where the base parameters cannot be decided
)

NAMES: tuple[str, ...] = tuple(name for name, _ in BUILDERS)
TREE_NAMES: tuple[str, ...] = tuple(name for name, _ in TREE_BUILDERS)


def derive_all(model: RobotModel | TreeModel, params: str = "numeric", only=None) -> list[SymbolicFunction]:
    """All applicable functions for ``model`` (optionally only the named ones)."""
    if isinstance(model, TreeModel):
        if params != "numeric":
            raise ValueError("a kinematic tree is generated with its description's parameters only "
                             "(--params numeric)")
        found = (build(model) for name, build in TREE_BUILDERS if only is None or name in only)
        return [function for function in found if function is not None]
    out = []
    for name, build in BUILDERS:
        if only is not None and name not in only:
            continue
        function = build(model, params)
        if function is not None:
            out.append(with_lengths_port(function, model))
    return out


def base_params_document(model: RobotModel | TreeModel) -> dict | None:
    """Content of ``base_params.json`` for either kind of model (None for an arm with symbolic
    lengths)."""
    return tree_base_params_document(model) if isinstance(model, TreeModel) else arm_base_params_document(model)


def undecided_notes(model: RobotModel | TreeModel, only=None) -> list[str]:
    """One line per regressor (of ``only``, default all) left out because its base parameters
    could not be decided."""
    if not isinstance(model, TreeModel):
        return arm_undecided_notes(model, only)
    reason = tree_regressor_unavailable(model) if only is None or "Y" in only else None
    return [f"{model.identifier}: regressor Y not generated: {reason}"] if reason else []


def with_lengths_port(function: SymbolicFunction, model: RobotModel) -> SymbolicFunction:
    """Give a function of a robot with symbolic DH lengths the extra last input ``lengths``
    (all of the robot's length symbols, in order of appearance), so every function of that
    robot has the same signature whether or not a particular length reaches it."""
    symbols = tuple(se.Symbol(str(s)) for s in model.length_symbols)
    if not symbols:
        return function
    port = Port("lengths", (len(symbols),), "symbolic DH lengths: " + ", ".join(map(str, symbols)), "m")
    return replace(function, inputs=function.inputs + (port,), input_symbols=function.input_symbols + (symbols,))
