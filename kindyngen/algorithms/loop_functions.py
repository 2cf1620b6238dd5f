"""Every function a tree closed by loops gets (:mod:`kindyngen.algorithms.loop_closure`): the
constraint itself, the dependent joints' closed form, and the kinematics and dynamics in the
independent coordinates ``y``, derived on the tree without loops and reduced symbolically
through ``G(q) = [I; -Jd^-1 Ji]`` before any code exists:

* ``loop_residual(q) -> r`` (m) and ``loop_jacobian(q) -> K`` (m x n): the constraint rows and
  ``dr/dq`` at any configuration of the n joints (a Newton step on the dependent joints is
  ``q_d -= Jd^-1 r``);
* ``loop_solve(q) -> q_all`` (n): every joint from the independent ones, where the loops have a
  closed form (four-bar dyads, parallelograms); without one ``loop_solve(q, q_guess) -> q_all,
  r``: :data:`NEWTON_STEPS` Newton steps from a guess, unrolled, and the residual at the result;
* ``fk_hom``, ``jacobian`` (``J G``), ``com`` (``J_com G``, ``A_g G``): the tree's;
* ``M = G^T M_x G``, ``g = G^T g_x``, ``c = G^T tau_x(q, G qd, Gdot qd)`` without gravity,
  ``tau = G^T tau_x(q, G qd, G qdd + Gdot qd)`` by one Newton-Euler pass, ``fd``: ``M qdd =
  tau - G^T tau_x(q, G qd, Gdot qd)`` by ``L^T D L`` (``tau`` the generalised forces of the
  independent joints: the actuator torques where they are the driven joints).

Their ``q`` is the independent joints where the loops have a closed form (computed inside from
it), else every joint (a configuration closing the loops: ``loop_residual(q) = 0``); ``qd``,
``qdd`` and ``tau`` are always the independent joints'. Where every loop is a parallelogram, G is
constant and the model is reduced as one with mimic joints instead (every function of
:mod:`kindyngen.algorithms.reduced_functions`, the derivatives and ``Y`` included:
:func:`kindyngen.algorithms.loop_closure.coupled_model`). Not generated with a q-dependent G:
the derivatives (``d(G^T tau)/dq`` needs ``dG/dq``) and ``Y`` (its base parameters are
decided on samples of the closed loops); a note says so.

Example: the four-bar's inertia about its crank, a 1 x 1 function of the crank angle:

>>> from kindyngen.readers.yaml_description import parse_robot
>>> from kindyngen.algorithms.loop_closure import FOUR_BAR
>>> f = mass_matrix_loop(parse_robot(FOUR_BAR, tree=True))
>>> [(p.name, p.shape) for p in f.inputs], f.outputs[0].shape
([('q', (1,))], (1, 1))
"""
from __future__ import annotations

from dataclasses import replace

import symengine as se

from .dynamics import (ROUTE, centre_of_mass_tree, conventions as tree_conventions, crba, dynamics_function,
                       gravity_composite, rnea, setup)
from .kinematics import fk_hom_tree, jacobian_tree
from .ldlt import tree_ldlt_solve
from .loop_closure import (LoopSystem, closed_form_expressions, constraint_jacobian, eliminate, loop_system,
                           residual, row_names, solve, velocity_map)
from .reduced_coordinates import elimination_parents
from .symbolic import Port, Stages, SymbolicFunction, naming, port_symbols
from ..model.robot_model import RobotModel

# ----------------------------------------------------------------------------- ports

def _units(joints, revolute: str, prismatic: str) -> str:
    kinds = {j.kind for j in joints}
    if kinds == {"revolute"}:
        return revolute
    if kinds == {"prismatic"}:
        return prismatic
    moving = ", ".join(str(i) for i, j in enumerate(joints) if j.prismatic)
    return f"{revolute} ({prismatic} for entries {moving}, 0-based)"


def _independent_joints(system: LoopSystem):
    return [system.free.joints[j] for j in system.independent]


