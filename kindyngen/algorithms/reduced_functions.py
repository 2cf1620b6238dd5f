"""Every function a model with mimic joints gets, in its independent coordinates
(:mod:`kindyngen.algorithms.reduced_coordinates`: ``q_x = G q_y + b``): derived on the same tree
without mimics by the tree routes, then reduced symbolically.

* ``fk_hom``, ``jacobian``, ``M``, ``g``, ``c``, ``tau``, ``com``: the tree functions with their
  velocity axes contracted with G (``J G``, ``G^T M G``, ``G^T tau``, ``J_com G``, ``A_g G``);
* ``fd``: ``M_y qdd_y = tau_y - G^T (c + g)(q_x, G qd_y)`` with ``M_y = G^T M G`` factorised as
  ``L^T D L`` along the elimination tree of its pattern (a mimic coupling two branches joins
  them: :func:`kindyngen.algorithms.reduced_coordinates.elimination_parents`), the joint effects
  in M and the bias as for every robot;
* ``tau_derivatives``, ``fd_derivatives``, ``fd_derivatives_no_minv``: the world-frame
  derivatives of the full tree (:mod:`kindyngen.algorithms.derivatives_world_frame`; the
  friction derivative on the diagonal of dtau/dqd where the description has friction) at
  ``(q_x, G qd_y, G qdd_y)``, then ``G^T D G`` (G constant), and for fd ``-M_y^-1`` of those
  through the factor of ``M_y``, at ``qdd_y = fd``;
* ``Y`` (:mod:`kindyngen.algorithms.regressors`): ``G^T Y_x`` on the base parameters of the
  reduced regressor, found on it.

The routes written for serial chains (``S``, the Lagrange and dual-quaternion dynamics, ``Y_g``,
``Y_m``, the closed-form IK) are not generated for a model with mimic joints (the catalog says
so in a note); ``ik_dls`` iterates the reduced ``fk_hom`` and ``jacobian`` of an arm.

Example: the two pendulums, the right one following the left with multiplier -1:

>>> import sympy
>>> from dataclasses import replace
>>> from kindyngen.model.robot_model import Mimic
>>> from kindyngen.readers.urdf import parse_urdf, TWO_PENDULUMS
>>> tree = parse_urdf(TWO_PENDULUMS, tree=True)
>>> coupled = replace(tree, joints=(tree.joints[0], replace(tree.joints[1], mimic=Mimic(0, sympy.Integer(-1)))))
>>> f = mass_matrix_reduced(coupled)
>>> [(p.name, p.shape) for p in f.inputs], f.outputs[0].shape
([('q', (1,))], (1, 1))
"""
from __future__ import annotations

from dataclasses import replace

import symengine as se

from .derivatives_sweeps import with_diagonal
from .derivatives_world_frame import NOTE as DERIVATIVES_NOTE, WorldPass
from .effect_torques import additive_derivatives
from .dynamics import (ROUTE, centre_of_mass_tree, coriolis_tree, crba, dynamics_function, force_port, gravity_tree,
                       inverse_dynamics_tree, joint_effects, mass_matrix_tree, mass_matrix_with_armature, rnea, setup)
from .kinematics import fk_hom_tree, jacobian_tree
from .kinematics_conventions import q_port
from .ldlt import tree_ldlt_factor, tree_ldlt_substitute
from .reduced_coordinates import coordinate_map, elimination_parents, reduce_function, reduced_function, reduced_input
from .rigid_bodies import ZERO, qd_port, qdd_port
from .symbolic import Port, Stages, SymbolicFunction, naming, port_symbols
from ..model.robot_model import FREE_FLYER_NV, RobotModel

FOLDED = ("Reduced to the independent joints: the mimic joints' motion through their multipliers, "
          "{what} (derived on the tree without mimics, then folded in symbolically).")


def fk_hom_reduced(model: RobotModel, name: str = "fk_hom") -> SymbolicFunction:
    f = fk_hom_tree(model.without_mimics(), name)
    return reduce_function(f, model, {"T": ()}, FOLDED.format(what="poses at q_x = G q + b"))


def jacobian_reduced(model: RobotModel, name: str = "jacobian") -> SymbolicFunction:
    f = jacobian_tree(model.without_mimics(), name)
    return reduce_function(f, model, {"J": (len(f.outputs[0].shape) - 1,)},
                           FOLDED.format(what="J = J_x G (each mimic joint's column added to its joint's, "
                                              "times the multiplier)"))


def mass_matrix_reduced(model: RobotModel, params: str = "numeric", name: str = "M") -> SymbolicFunction:
    f = mass_matrix_tree(model.without_mimics(), params, name)
    return reduce_function(f, model, {"M": (0, 1)}, FOLDED.format(what="M = G^T M_x G"))


def gravity_reduced(model: RobotModel, params: str = "numeric", name: str = "g") -> SymbolicFunction:
    f = gravity_tree(model.without_mimics(), params, name)
    return reduce_function(f, model, {"g": (0,)}, FOLDED.format(what="g = G^T g_x"))


