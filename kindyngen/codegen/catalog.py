"""Which functions are generated for a robot: one entry per derivation, in output order.

Each builder takes the robot model and the inertial-parameter mode ("numeric": the
description's values baked in; "symbolic": an extra input ``p`` of 10 barycentric parameters
per body, a floating base's root body first) and returns a SymbolicFunction, or None where
the derivation does not apply to that robot. Builders marked :func:`per_scalar` also take the
C scalar type the code is for (the closed-form IK's tolerances differ between double and
float).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable, Optional

import symengine as se

from ..algorithms.derivatives_sweeps import fd_derivatives, tau_derivatives
from ..algorithms.dualquat.dq_dynamics import coriolis_dq, gravity_dq, inverse_dynamics_dq, mass_matrix_dq, regressor_dq
from ..algorithms.lagrange import coriolis_christoffel, coriolis_matrix, gravity_lagrange, mass_matrix_lagrange
from ..ik.lwr_dualquat import ik_dq
from ..ik.lwr_homogeneous import ik_hom
from ..algorithms.dualquat.dq_kinematics import fk_dq, jacobian_dq, pose_jacobian_dq
from ..model.robot_model import RobotModel
from ..algorithms.regressors import regressor
from ..algorithms.symbolic import Port, SymbolicFunction
from ..algorithms.articulated_body import forward_dynamics_aba
from ..algorithms.dynamics import (centre_of_mass_tree, coriolis_tree, forward_dynamics_tree, gravity_tree,
                                   inverse_dynamics_tree, mass_matrix_tree)
from ..algorithms.kinematics import fk_hom_tree, jacobian_tree
from ..algorithms.derivatives_world_frame import fd_derivatives_tree, tau_derivatives_tree
from ..algorithms import reduced_functions as reduced
from ..algorithms import loop_functions as loops
from ..algorithms.loop_closure import coupled_model, loop_system

Builder = Callable[[RobotModel, str], Optional[SymbolicFunction]]


def forward_dynamics_routes(model: RobotModel, params: str = "numeric", name: str = "fd") -> SymbolicFunction:
    """fd by the sparse L^T D L route, with the articulated-body route as its alternative:
    optimisation keeps whichever has fewer operations after CSE on this robot."""
    return replace(forward_dynamics_tree(model, params, name), alternatives=(forward_dynamics_aba(model, params, name),))


def chain_only(build: Builder) -> Builder:
    """A derivation written for serial chains (the Lagrange and dual-quaternion dynamics, the
    gravity and inertia regressors): None unless the model is one (fixed base, each joint's
    parent the joint before it: :attr:`RobotModel.is_chain`), however it was read."""
    def chain_build(model, params):
        return build(model, params) if model.is_chain else None
    chain_build.chain_only = True
    return chain_build


def flange_only(build: Builder) -> Builder:
    """A derivation of a chain's flange (dual-quaternion kinematics, closed-form IK), built on
    :attr:`RobotModel.flange_chain` (a chain read as a tree: its one frame of interest on the
    last link as the flange); None where there is no such flange."""
    def flange_build(model, params, *scalar):
        arm = model.flange_chain
        return build(arm, params, *scalar) if arm is not None else None
    flange_build.chain_only = True
    flange_build.per_scalar = getattr(build, "per_scalar", False)
    return flange_build


def per_scalar(build: Callable[[RobotModel, str, str], Optional[SymbolicFunction]]) -> Builder:
    """A derivation whose expressions depend on the C scalar type (render.SCALARS) it is
    printed in: called as ``build(model, params, scalar)``. Only the closed-form IK: its
    singular sets are decided by tolerances, which must lie above what the type resolves
    (kindyngen/ik/lwr_common.py, TOLERANCES); everything else is the same in both."""
    build.per_scalar = True
    return build


# every robot's functions, in output order; one builder per function, each written over the
# tree (an arm is the tree whose parent of joint j is j - 1) or marked chain_only / flange_only
# (by the model's structure, never by how the file was read)
BUILDERS: tuple[tuple[str, Builder], ...] = (
    ("fk_hom", lambda model, params: fk_hom_tree(model)),
    ("fk_dq", flange_only(lambda model, params: fk_dq(model))),
    ("jacobian", lambda model, params: jacobian_tree(model)),
    ("pose_jacobian_dq", flange_only(lambda model, params: pose_jacobian_dq(model))),
    ("jacobian_dq", flange_only(lambda model, params: jacobian_dq(model))),
    # dynamics: public names by the route with fewer operations after CSE (numeric LWR),
    # the other route under a suffixed name (kindyngen/algorithms/)
    ("M", lambda model, params: mass_matrix_tree(model, params, "M")),
    ("g", lambda model, params: gravity_tree(model, params, "g")),
    ("c", lambda model, params: coriolis_tree(model, params, "c")),
    ("S", chain_only(lambda model, params: coriolis_matrix(model, params, "S"))),
    ("tau", lambda model, params: inverse_dynamics_tree(model, params, "tau")),
    ("fd", lambda model, params: forward_dynamics_routes(model, params, "fd")),
    ("com", lambda model, params: centre_of_mass_tree(model, params, "com")),
    # their partial derivatives, for optimal control: on a chain by the adjoint sweeps over the
    # Newton-Euler pass (kindyngen/algorithms/derivatives_sweeps.py; they carry the joint effects),
    # on a branched tree or a floating base by the world-frame formulation
    # (algorithms/derivatives_world_frame.py; on lwr4 and panda it costs 7-9 % more operations
    # than the sweeps, with a shorter critical path: docs/latency.md)
    ("tau_derivatives", lambda model, params: tau_derivatives(model, params, "tau_derivatives") if model.is_chain
     else tau_derivatives_tree(model, "tau_derivatives", params)),
    ("fd_derivatives", lambda model, params: fd_derivatives(model, params, "fd_derivatives") if model.is_chain
     else fd_derivatives_tree(model, "fd_derivatives", params=params)),
    # the same without Minv, for callers that do not need it, by the same routes (on lwr4 the
    # sweeps without Minv cost fewer operations than the world frame's and carry the effects)
    ("fd_derivatives_no_minv", lambda model, params: fd_derivatives(
        model, params, "fd_derivatives_no_minv", with_minv=False) if model.is_chain
     else fd_derivatives_tree(model, "fd_derivatives_no_minv", with_minv=False, params=params)),
    ("M_lagrange", chain_only(lambda model, params: mass_matrix_lagrange(model, params, "M_lagrange"))),
    ("g_lagrange", chain_only(lambda model, params: gravity_lagrange(model, params, "g_lagrange"))),
    ("c_christoffel", chain_only(lambda model, params: coriolis_christoffel(model, params, "c_christoffel"))),
    # the same dynamics in dual-quaternion form (kindyngen/algorithms/dualquat/dq_dynamics.py); Y_dq: the
    # regressor of tau_dq on Y's base parameters, the same function in both params modes
    ("M_dq", chain_only(lambda model, params: mass_matrix_dq(model, params, "M_dq"))),
    ("g_dq", chain_only(lambda model, params: gravity_dq(model, params, "g_dq"))),
    ("c_dq", chain_only(lambda model, params: coriolis_dq(model, params, "c_dq"))),
    ("tau_dq", chain_only(lambda model, params: inverse_dynamics_dq(model, params, "tau_dq"))),
    ("Y_dq", chain_only(lambda model, params: regressor_dq(model, "Y_dq"))),
    # closed-form IK of LWR-like arms (None for other arms): kindyngen/ik/lwr_*.py
    ("ik_hom", flange_only(per_scalar(lambda model, params, scalar: ik_hom(model, scalar)))),
    ("ik_dq", flange_only(per_scalar(lambda model, params, scalar: ik_dq(model, scalar)))),
    # regressors on base parameters (kindyngen/algorithms/regressors.py): the same functions in both
    # params modes; Y_g and Y_m differentiate the Lagrange route, which is written for chains
    ("Y_g", chain_only(lambda model, params: regressor(model, "Y_g"))),
    ("Y_m", chain_only(lambda model, params: regressor(model, "Y_m"))),
    ("Y", lambda model, params: regressor(model, "Y")),
)

# a model with mimic joints: these functions, in its independent coordinates
# (kindyngen/algorithms/reduced_functions.py); the others (routes written for independent
# chains, closed-form IK) are not generated for it, with a note (MIMIC_NOTE)
MIMIC_BUILDERS: dict[str, Builder] = {
    "fk_hom": lambda model, params: reduced.fk_hom_reduced(model),
    "jacobian": lambda model, params: reduced.jacobian_reduced(model),
    "M": reduced.mass_matrix_reduced,
    "g": reduced.gravity_reduced,
    "c": reduced.coriolis_reduced,
    "tau": reduced.inverse_dynamics_reduced,
    "fd": reduced.forward_dynamics_reduced,
    "com": reduced.centre_of_mass_reduced,
    "tau_derivatives": reduced.tau_derivatives_reduced,
    "fd_derivatives": reduced.fd_derivatives_reduced,
    "fd_derivatives_no_minv": lambda model, params: reduced.fd_derivatives_reduced(
        model, params, "fd_derivatives_no_minv", with_minv=False),
    "Y": lambda model, params: regressor(model, "Y"),
}

# a tree closed by loops with a q-dependent G (kindyngen/algorithms/loop_functions.py): these
# functions in its independent coordinates; where every loop is a parallelogram (G constant) it
# is derived as a model with mimic joints instead (MIMIC_BUILDERS)
LOOP_BUILDERS: dict[str, Builder] = {
    "fk_hom": lambda model, params: loops.fk_hom_loop(model),
    "jacobian": lambda model, params: loops.jacobian_loop(model),
    "M": loops.mass_matrix_loop,
    "g": loops.gravity_loop,
    "c": loops.coriolis_loop,
    "tau": loops.inverse_dynamics_loop,
    "fd": loops.forward_dynamics_loop,
    "com": loops.centre_of_mass_loop,
}
# every tree closed by loops also gets the constraint, and the closed form where there is one
LOOP_FUNCTIONS: tuple[tuple[str, Builder], ...] = (
    ("loop_residual", lambda model, params: loops.loop_residual(model)),
    ("loop_jacobian", lambda model, params: loops.loop_jacobian(model)),
    ("loop_solve", lambda model, params: loops.loop_solve(model)),
)

NAMES: tuple[str, ...] = tuple(name for name, _ in BUILDERS) + tuple(name for name, _ in LOOP_FUNCTIONS)
# the iterative IK (kindyngen/ik/damped_least_squares.py): no derivation of its own, it iterates the
# generated fk_hom and jacobian, and is written wherever those are (an arm's one flange pose)
ITERATIVE_NAMES: tuple[str, ...] = ("ik_dls",)
ITERATED = {"ik_dls": ("fk_hom", "jacobian")}
# every name ``generate --functions`` takes
SELECTABLE_NAMES: tuple[str, ...] = NAMES + ITERATIVE_NAMES
# the functions a branched tree (or a floating base) read as a tree gets
TREE_NAMES: tuple[str, ...] = tuple(name for name, build in BUILDERS if not getattr(build, "chain_only", False))


def derive_all(model: RobotModel, params: str = "numeric", only=None, scalar: str = "double") -> list[SymbolicFunction]:
    """All applicable functions for ``model`` (optionally only the named ones), for C of the
    scalar type ``scalar`` (and the other languages written beside it)."""
    if model.has_loops:
        return _derive_loops(model, params, only)
    out = []
    for name, build in BUILDERS:
        if only is not None and name not in only:
            continue
        if model.has_mimics:
            build = MIMIC_BUILDERS.get(name, lambda model, params: None)
        function = build(model, params, scalar) if getattr(build, "per_scalar", False) else build(model, params)
        if function is not None:
            out.append(with_lengths_port(function, model))
    return out


def _derive_loops(model: RobotModel, params: str, only) -> list[SymbolicFunction]:
    """The functions of a tree closed by loops (LOOP_BUILDERS, or MIMIC_BUILDERS on its coupled
    model where G is constant), then the loop functions."""
    system = loop_system(model)
    linear = system.closed is not None and system.closed.linear
    derived, builders = (coupled_model(system), MIMIC_BUILDERS) if linear else (model, LOOP_BUILDERS)
    out = []
    for name, _ in BUILDERS + LOOP_FUNCTIONS:
        if only is not None and name not in only:
            continue
        if name in dict(LOOP_FUNCTIONS):
            function = dict(LOOP_FUNCTIONS)[name](model, params)
        else:
            function = builders.get(name, lambda model, params: None)(derived, params)
        if function is not None:
            out.append(with_lengths_port(function, model))
    return out


def mimic_notes(model: RobotModel, only=None) -> list[str]:
    """For a model with mimic joints whose tree without mimics is a chain: the functions a
    chain gets that it does not (written for independent joints), as one note; else none. A
    tree closed by loops: :func:`loop_notes`."""
    if model.has_loops:
        return loop_notes(model, only)
    if not model.has_mimics or not model.without_mimics().is_chain:
        return []
    missing = [name for name, build in BUILDERS if name not in MIMIC_BUILDERS and (only is None or name in only)]
    return [f"{model.identifier}: mimic joints: {', '.join(missing)} not generated (routes written for independent "
            f"joints); every other function takes the independent joints"] if missing else []


def loop_notes(model: RobotModel, only=None) -> list[str]:
    """What a tree closed by loops does not get, and why, as notes."""
    system = loop_system(model)
    wanted = (lambda name: only is None or name in only)
    notes = []
    if system.closed is None:
        notes.append(f"{model.identifier}: closed loops: no closed form recognised for the dependent joints "
                     f"({', '.join(system.dependent_names)}): loop_solve runs {loops.NEWTON_STEPS} Newton steps from "
                     "q_guess; every function takes the positions of all joints")
    if system.closed is None or not system.closed.linear:
        missing = [name for name in loops.NOT_GENERATED if wanted(name)]
        if missing:
            notes.append(f"{model.identifier}: closed loops with a configuration-dependent G: {', '.join(missing)} "
                         "not generated")
    return notes
def derived_names(only):
    """The derivations a selection ``only`` (None: everything) needs: its own, and those the
    iterative functions it names iterate.

    >>> sorted(derived_names({"ik_dls", "M"})), derived_names(None)
    (['M', 'fk_hom', 'ik_dls', 'jacobian'], None)
    """
    if only is None:
        return None
    return set(only).union(*(ITERATED.get(name, ()) for name in only))


def wants_ik_dls(only) -> bool:
    """Whether a selection ``only`` (None: everything) asks for ik_dls, which is then written
    where it applies (an arm's flange: kindyngen.ik.damped_least_squares.applies).

    >>> wants_ik_dls(None), wants_ik_dls({"fk_hom", "jacobian"}), wants_ik_dls({"ik_dls"})
    (True, False, True)
    """
    return only is None or "ik_dls" in only


def with_lengths_port(function: SymbolicFunction, model: RobotModel) -> SymbolicFunction:
    """Give a function of a robot with symbolic DH lengths the extra last input ``lengths``
    (all of the robot's length symbols, in order of appearance), so every function of that
    robot has the same signature whether or not a particular length reaches it."""
    symbols = tuple(se.Symbol(str(s)) for s in model.length_symbols)
    if not symbols:
        return function
    port = Port("lengths", (len(symbols),), "symbolic DH lengths: " + ", ".join(map(str, symbols)), "m")
    return replace(function, inputs=function.inputs + (port,), input_symbols=function.input_symbols + (symbols,))