def all_joints_port(system: LoopSystem) -> Port:
    free = system.free
    return Port("q", (free.n,), f"positions of every joint ({', '.join(j.name for j in free.joints)}), "
                f"{free.order_text}; a configuration closing the loops (loop_residual(q) = 0: solve the dependent "
                f"joints {', '.join(system.dependent_names)})", _units(free.joints, "rad", "m"))


def independent_port(system: LoopSystem) -> Port:
    return Port("q", (len(system.independent),), f"positions of the independent joints {', '.join(system.names)} "
                f"(the dependent joints {', '.join(system.dependent_names)} follow in closed form)",
                _units(_independent_joints(system), "rad", "m"))


def q_input(system: LoopSystem) -> Port:
    """The functions' ``q``: the independent joints with a closed form, else every joint."""
    return independent_port(system) if system.closed is not None else all_joints_port(system)


def _velocity_port(system: LoopSystem, name: str, what: str, revolute: str, prismatic: str) -> Port:
    return Port(name, (len(system.independent),), f"{what} of the independent joints {', '.join(system.names)}",
                _units(_independent_joints(system), revolute, prismatic))


def qd_input(system):
    return _velocity_port(system, "qd", "velocities", "rad/s", "m/s")


def qdd_input(system, name="qdd"):
    return _velocity_port(system, name, "accelerations", "rad/s^2", "m/s^2")


def force_input(system, name, what):
    """An applied force: what drives the independent joints."""
    return _velocity_port(system, name, f"{what} (generalised forces: the driving torques where these joints are the "
                          f"driven ones; G^T of the joints' torques in general)", "N m", "N")


def force_output(system, name, what):
    """A computed force in the independent coordinates: G^T of the tree's joint torques."""
    return _velocity_port(system, name, f"{what} (G^T of the tree's joint torques: the driving torques needed)",
                          "N m", "N")


# ----------------------------------------------------------------------------- the rewriting

def in_coordinates(f: SymbolicFunction, system: LoopSystem) -> SymbolicFunction:
    """``f``, derived in every joint's symbols (q_0 .. q_{n-1}), with its ``q`` the
    independent joints where the loops have a closed form: the dependent joints computed first
    (named ``_p..``), every intermediate and output rewritten by one simultaneous substitution;
    else ``f`` with ``q`` described as every joint. The loops' text joins the conventions."""
    conventions = f"{f.conventions} {system.text}".strip()
    names = [p.name for p in f.inputs]
    if "q" not in names:
        return replace(f, conventions=conventions)
    k = names.index("q")
    if system.closed is None:
        inputs = f.inputs[:k] + (all_joints_port(system),) + f.inputs[k + 1:]
        return replace(f, inputs=inputs, conventions=conventions)
    phi = Stages(prefix="_p")
    reduced = port_symbols("q", (len(system.independent),))
    trig: dict = {}
    full = closed_form_expressions(system, reduced, phi.cut, trig)
    mapping = {**dict(zip(port_symbols("q", (system.free.n,)), full)), **trig}
    stages = phi.definitions + tuple((s, e.xreplace(mapping)) for s, e in f.stages)
    outputs = tuple(tuple(se.sympify(e).xreplace(mapping) for e in exprs) for exprs in f.output_exprs)
    inputs = f.inputs[:k] + (independent_port(system),) + f.inputs[k + 1:]
    symbols = f.input_symbols[:k] + (reduced,) + f.input_symbols[k + 1:]
    return replace(f, inputs=inputs, input_symbols=symbols, output_exprs=outputs, stages=stages,
                   conventions=conventions)


# ----------------------------------------------------------------------------- the constraint

