"""Generic iterative inverse kinematics: damped least squares (Levenberg-Marquardt) on the
generated forward kinematics and Jacobian, for every arm (the fallback where no closed form
exists, e.g. the Panda; generated for the LWR too).

Unlike the other functions this is not a derived expression DAG: the algorithm is written
in the templates ``templates/c/ik_dls.c.j2``, ``templates/python/ik_dls.py.j2`` (numpy,
vectorised over targets) and ``templates/casadi/ik_dls.py.j2`` (branch-free, a fixed number
of iterations by ``Function.fold``), with the same operations in the same order, and this
module supplies what they need (joint limits, constants, restart table, the symbols of
the FK and Jacobian they call) plus the function's ``functions.json`` entry, whose cost is
given per iteration (:func:`dls_manifest_entry`).

Algorithm (identical in every language; constants in :data:`CONSTANTS`):

1. Invalid input (a non-finite entry in ``T`` or ``q0``, ``T``'s rotation block not
   orthonormal to ``ORTHONORMAL_TOL`` or a reflection): status 3, ``q`` = ``q0`` clamped to the
   limits where finite, else 0.
2. Start at ``q0`` clamped to the limits. Each evaluation of a candidate ``qn`` computes the
   pose error ``e = [p* - p; log(R* R^T)]`` (rotation vector in base axes; near angle 0 a
   series, near pi the axis from the symmetric part) and ``E = |e|^2``.
3. A candidate is accepted if it starts an attempt or lowers ``E``; then the Jacobian is
   evaluated there and the damping decreases (``lambda^2 *= LAMBDA2_DOWN``, not below
   ``LAMBDA2_MIN``); otherwise it is rejected and the damping increases (``*= LAMBDA2_UP``, not
   above ``LAMBDA2_MAX``). An accepted iterate with ``|e_p| < TOL_POSITION`` and
   ``|e_r| < TOL_ROTATION`` is the answer (status 0, or 1 if outside the limits, which
   clamping rules out in this algorithm).
4. Step: ``dq = J^T (J J^T + lambda^2 I)^-1 e`` by a 6x6 Cholesky solve; joints at a limit
   that the step pushes outward are removed (their Jacobian columns zeroed) and the step is
   solved once more; the step is scaled so that ``max |dq_i| <= MAX_STEP``; the candidate is
   ``q + dq`` clamped to the limits.
5. Restart: when ``E`` has not fallen below ``STALL_RATIO`` times its reference for
   ``STALL_ITERATIONS`` iterations (a local minimum, typically against a limit), the next
   configuration of a fixed pseudo-random table within the limits starts a new attempt.
6. After ``MAX_ITERATIONS`` iterations (each one FK evaluation; the first evaluation at the
   start is not counted): status 2, ``q`` = the iterate with the smallest ``E`` seen.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..algorithms.kinematics_conventions import joint_units
from ..codegen.opcount import OpCount
from ..model.robot_model import RobotModel

NAME = "ik_dls"
LANGUAGES = ("c", "python", "casadi")

# name -> (value, meaning). Values were chosen on the Panda and the LWR: 500 reachable
# targets (FK of random in-limit configurations) from random in-limit starts
# (tests/ik/test_ik_dls.py prints the measured success rates).
CONSTANTS = {
    "MAX_ITERATIONS": (200, "iteration limit (one FK evaluation each; restarts included)"),
    "TOL_POSITION": (1e-10, "convergence: |p* - p| below this [m]"),
    "TOL_ROTATION": (1e-10, "convergence: rotation-error angle below this [rad]"),
    "MAX_STEP": (0.5, "largest joint change per iteration; longer steps are scaled down [rad]"),
    "LAMBDA2_INITIAL": (1e-2, "damping lambda^2 at the start of each attempt [m^2, rad^2]"),
    "LAMBDA2_MIN": (1e-12, "smallest damping (keeps J J^T + lambda^2 I positive definite)"),
    "LAMBDA2_MAX": (1e2, "largest damping"),
    "LAMBDA2_DOWN": (0.1, "damping factor after an accepted step"),
    "LAMBDA2_UP": (10.0, "damping factor after a rejected step"),
    "STALL_ITERATIONS": (8, "restart after this many iterations without enough progress"),
    "STALL_RATIO": (0.5, "enough progress: |e|^2 below this times its value at the last progress"),
    "ORTHONORMAL_TOL": (1e-6, "invalid input: max |R^T R - I| above this (or det R <= 0)"),
    "NEAR_PI_COS": (-0.9, "rotation log: cos(angle) below this takes the axis from the symmetric part"),
    "SMALL_SIN": (1e-4, "rotation log: sin(angle) below this uses angle/sin(angle) = 1 + s^2/6"),
}

RESTART_SEED = 0x4B696E44796E47  # "KinDynG": the restart table is the same on every run


def _splitmix64(state: int):
    """Deterministic uniform numbers in [0, 1) (SplitMix64), independent of numpy's version."""
    mask = (1 << 64) - 1
    while True:
        state = (state + 0x9E3779B97F4A7C15) & mask
        z = state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        z ^= z >> 31
        yield (z >> 11) * 2.0 ** -53