def coriolis_reduced(model: RobotModel, params: str = "numeric", name: str = "c") -> SymbolicFunction:
    f = coriolis_tree(model.without_mimics(), params, name)
    return reduce_function(f, model, {"c": (0,)}, FOLDED.format(what="c = G^T c_x(q_x, G qd)"))


def inverse_dynamics_reduced(model: RobotModel, params: str = "numeric", name: str = "tau") -> SymbolicFunction:
    f = inverse_dynamics_tree(model.without_mimics(), params, name)
    return reduce_function(f, model, {"tau": (0,)}, FOLDED.format(what="tau = G^T tau_x(q_x, G qd, G qdd)"))


def centre_of_mass_reduced(model: RobotModel, params: str = "numeric", name: str = "com") -> SymbolicFunction:
    f = centre_of_mass_tree(model.without_mimics(), params, name)
    return reduce_function(f, model, {"com": (), "J_com": (1,), "A_g": (1,)},
                           FOLDED.format(what="J_com = J_com_x G, A_g = A_g_x G"))


# ----------------------------------------------------------------------------- fd and the derivatives

class _ReducedDynamics:
    """What fd and its derivatives share, on the tree without mimics in its full symbols: M_y
    and the bias ``G^T (c + g + effects)`` (both named), M_y's factor along its elimination
    tree, the reduced input ``tau`` and ``qdd_y = fd``."""

    def __init__(self, model: RobotModel, params: str, stages: Stages):
        cmap = self.cmap = coordinate_map(model)
        free = cmap.free
        name = self.name = naming(stages)
        self.ts = setup(free, params)
        self.qd = port_symbols("qd", (free.nv,))
        M, _, _ = crba(self.ts, stages)
        M = mass_matrix_with_armature(free, M)
        # no load-dependent friction here (the reader refuses it beside mimic joints): the
        # joint effects are additive, a(q, qd) on the bias
        bias = joint_effects(free, self.ts.q, self.qd, None, rnea(self.ts, self.qd, None, True, stages))
        reduced = cmap.congruence(M)
        nv = cmap.nv
        upper = {(r, c): name(reduced[r][c]) for r in range(nv) for c in range(r, nv)}
        self.M = [[upper[min(r, c), max(r, c)] for c in range(nv)] for r in range(nv)]
        self.bias = [name(e) for e in cmap.contract(bias, (free.nv,), (0,))]
        self.parents = elimination_parents(self.M)
        self.factor = tree_ldlt_factor(self.M, self.parents, stages)
        self.tau = port_symbols("tau", (nv,))
        self.qdd = tree_ldlt_substitute(self.factor, [t - b for t, b in zip(self.tau, self.bias)], name)

    def derivatives(self, qdd_full, stages: Stages):
        """``(dtau_dq, dtau_dqd)`` reduced, at (q_x, qd_x, ``qdd_full``): :func:`_derivatives`."""
        return _derivatives(self.cmap, self.ts, self.qd, qdd_full, stages)


def _derivatives(cmap, ts, qd, qdd_full, stages: Stages):
    """``(dtau_dq, dtau_dqd)`` of the full tree at (q_x, ``qd``, ``qdd_full``) by the world-frame
    pass, with the description's friction derivative, reduced to ``G^T D G`` (G constant)."""
    free = cmap.free
    dq, dqd = WorldPass(ts, qd, qdd_full, stages).derivatives()
    base = FREE_FLYER_NV if free.floating_base else 0
    if free.effects:
        # the additive effects depend on each joint's own q (ripple) and qd (friction) only
        da_dq, da_dqd = additive_derivatives(free, ts.q[base:] if base == 0 else None, qd[base:])
        if any(d != 0 for d in da_dq):
            dq = with_diagonal(dq, [ZERO] * base + da_dq)
        dqd = with_diagonal(dqd, [ZERO] * base + da_dqd)
    return cmap.congruence(dq), cmap.congruence(dqd)


def _ports(model: RobotModel, last: Port) -> tuple[Port, ...]:
    free = model.without_mimics()
    return (reduced_input(model, q_port(free), free), reduced_input(model, qd_port(free), free), last)


def _flat(matrix):
    return [e for row in matrix for e in row]


def _symbols(model: RobotModel, last: str) -> tuple:
    return (port_symbols("q", (model.nq,)), port_symbols("qd", (model.nv,)), port_symbols(last, (model.nv,)))