def loop_residual(model: RobotModel, name: str = "loop_residual") -> SymbolicFunction:
    system = loop_system(model)
    q = port_symbols("q", (system.free.n,))
    rows = residual(system.free, model.loops, q)
    f = SymbolicFunction(name, "Loop-closure residual r(q): zero where the configuration closes every loop.",
                         (all_joints_port(system),), (Port("r", (len(rows),), "constraint rows "
                          f"{', '.join(row_names(model))}: translations of frame B's origin from frame A's, rotations "
                          "of B from A (entries of R_A^T R_B), in frame A's axes", "m (translations), 1 (rotations)"),),
                         (q,), (tuple(rows),))
    return replace(f, conventions=system.text)


def loop_jacobian(model: RobotModel, name: str = "loop_jacobian") -> SymbolicFunction:
    system = loop_system(model)
    q = port_symbols("q", (system.free.n,))
    K = constraint_jacobian(residual(system.free, model.loops, q), q)
    f = SymbolicFunction(name, "Loop-closure Jacobian K = dr/dq (K qd = 0 along the loops; a Newton step on the "
                         "dependent joints is q_d -= K_d^-1 r).", (all_joints_port(system),),
                         (Port("K", (len(K), system.free.n), "d r_i / d q_j (row-major; rows as loop_residual's)",
                               "m or 1 per unit of q"),), (q,), (tuple(e for row in K for e in row),))
    return replace(f, conventions=system.text)


NEWTON_STEPS = 8     # Newton steps of loop_solve without a closed form (quadratic convergence)


def loop_solve(model: RobotModel, name: str = "loop_solve") -> SymbolicFunction:
    """Every joint from the independent ones: the closed form, or (without one)
    :func:`loop_newton`."""
    system = loop_system(model)
    if system.closed is None:
        return loop_newton(model, name)
    stages = Stages()
    reduced = port_symbols("q", (len(system.independent),))
    full = closed_form_expressions(system, reduced, stages.cut)
    kinds = ", ".join(f"{model.loops[step[1]].name}: {step[0]}" for step in system.closed.steps)
    f = SymbolicFunction(name, f"Closed form of the dependent joints ({kinds}): every joint's position from the "
                         "independent ones (angles within half a turn of the reference configuration's).",
                         (independent_port(system),),
                         (Port("q_all", (system.free.n,), f"positions of every joint "
                               f"({', '.join(j.name for j in system.free.joints)}), {system.free.order_text}",
                               _units(system.free.joints, "rad", "m")),), (reduced,), (tuple(full),),
                         stages=stages.definitions)
    return replace(f, conventions=system.text)


def loop_newton(model: RobotModel, name: str = "loop_solve", steps: int = NEWTON_STEPS) -> SymbolicFunction:
    """``loop_solve(q, q_guess) -> q_all, r`` of loops without a closed form: ``steps`` Newton
    steps on the dependent joints ``q_d -= Jd^-1 r`` from ``q_guess`` (every joint; its
    independent entries are replaced by ``q``), unrolled, each through the elimination of Jd in
    the pivot order fixed at the reference (:func:`kindyngen.algorithms.loop_closure.eliminate`);
    ``r`` is the residual at the result, for the caller to judge convergence."""
    system = loop_system(model)
    free = system.free
    stages = Stages()
    tree = port_symbols("q", (free.n,))
    reduced = port_symbols("q", (len(system.independent),))
    guess = port_symbols("q_guess", (free.n,))
    rows = residual(free, model.loops, tree)
    K = constraint_jacobian(rows, tree)
    Jd = [[row[j] for j in system.dependent] for row in K]
    current = list(guess)
    for a, j in enumerate(system.independent):
        current[j] = reduced[a]

    def at(exprs, values):
        mapping = dict(zip(tree, values))
        return [stages.cut(se.sympify(e).xreplace(mapping)) if e != 0 else e for e in exprs]

    for _ in range(steps):
        r = at(rows, current)
        A = [at(row, current) for row in Jd]
        step = solve(eliminate(A, system.pivots, stages.cut), system.pivots, r, stages.cut)
        for j, d in zip(system.dependent, step):
            current[j] = stages.cut(current[j] - d)
    f = SymbolicFunction(name, f"Dependent joints by {steps} Newton steps on the loop constraints (no closed form "
                         "recognised): q_d -= Jd^-1 r from q_guess, unrolled; r is the residual at the result.",
                         (independent_port(system),
                          Port("q_guess", (free.n,), "a configuration near the solution (every joint; its independent "
                               "entries are ignored): the previous solution, or 0, the reference",
                               _units(free.joints, "rad", "m"))),
                         (Port("q_all", (free.n,), f"positions of every joint "
                               f"({', '.join(j.name for j in free.joints)}), {free.order_text}",
                               _units(free.joints, "rad", "m")),
                          Port("r", (len(rows),), f"loop residual at q_all (rows {', '.join(row_names(model))}): "
                               "converged where it is at rounding level", "m (translations), 1 (rotations)")),
                         (reduced, guess), (tuple(current), tuple(at(rows, current))), stages=stages.definitions)
    return replace(f, conventions=system.text)