def restart_table(model: RobotModel) -> tuple[tuple[float, ...], ...]:
    """Start configurations of the restarts: uniform within the limits, one row per possible
    restart (at most MAX_ITERATIONS // STALL_ITERATIONS), the same bytes on every run."""
    rows = CONSTANTS["MAX_ITERATIONS"][0] // CONSTANTS["STALL_ITERATIONS"][0]
    rng = _splitmix64(RESTART_SEED)
    return tuple(tuple(float(lo + next(rng) * (hi - lo)) for lo, hi in zip(model.lower, model.upper))
                 for _ in range(rows))


def literal(value) -> str:
    """A number as a C and Python literal that reads back exactly (ints stay ints)."""
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


@dataclass(frozen=True)
class ExtraInput:
    """An input of fk_hom and jacobian besides q (symbolic DH lengths), passed through."""
    name: str
    shape: tuple
    size: int
    unit: str
    description: str


@dataclass(frozen=True)
class DlsView:
    """Everything the ik_dls templates read."""
    name: str
    c_symbol: str
    fk_name: str
    fk_symbol: str
    jacobian_name: str
    jacobian_symbol: str
    n: int
    lower: tuple[str, ...]
    upper: tuple[str, ...]
    restarts: tuple[tuple[str, ...], ...]
    constants: dict            # name -> literal text
    descriptions: dict         # name -> meaning
    extra: tuple[ExtraInput, ...]
    cost: dict                 # per_iteration counts (see dls_manifest_entry)
    summary: str
    conventions: str
    status_text: tuple[str, ...]
    order: str                 # how q is ordered ("DH order", "chain order from the base")
    q_unit: str                # "rad", or the units of a robot with prismatic joints
    q_what: str                # "joint angles", or "joint positions" with prismatic joints


SUMMARY = "Inverse kinematics by damped least squares (Levenberg-Marquardt): q with fk_hom(q) = T within the joint limits."
CONVENTIONS = ("Iterative and generic (any arm): the generated fk_hom and jacobian, pose error "
               "e = [p* - p; log(R* R^T)] (rotation vector, base-frame axes), step dq = J^T (J J^T + "
               "lambda^2 I)^-1 e with adaptive damping, steps scaled to max |dq_i| <= MAX_STEP, every "
               "iterate clamped to the joint limits (joints held at a limit drop out of the step), "
               "restarts from a fixed table of in-limit configurations when progress stalls. "
               "Deterministic: the same T and q0 give the same q. T's last row is only checked to be finite.")
STATUS = (
    "0: converged (|p* - p| < TOL_POSITION m, rotation error < TOL_ROTATION rad) within the joint limits",
    "1: converged but outside the joint limits (cannot happen here: every iterate is clamped)",
    "2: not converged within MAX_ITERATIONS iterations; q = the iterate closest to T (smallest |e|^2)",
    "3: invalid input (non-finite T or q0, or T's rotation not orthonormal to ORTHONORMAL_TOL or "
    "a reflection); q = q0 clamped to the limits where finite, else 0",
)


def _program(programs, name):
    for p in programs:
        if p.function.name == name:
            return p
    return None


def _extra_inputs(programs) -> tuple[ExtraInput, ...] | None:
    """Inputs of fk_hom after q (they must equal jacobian's), or None if unusable."""
    fk, jac = _program(programs, "fk_hom"), _program(programs, "jacobian")
    if fk is None or jac is None:
        return None
    fk_in, jac_in = fk.function.inputs, jac.function.inputs
    if fk.function.outputs[0].shape != (4, 4):      # several frames (a tree): no single pose to reach
        return None
    if not fk_in or fk_in[0].name != "q" or [p.to_json() for p in fk_in] != [p.to_json() for p in jac_in]:
        return None
    return tuple(ExtraInput(p.name, p.shape, p.size, p.unit, p.description) for p in fk_in[1:])


def _solve_counts(n: int) -> dict:
    """Arithmetic of one iteration besides FK and Jacobian, by the README's counting rule, on
    the generic path (one solve pass, no restart; comparisons and clamping not counted):
    "solve" = J J^T + lambda^2 I (21 entries), 6x6 Cholesky, two triangular solves, J^T y,
    q + dq; "pose_error" = R* R^T, p* - p, the rotation log near 0, |e|^2."""
    jjt = OpCount(add=21 * (n - 1) + 6, mul=21 * n)
    chol = OpCount(add=sum(j + (5 - j) * j for j in range(6)),
                   mul=sum(j + (5 - j) * (j + 1) for j in range(6)), call=6)
    triangular = OpCount(add=2 * 15, mul=2 * 21)
    jty = OpCount(add=5 * n, mul=6 * n)
    # R* R^T (9 dot products of 3), p* - p (3), log: trace and cosine (3 add, 1 mul), skew
    # part (3 add, 3 mul), |v| (2 add, 3 mul, sqrt), atan2, angle/s (1 mul), e_r (3 mul),
    # |e|^2 (5 add, 6 mul)
    pose_error = OpCount(add=18 + 3 + 3 + 3 + 2 + 5, mul=27 + 1 + 3 + 3 + 1 + 3 + 6, call=2)
    step = OpCount(add=n, mul=n)  # q + dq, and at most n scalings
    solve = jjt + chol + triangular + jty + step
    return {"solve": solve, "pose_error": pose_error}