def forward_dynamics_reduced(model: RobotModel, params: str = "numeric", name: str = "fd") -> SymbolicFunction:
    """``fd(q, qd, tau) -> qdd`` in the independent coordinates (module text)."""
    stages = Stages()
    rd = _ReducedDynamics(model, params, stages)
    ports = _ports(model, force_port(model, "tau", "applied torque"))
    f = dynamics_function(name, ROUTE + "forward dynamics qdd = M^-1 (tau - c - g) in the independent joints: M = "
                          "G^T M_x G (M_x by composite rigid bodies on the tree without mimics), c + g = G^T of one "
                          "Newton-Euler pass at qd_x = G qd, M = L^T D L along its elimination tree and the two sparse "
                          "triangular solves.", rd.ts, ports, _symbols(model, "tau"), (qdd_port(model),), (rd.qdd,),
                          stages, route="reduced L^T D L")
    return reduced_function(f, model, f.inputs, f.input_symbols, f.outputs, f.output_exprs)


def _matrix_port(model: RobotModel, name: str, what: str, unit: str) -> Port:
    return Port(name, (model.nv, model.nv), what + " (row-major, nv x nv)", unit)


def tau_derivatives_reduced(model: RobotModel, params: str = "numeric",
                            name: str = "tau_derivatives") -> SymbolicFunction:
    """``tau_derivatives(q, qd, qdd) -> dtau_dq, dtau_dqd`` in the independent coordinates."""
    cmap, stages = coordinate_map(model), Stages()
    free = cmap.free
    ts = setup(free, params)
    qd, qdd = port_symbols("qd", (free.nv,)), port_symbols("qdd", (free.nv,))
    dq, dqd = _derivatives(cmap, ts, qd, qdd, stages)
    ports = _ports(model, reduced_input(model, qdd_port(free), free))
    f = dynamics_function(name, ROUTE + "partial derivatives of the inverse dynamics tau(q, qd, qdd) in the independent "
                          "joints: the world-frame derivatives of Carpentier and Mansard (RSS 2018) of the tree without "
                          "mimics at (q_x, G qd, G qdd), then G^T D G; dtau/dqdd is M.", ts, ports, _symbols(model, "qdd"),
                          (_matrix_port(model, "dtau_dq", "dtau_i / dq_j", "N m/rad and mixed units by coordinate"),
                           _matrix_port(model, "dtau_dqd", "dtau_i / dqd_j", "N m s/rad and mixed units by coordinate")),
                          (_flat(dq), _flat(dqd)), stages, route="world frame")
    f = reduced_function(f, model, f.inputs, f.input_symbols, f.outputs, f.output_exprs)
    return _noted(f)


def fd_derivatives_reduced(model: RobotModel, params: str = "numeric", name: str = "fd_derivatives",
                           with_minv: bool = True) -> SymbolicFunction:
    """``fd_derivatives(q, qd, tau) -> dqdd_dq, dqdd_dqd[, Minv]`` in the independent
    coordinates: ``-M_y^-1 dtau_y/dx`` at ``qdd_y = fd``, every column through M_y's factor."""
    stages = Stages()
    rd = _ReducedDynamics(model, params, stages)
    nv = model.nv
    dq, dqd = rd.derivatives(rd.cmap.velocity(rd.qdd), stages)
    solved = [[tree_ldlt_substitute(rd.factor, [-B[i][j] for i in range(nv)], rd.name) for j in range(nv)]
              for B in (dq, dqd)]
    outputs = [[col[i] for i in range(nv) for col in columns] for columns in solved]
    ports = [_matrix_port(model, "dqdd_dq", "dqdd_i / dq_j", "1/s^2 and mixed units by coordinate"),
             _matrix_port(model, "dqdd_dqd", "dqdd_i / dqd_j", "1/s and mixed units by coordinate")]
    what = "dqdd/dtau is M^-1"
    if with_minv:
        columns = [tree_ldlt_substitute(rd.factor, [se.Integer(1 if i == k else 0) for i in range(nv)], rd.name)
                   for k in range(nv)]
        outputs.append([columns[min(i, k)][max(i, k)] for i in range(nv) for k in range(nv)])
        ports.append(_matrix_port(model, "Minv", "inverse joint-space inertia matrix M^-1 = dqdd/dtau (symmetric)",
                                  "1/(kg m^2) and mixed units by coordinate"))
    else:
        what += ", not formed here (the function fd_derivatives has it)"
    f = dynamics_function(name, ROUTE + "partial derivatives of the forward dynamics qdd = fd(q, qd, tau) in the "
                          "independent joints: dqdd/dx = -M^-1 G^T (dtau_x/dx) G at qdd = fd(q, qd, tau), dtau_x/dx in "
                          "the world-frame formulation of Carpentier and Mansard (RSS 2018) on the tree without mimics, "
                          "every column solved through one L^T D L factor of M = G^T M_x G; " + what + ".", rd.ts,
                          _ports(model, force_port(model, "tau", "applied torque")), _symbols(model, "tau"),
                          tuple(ports), tuple(outputs), stages, route="world frame")
    f = reduced_function(f, model, f.inputs, f.input_symbols, f.outputs, f.output_exprs)
    return _noted(f)


def _noted(f: SymbolicFunction) -> SymbolicFunction:
    return replace(f, conventions=f.conventions + DERIVATIVES_NOTE)