# ----------------------------------------------------------------------------- kinematics

def fk_hom_loop(model: RobotModel, name: str = "fk_hom") -> SymbolicFunction:
    system = loop_system(model)
    return in_coordinates(fk_hom_tree(system.free, name), system)


def _with_columns(f: SymbolicFunction, system: LoopSystem, ports: dict, summary: str) -> SymbolicFunction:
    """``f`` (in every joint's symbols) with the last axis of each port in ``ports`` times G."""
    stages = Stages(prefix="_g")
    vmap = velocity_map(system, stages.cut)
    outputs, out_ports = [], []
    for port, exprs in zip(f.outputs, f.output_exprs):
        if port.name in ports:
            outputs.append(tuple(vmap.columns(list(exprs), port.shape)))
            port = replace(port, shape=port.shape[:-1] + (len(system.independent),))
        else:
            outputs.append(exprs)
        out_ports.append(port)
    f = replace(f, outputs=tuple(out_ports), output_exprs=tuple(outputs), stages=stages.definitions + f.stages,
                summary=f"{f.summary} {summary}")
    return in_coordinates(f, system)


def jacobian_loop(model: RobotModel, name: str = "jacobian") -> SymbolicFunction:
    system = loop_system(model)
    return _with_columns(jacobian_tree(system.free, name), system, {"J"},
                         "Reduced to the independent joints: J = J_x G.")


def centre_of_mass_loop(model: RobotModel, params: str = "numeric", name: str = "com") -> SymbolicFunction:
    system = loop_system(model)
    f = centre_of_mass_tree(system.free, params, name)
    return _with_columns(f, system, {"J_com", "A_g"}, "Reduced to the independent joints: J_com G, A_g G.")


# ----------------------------------------------------------------------------- dynamics

class _LoopDynamics:
    """What the dynamics functions share: the tree's setup, G and its factor, the joints'
    velocities ``G qd`` and the drift ``Gdot qd``, all named in ``stages``."""

    def __init__(self, model: RobotModel, params: str, stages: Stages):
        self.system = system = loop_system(model)
        self.name = name = naming(stages)
        self.ts = setup(system.free, params)
        self.map = velocity_map(system, name)
        ny = len(system.independent)
        self.qd = port_symbols("qd", (ny,))
        self.qd_full = self.map.full(self.qd)
        self.drift = self.map.drift(self.qd_full)

    def accelerations(self, qdd) -> list:
        """``G qdd + Gdot qd``: every joint's acceleration."""
        return [self.name(a + b) for a, b in zip(self.map.full(qdd), self.drift)]


def _function(name, summary, dyn: _LoopDynamics, inputs, symbols, outputs, exprs, stages, route=None):
    """A dynamics function of every joint's q and the independent joints' other ``inputs``,
    then in the loops' coordinates (:func:`in_coordinates`)."""
    system = dyn.system
    f = dynamics_function(name, ROUTE + summary, dyn.ts, (all_joints_port(system),) + tuple(inputs),
                          (port_symbols("q", (system.free.n,)),) + tuple(symbols), outputs, exprs, stages, route)
    return in_coordinates(replace(f, conventions=tree_conventions(system.free, dyn.ts.params)), system)