def per_iteration_counts(model: RobotModel, programs) -> dict:
    """{"fk_hom", "jacobian", "solve", "pose_error", "total"} -> {add, mul, call} for one
    iteration: one fk_hom, at most one jacobian (after an accepted step), one 6x6 solve (a
    second one only when a joint at a limit is released) and the pose error."""
    fk, jac = _program(programs, "fk_hom"), _program(programs, "jacobian")
    parts = {"fk_hom": fk.after, "jacobian": jac.after, **_solve_counts(model.nv)}
    total = OpCount()
    for count in parts.values():
        total = total + count
    return {**{k: v.to_json() for k, v in parts.items()}, "total": total.to_json()}


def applies(model: RobotModel, programs) -> bool:
    """ik_dls is generated whenever fk_hom and jacobian are (every arm)."""
    return _extra_inputs(programs) is not None


def dls_view(model: RobotModel, programs) -> DlsView | None:
    """The template context of ik_dls for ``model`` (None when fk_hom/jacobian are missing)."""
    extra = _extra_inputs(programs)
    if extra is None:
        return None
    prefix = model.identifier
    return DlsView(
        name=NAME, c_symbol=f"{prefix}_{NAME}",
        fk_name="fk_hom", fk_symbol=f"{prefix}_fk_hom", jacobian_name="jacobian",
        jacobian_symbol=f"{prefix}_jacobian", n=model.nv,
        lower=tuple(literal(float(v)) for v in model.lower),
        upper=tuple(literal(float(v)) for v in model.upper),
        restarts=tuple(tuple(literal(v) for v in row) for row in restart_table(model)),
        constants={k: literal(v) for k, (v, _) in CONSTANTS.items()},
        descriptions={k: d for k, (_, d) in CONSTANTS.items()},
        extra=extra, cost=per_iteration_counts(model, programs),
        summary=SUMMARY, conventions=CONVENTIONS, status_text=STATUS,
        order=model.order_text, q_unit=joint_units(model, "rad", "m"), q_what=_q_what(model),
    )


def _q_what(model: RobotModel) -> str:
    return "joint positions" if any(j.prismatic for j in model.coordinate_joints) else "joint angles"


def ports(model: RobotModel, programs) -> tuple[list, list]:
    """functions.json inputs and outputs of ik_dls."""
    extra = _extra_inputs(programs) or ()
    n = model.nv
    inputs = [
        {"name": "T", "shape": [4, 4], "description": "target flange pose in the base frame (row-major; last row unused)",
         "unit": "m (translation), 1 (rotation)", "dtype": "double"},
        {"name": "q0", "shape": [n], "description": f"start configuration, {model.order_text}",
         "unit": joint_units(model, "rad", "m"), "dtype": "double"},
    ] + [{"name": p.name, "shape": list(p.shape), "description": p.description, "unit": p.unit, "dtype": "double"}
         for p in extra]
    outputs = [
        {"name": "q", "shape": [n], "description": f"{_q_what(model)} reaching T (status 0); see status otherwise",
         "unit": joint_units(model, "rad", "m"), "dtype": "double"},
        {"name": "status", "shape": [1], "description": "0 converged within limits, 1 converged outside limits, "
         "2 not converged (q = best iterate), 3 invalid input", "unit": "1", "dtype": "int"},
    ]
    return inputs, outputs


def dls_manifest_entry(model: RobotModel, programs) -> dict:
    """The functions.json entry of ik_dls: "kind": "iterative", the languages it exists in,
    and instead of "before"/"after" op counts the cost of one iteration ("per_iteration",
    from the fk_hom and jacobian counts of ``programs``, the pipeline's) and the iteration
    limit."""
    inputs, outputs = ports(model, programs)
    return {
        "name": NAME,
        "kind": "iterative",
        "languages": list(LANGUAGES),
        "summary": SUMMARY,
        "conventions": CONVENTIONS,
        "c_symbol": f"{model.identifier}_{NAME}",
        "inputs": inputs,
        "outputs": outputs,
        "status": list(STATUS),
        "constants": {k: v for k, (v, _) in CONSTANTS.items()},
        "opcount": {"per_iteration": per_iteration_counts(model, programs),
                    "max_iterations": CONSTANTS["MAX_ITERATIONS"][0]},
    }