def mass_matrix_loop(model: RobotModel, params: str = "numeric", name: str = "M") -> SymbolicFunction:
    stages = Stages()
    dyn = _LoopDynamics(model, params, stages)
    M, _, _ = crba(dyn.ts, stages)
    My = dyn.map.congruence(M)
    ny = len(My)
    return _function(name, "inertia matrix in the independent joints M = G^T M_x G (M_x by composite rigid "
                     "bodies on the tree without loops).", dyn, (), (),
                     (Port("M", (ny, ny), "inertia matrix in the independent joints (symmetric, row-major)",
                           "kg m^2 and mixed units by coordinate"),), ([e for row in My for e in row],), stages)


def gravity_loop(model: RobotModel, params: str = "numeric", name: str = "g") -> SymbolicFunction:
    stages = Stages()
    dyn = _LoopDynamics(model, params, stages)
    g = dyn.map.transpose_times(gravity_composite(dyn.ts))
    return _function(name, "gravity forces g = G^T g_x (composite first moments on the tree).", dyn, (),
                     (), (force_output(dyn.system, "g", "gravity torques"),), (g,), stages)


def coriolis_loop(model: RobotModel, params: str = "numeric", name: str = "c") -> SymbolicFunction:
    stages = Stages()
    dyn = _LoopDynamics(model, params, stages)
    c = dyn.map.transpose_times(rnea(dyn.ts, dyn.qd_full, dyn.drift, False, stages))
    return _function(name, "Coriolis and centrifugal forces c = G^T tau_x(q, G qd, Gdot qd) without gravity "
                     "(one Newton-Euler pass).", dyn, (qd_input(dyn.system),), (dyn.qd,),
                     (force_output(dyn.system, "c", "Coriolis and centrifugal torques"),), (c,), stages)


def inverse_dynamics_loop(model: RobotModel, params: str = "numeric", name: str = "tau") -> SymbolicFunction:
    stages = Stages()
    dyn = _LoopDynamics(model, params, stages)
    qdd = port_symbols("qdd", (len(dyn.system.independent),))
    tau = dyn.map.transpose_times(rnea(dyn.ts, dyn.qd_full, dyn.accelerations(qdd), True, stages))
    return _function(name, "inverse dynamics tau = M qdd + c + g in the independent joints: G^T tau_x(q, G qd, "
                     "G qdd + Gdot qd) by one Newton-Euler pass.", dyn, (qd_input(dyn.system), qdd_input(dyn.system)),
                     (dyn.qd, qdd), (force_output(dyn.system, "tau", "torques"),), (tau,), stages)


def forward_dynamics_loop(model: RobotModel, params: str = "numeric", name: str = "fd") -> SymbolicFunction:
    stages = Stages()
    dyn = _LoopDynamics(model, params, stages)
    M, _, _ = crba(dyn.ts, stages)
    My = dyn.map.congruence(M)
    ny = len(My)
    bias = dyn.map.transpose_times(rnea(dyn.ts, dyn.qd_full, dyn.drift, True, stages))
    tau = port_symbols("tau", (ny,))
    qdd = tree_ldlt_solve(My, elimination_parents(My), [t - b for t, b in zip(tau, bias)], stages)
    return _function(name, "forward dynamics in the independent joints: M qdd = tau - G^T tau_x(q, G qd, Gdot qd)"
                     " with M = G^T M_x G, solved by L^T D L.", dyn,
                     (qd_input(dyn.system), force_input(dyn.system, "tau", "applied torques")),
                     (dyn.qd, tau), (qdd_input(dyn.system),), (qdd,), stages,
                     route="reduced L^T D L")


# not generated with a q-dependent G (Y: the regressors module says why, in base_params.json)
NOT_GENERATED = ("tau_derivatives", "fd_derivatives", "fd_derivatives_no_minv")
