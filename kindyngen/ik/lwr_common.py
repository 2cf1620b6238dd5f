"""Closed-form inverse kinematics of LWR-type arms: the pieces shared by the homogeneous
form (:mod:`kindyngen.ik.lwr_homogeneous`, ``ik_hom``) and the dual-quaternion form
(:mod:`kindyngen.ik.lwr_dualquat`, ``ik_dq``), plus pure-numpy helpers that work on their
outputs (closest branch, admissible intervals of the redundancy parameter).

Applicability ("LWR type", :func:`lwr_geometry`): decided on the exact geometry, whatever
the description (DH table of either convention with any offsets, joints by origin and axis,
a tool): seven revolute joints, consecutive axes perpendicular, axes 1, 2, 3 through one point
S (spherical shoulder), axes 3, 4, 5 through one point E (elbow), axes 5, 6, 7 through one
point W (spherical wrist), S != E != W (the KUKA LWR 4 and the iiwa family). Such an arm is
mapped exactly onto the canonical LWR, the standard DH table alpha = (+pi/2, -pi/2, -pi/2,
+pi/2, +pi/2, -pi/2, 0), every a_i = 0, d = (0, 0, d3, 0, d5, 0, 0), no offsets:

    FK(q) = B FK_canon(theta) F,   theta_i = s_i q_i + o_i   (s_i = +-1, o_i exact),

with B, F constant exact transforms (base, tool; FK includes the description's tool). The
closed form below solves B^-1 T F^-1 for theta (the target is not touched when B = F = 1,
as for robots/lwr4.yaml, which is the canonical table itself); each q_i = s_i (theta_i - o_i)
is returned in a 2 pi wide window holding the joint's limits (:meth:`LwrGeometry.angle_plan`:
(-pi, pi] when the limits lie within it, else theta + constant or [lower, lower + 2 pi)), so
that the representative within the limits is returned whenever there is one. Example:
robots/lwr4_hartl.yaml (all alphas +pi/2) has B = F = 1, s = 1, o = (0, pi, 0, pi, 0, pi, pi),
its q2, q4, q6, q7 in [0, 2 pi]. In what follows th_i are the canonical angles theta_i. With
R_y the rotation about y,

    R_04 = Rz(th1) Ry(-th2) Rz(th3) Ry(th4),   R_47 = Rz(th5) Ry(-th6) Rz(th7),
    wrist centre = flange origin = Rz(th1) Ry(-th2) (d5 c3 s4, d5 s3 s4, d3 + d5 c4).

Method (both forms): ||p|| gives cos th4 (law of cosines); with th3 given the wrist centre
in frame 2 is p2 = (u, v, w) = (d5 c3 s4, d5 s3 s4, d3 + d5 c4); Rz(th1) maps (r, v) to
(px, py) and Ry(-th2) maps (u, w) to (r, pz), so r = +-sqrt(px^2 + py^2 - v^2) (shoulder
branch) and th1, th2 are two planar angles; the wrist rotation R_47 = R_04^T R* is a ZYZ
rotation (with -th6). Only the two shoulder solutions with th4 >= 0 and th6 >= 0 are
computed; the other six branches follow from two exact identities of this geometry:

    elbow twin:  (th1 + pi, -th2, th3, -th4, th5 + pi, th6, th7)   same flange pose,
    wrist twin:  (th1, th2, th3, th4, th5 + pi, -th6, th7 + pi)     same flange pose,

(R_04 of the elbow twin is R_04 Rz(-pi)), angles wrapped to (-pi, pi]. At a wrist
singularity (th6 = 0, only th5 + th7 matters) the rotation about the common axis is split
equally, th5 = th7, in every row, and the wrist twin is the same row.

Branch order: row k = 4 s + 2 e + w of ``q`` (bits of the canonical angles, which are the
angles q themselves for the canonical table):
    e (elbow) = 0: th4 >= 0, e = 1: th4 <= 0 (the elbow twin of row k - 2);
    w (wrist) = 0: th6 >= 0, w = 1: th6 <= 0 (the wrist twin of row k - 1);
    s (shoulder) = 0 / 1: r = c1 px + s1 py (the wrist centre seen along the heading of
    joint 1, in the canonical base frame) has the sign of +th4 / -th4, i.e. for e = 0 rows,
    s = 0 has r >= 0.

Status codes (one per row, first match wins; the tolerances are the double build's, the
float build's are larger, above what float resolves: :data:`TOLERANCES`):

    2  unreachable: the target is outside the workspace (||p|| beyond |d3| + |d5| or below
       ||d3| - |d5||), or not reachable with this theta3 (horizontal distance of the wrist
       centre from the z0 axis below |v| = |d5 sin th3 sin th4|); q is then a finite
       best effort (clamped), FK(q) != target.
    1  outside joint limits (reachable; some q_i outside [lower_i, upper_i] of the
       description: the arm's own angles against the arm's own limits).
    5  shoulder singular: r^2 < 1e-12 m^2 (both shoulder branches coincide; on the z0
       axis, reachable only with sin th3 sin th4 = 0, th1 is free: within 1e-12 m of the axis
       the wrist centre is put on it and th1 = 0 (or pi in the elbow twins) is returned).
    4  elbow singular: |sin th4| < ~1e-6 (arm stretched or folded; th4 is snapped to 0 / pi).
    3  wrist singular: |th6| < 1e-12 (joints 5 and 7 aligned; the rotation about the
       common axis is split equally, th5 = th7, within +-135 deg (ik_dq: +-90 deg), so that
       the limits of joints 5 and 7 rarely exclude it; th6 = 0 exactly and the wrist twin
       is the same row). th6 = +-pi (anti-aligned, beyond the LWR's limits) is not
       flagged; a valid member is returned there too.
    0  valid.

Statuses 0, 1, 3, 4, 5 all satisfy FK(q) = target (to rounding); 0, 3, 4, 5 are
admissible (within limits). Every output is finite for every finite input: inputs whose
sum of squares reaches 1e300 (ik_hom) or 1e149 (ik_dq) (float: 1e36, 1e17), divided by
(1 + |p_B| + |p_F|)^2 for a map with translations, too large for the squares and products
inside, are replaced by the (canonical) zero pose (status 2).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Optional

import numpy as np
import sympy
import symengine as se

from ..algorithms.geometry import constant, exact
from ..model.robot_model import RobotModel

# --- status codes ------------------------------------------------------------------------
VALID, LIMITS, UNREACHABLE, WRIST_SINGULAR, ELBOW_SINGULAR, SHOULDER_SINGULAR = 0, 1, 2, 3, 4, 5
STATUS_NAMES = {VALID: "valid", LIMITS: "outside joint limits", UNREACHABLE: "unreachable",
                WRIST_SINGULAR: "wrist singular", ELBOW_SINGULAR: "elbow singular",
                SHOULDER_SINGULAR: "shoulder singular"}
ADMISSIBLE = (VALID, WRIST_SINGULAR, ELBOW_SINGULAR, SHOULDER_SINGULAR)
N_BRANCHES = 8

# --- tolerances (lengths in m) -----------------------------------------------------------
@dataclass(frozen=True)
class Tolerances:
    """Where the closed form decides near its singular sets, and its overflow guards: one set
    per C scalar type, because a decision by an exact zero (or a tolerance below what the type
    resolves) is moved by rounding: in float a stretched elbow came out unreachable, and
    ``tiny`` = 1e-150 printed as 0.0f turned the guard 1 / max(x, tiny) into 1/0 and the
    wrist centre on the z0 axis (T = identity, the pose at q = 0) into NaN.

    ``reach_c4``: |cos th4| may exceed 1 by this and still reach; ``elbow_c4``: 1 - |cos th4|
    below this is elbow singular, th4 snapped (|sin th4| below ``elbow_sine``, the text of
    sqrt(2 elbow_c4)); ``shoulder_reach`` (m): |v| may exceed the wrist centre's distance
    from the z0 axis by this and still reach; ``shoulder_r2`` (m^2): r^2 below this is
    shoulder singular; ``shoulder_axis`` (m): a wrist centre this close to the z0 axis is
    put on it (th1 = 0); ``wrist_s6``: |sin th6| below this (cos th6 > 0) is wrist singular,
    th6 = 0; ``tiny``: guards 0/0 (1 / max(x, tiny), atan2(0, 0 + tiny)), a normal number
    of the type above every guarded product that is not exactly 0; ``bound_hom``,
    ``bound_dq``: inputs whose sum of squares reaches this are replaced by the zero pose
    (status 2), so that no square or product inside overflows (ik_hom's intermediates stay
    below 6 bound_hom, ik_dq's below 13 bound_dq^2 for the LWR's lengths)."""

    reach_c4: float
    elbow_c4: float
    elbow_sine: str
    shoulder_reach: float
    shoulder_r2: float
    shoulder_axis: float
    wrist_s6: float
    tiny: float
    bound_hom: float
    bound_dq: float
    stated: bool = False     # the header lists them all (float; double's header predates it)

    def conventions(self, limits: str, bound: float) -> str:
        """The generated documentation's conventions with these tolerances."""
        text = CONVENTIONS.format(limits=limits, bound=f"{bound:g}", elbow_sine=self.elbow_sine,
                                  wrist_s6=_short(self.wrist_s6))
        if self.stated:
            text += (f" Tolerances of this scalar type (above the rounding errors measured at exactly "
                     f"singular targets): reachable while |cos q4| <= 1 + {_short(self.reach_c4)} and "
                     f"|v| = |d5 sin q3 sin q4| <= rho + {_short(self.shoulder_reach)} m (rho: the wrist "
                     f"centre's distance from the z0 axis); elbow singular where 1 - |cos q4| < "
                     f"{_short(self.elbow_c4)}; shoulder singular where r^2 = rho^2 - v^2 < "
                     f"{_short(self.shoulder_r2)} m^2 (r < {math.sqrt(self.shoulder_r2) * 1e3:g} mm); a wrist "
                     f"centre within {_short(self.shoulder_axis)} m of the z0 axis is put on it; wrist "
                     f"singular where |sin q6| < {_short(self.wrist_s6)} (q6 set to 0).")
        return text


def _short(x: float) -> str:
    """A tolerance as text.

    >>> _short(1e-12), _short(1e-05), _short(4e-06)
    ('1e-12', '1e-5', '4e-6')
    """
    return f"{x:g}".replace("e-0", "e-")


TOLERANCES = {
    # double (unit roundoff 1.1e-16): |cos q4| beyond 1 by 1e-12 is about 2e-13 m in ||p||
    "double": Tolerances(reach_c4=1e-12, elbow_c4=5e-13, elbow_sine="1e-6", shoulder_reach=1e-10,
                         shoulder_r2=1e-12, shoulder_axis=1e-12, wrist_s6=1e-12, tiny=1e-150,
                         bound_hom=1e300, bound_dq=1e149),
    # float (unit roundoff 6e-8), above the rounding errors measured at exactly singular float
    # targets (tests/ik/test_ik_float.py, docs/reference/ik.md): cos q4 from ||p||^2 errs by
    # ~1e-6 (2e-5 beyond 1 is 4e-6 m in ||p|| for the LWR), r^2 by < 4e-7 m^2 where
    # |sin q4| >= 0.1, a float FK's wrist centre on the z0 axis lies ~1e-7 m off it: ten times
    # those; q6 errs by up to 5e-5 (the arm's angles carry the target's rounding, amplified
    # near the elbow and shoulder singularities): 3e-5 flags all but 0.3 %, and a wider band
    # would turn the pose by as much; tiny 1e-30 (float's normal range ends at 1.2e-38); the
    # bounds keep every intermediate below FLT_MAX (3.4e38)
    "float": Tolerances(reach_c4=2e-5, elbow_c4=1e-5, elbow_sine="4.5e-3", shoulder_reach=1e-5,
                        shoulder_r2=4e-6, shoulder_axis=1e-6, wrist_s6=3e-5, tiny=1e-30,
                        bound_hom=1e36, bound_dq=1e17, stated=True),
}

CONVENTIONS = (
    "Returns all eight closed-form branches of the LWR IK for the given theta3 (= q3). "
    "Row k = 4 s + 2 e + w of q: e = 0 elbow q4 >= 0, e = 1 q4 <= 0 (elbow twin: q1 + pi, "
    "-q2, -q4, q5 + pi); w = 0 wrist q6 >= 0, w = 1 q6 <= 0 (wrist twin: q5 + pi, -q6, "
    "q7 + pi); s = 0/1 shoulder: r = c1 px + s1 py has the sign of +q4/-q4. Angles in "
    "(-pi, pi] (q3 = theta3 as given). status (first match wins): 2 unreachable (outside "
    "the workspace or not reachable with this theta3; q finite but not a solution), "
    "1 outside joint limits, 5 shoulder singular (r ~ 0; q1 = 0 on the z0 axis), "
    "4 elbow singular (|sin q4| < {elbow_sine}, q4 snapped), 3 wrist singular (|q6| < {wrist_s6}, "
    "q6 = 0, q5 = q7: the rotation about the common axis split equally), 0 valid. "
    "Statuses 0, 1, 3, 4, 5 reproduce the target; 0, 3, 4, 5 are within the joint limits "
    "{limits}. Branch-free; no NaN/Inf for any finite input (inputs with a sum of squares "
    ">= {bound} count as the zero pose: status 2).")


# --- applicability -----------------------------------------------------------------------
@dataclass(frozen=True)
class LwrGeometry:
    """What the closed form needs from an LWR-type model, and how the model maps onto the
    canonical LWR (lwr4.yaml's standard DH table with lengths d3, d5 and no offsets):

        FK(q) = B FK_canon(theta) F,   theta_i = s_i q_i + o_i,

    with FK the model's (tool included). ``d3``, ``d5``: the canonical lengths (exact,
    signed); ``signs``: s_i = +-1; ``offsets``: o_i (exact sympy, in (-pi, pi]); ``base``: B
    as exact sympy (R, p), the canonical base frame in the model's base frame, None for the
    identity; ``flange``: F, the model's tool frame in the canonical flange frame, None for
    the identity; ``lower``, ``upper``: the model's joint limits (floats)."""

    d3: se.Basic
    d5: se.Basic
    offsets: tuple
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    signs: tuple[int, ...] = (1,) * 7
    base: Optional[tuple] = None
    flange: Optional[tuple] = None

    def limits_text(self) -> str:
        return "[" + ", ".join(f"[{lo:.6g}, {up:.6g}]" for lo, up in zip(self.lower, self.upper)) + "] rad"

    def angle_plan(self, i: int) -> tuple:
        """How the returned q_i is formed from the canonical theta_i in [-pi, pi]:
        ``(shift, lo, hi, wrap)``: q_i = s_i theta_i + shift (shift = -s_i o_i mod 2 pi, exact)
        lies in the 2 pi wide window [lo, hi] that holds the joint's limits, so a representative
        within the limits is returned whenever one exists:

        * limits within (-pi, pi]: the window (-pi, pi] (wrap: at most one 2 pi shift, a select;
          none when s_i = 1 and o_i = 0);
        * else, when [shift - pi, shift + pi] holds the limits for the shift nearest their middle:
          that window, without any select;
        * else [lower, lower + 2 pi) (wrap)."""
        sign, offset = self.signs[i], sympy.sympify(self.offsets[i])
        lower, upper = self.lower[i], self.upper[i]
        shift = -sign * offset
        if -math.pi < lower and upper <= math.pi:
            return shift, -math.pi, math.pi, not (sign == 1 and offset == 0)
        middle = 0.5 * (lower + upper)
        shift = shift + 2 * sympy.pi * round((middle - float(shift)) / (2 * math.pi))
        if float(shift) - math.pi <= lower and upper <= float(shift) + math.pi:
            return shift, float(shift) - math.pi, float(shift) + math.pi, False
        k = math.ceil((lower - float(shift)) / (2 * math.pi))       # shift into [lower, lower + 2 pi)
        if float(shift) + 2 * math.pi * k >= lower + 2 * math.pi:
            k -= 1
        return shift + 2 * sympy.pi * k, lower, lower + 2 * math.pi, True

    @property
    def is_canonical(self) -> bool:
        """The model is the canonical table itself (up to its lengths): nothing is mapped."""
        return (self.base is None and self.flange is None and all(s == 1 for s in self.signs)
                and all(sympy.sympify(o) == 0 for o in self.offsets)
                and all(-math.pi < lo and up <= math.pi for lo, up in zip(self.lower, self.upper)))

    def map_text(self) -> str:
        """The mapping onto the canonical LWR, for the generated documentation ('' when none)."""
        if self.is_canonical:
            return ""
        signs = ", ".join("+1" if s == 1 else "-1" for s in self.signs)
        offsets = ", ".join(sympy.sstr(o) for o in self.offsets)
        parts = [f" Solved as the canonical LWR (standard DH, alpha = (pi/2, -pi/2, -pi/2, pi/2, pi/2, "
                 f"-pi/2, 0), d3 = {self.d3}, d5 = {self.d5}) with FK(q) = B FK_canon(theta) F, "
                 f"theta_i = s_i q_i + o_i, s = ({signs}), o = ({offsets})"]
        for name, value in (("B", self.base), ("F", self.flange)):
            if value is not None:
                R, p = value
                parts.append(f", {name} = (R = {sympy.sstr(R.tolist())}, p = {sympy.sstr(list(p))})")
        windows = [f"q{i + 1} in [{self.angle_plan(i)[1]:.6g}, {self.angle_plan(i)[2]:.6g}]" for i in range(7)
                   if not (-math.pi < self.lower[i] and self.upper[i] <= math.pi)]
        parts.append("; the branch bits and singular statuses refer to theta, limits and angles to q"
                     + (" (" + ", ".join(windows) + ")" if windows else "") + ".")
        return "".join(parts)


# the canonical table: sign of sin(alpha_i) for i = 1..6 (alpha_7 = 0)
LWR_ALPHA_SIGNS = (1, -1, -1, 1, 1, -1)
LWR_ALPHAS = (sympy.pi / 2, -sympy.pi / 2, -sympy.pi / 2, sympy.pi / 2, sympy.pi / 2, -sympy.pi / 2, 0)
MAP_CHECK_TOL = 1e-9     # m and rotation entries (times 1 + the lengths involved): FK identity
MAP_CHECK_SAMPLES = 8    # random configurations on which the identity is checked


def _circle_reduce(value):
    """sin(a)^k with k >= 2 rewritten through sin^2 = 1 - cos^2, expanded: a canonical form of
    a polynomial in sines and cosines of independent angles (zero iff it vanishes)."""
    def high_sine(e):
        return e.is_Pow and isinstance(e.base, sympy.sin) and e.exp.is_Integer and e.exp >= 2

    def lower(e):
        a = e.base.args[0]
        return sympy.sin(a) ** (e.exp % 2) * (1 - sympy.cos(a) ** 2) ** (e.exp // 2)

    return sympy.expand(sympy.expand(value).replace(high_sine, lower))


def _tidy(value):
    """Cheap exact simplification of a constant: expanded, sines reduced on the circle,
    radicals rationalised."""
    value = sympy.expand(sympy.sympify(value))
    if value.is_Rational:
        return value
    if value.has(sympy.sin):
        value = _circle_reduce(value)
    return sympy.radsimp(value) if value.has(sympy.Pow) else value


def _zero(value) -> bool:
    """Exactly zero (expanded, reduced on the circle; simplify for what remains without
    sines and cosines). Never a float decision; a zero it cannot prove counts as nonzero."""
    value = _tidy(value)
    if value == 0:
        return True
    if value.is_Rational or value.has(sympy.sin, sympy.cos):
        return False
    return sympy.simplify(value) == 0


def _vec(values) -> sympy.Matrix:
    return sympy.Matrix([_tidy(v) for v in values])


def _unit(v: sympy.Matrix) -> sympy.Matrix:
    norm = sympy.sqrt(_tidy(v.dot(v)))
    return _vec(v / norm)


def _compose(a, b):
    (R1, p1), (R2, p2) = a, b
    return (R1 * R2).applyfunc(_tidy), (p1 + R1 * p2).applyfunc(_tidy)


def _zero_configuration(model: RobotModel):
    """Each joint's axis (unit u, point p) in the base frame where every joint's motion is
    the identity (q_i = -offset_i), and the tool frame (R, p) there, exact; None if a joint
    is not revolute."""
    pose = (sympy.eye(3), sympy.zeros(3, 1))
    axes = []
    for joint in model.joints:
        if joint.kind != "revolute":
            return None
        pose = _compose(pose, joint.before.matrix())
        axes.append((_vec(pose[0][:, 2]), pose[1]))
        pose = _compose(pose, joint.after.matrix())
    return axes, _compose(pose, model.tool.matrix())


def _meet(line1, line2):
    """The common point of two perpendicular lines, or None if they do not intersect."""
    (u1, p1), (u2, p2) = line1, line2
    a = _vec(p1 + u1 * (p2 - p1).dot(u1))           # the feet of the common perpendicular
    b = _vec(p2 + u2 * (p1 - p2).dot(u2))
    return a if all(_zero(x) for x in a - b) else None


def _on_line(point, line) -> bool:
    u, p = line
    return all(_zero(x) for x in (point - p).cross(u))


def _angle(x_from, x_to, axis):
    """The exact angle in (-pi, pi] about ``axis`` turning unit x_from (perpendicular to it)
    onto x_to: sympy's atan2 where sine and cosine are algebraic (pi/2, pi/4, ...); where
    they hold sines and cosines of other angles (a URDF's rpy of 0.3), one of those angles
    plus or minus a multiple of pi/12 if it matches exactly, else atan2 of them."""
    c, s = _tidy(x_from.dot(x_to)), _tidy(x_from.cross(x_to).dot(axis))
    if not (c.has(sympy.sin, sympy.cos) or s.has(sympy.sin, sympy.cos)):
        return sympy.atan2(s, c)
    value = math.atan2(float(s), float(c))
    found = {t.args[0] for f in (c, s) for t in f.atoms(sympy.sin, sympy.cos)}
    for a in sorted(found, key=sympy.default_sort_key):
        for sign in (1, -1):
            k = round((value - sign * float(a)) * 12 / math.pi)
            guess = sign * a + sympy.pi * sympy.Rational(k, 12)
            if _zero(sympy.cos(guess) - c) and _zero(sympy.sin(guess) - s):
                return _principal(guess)
    return sympy.atan2(s, c)


def _principal(angle):
    """An exact angle shifted by a multiple of 2 pi into (-pi, pi]."""
    k = math.floor((math.pi - float(angle)) / (2 * math.pi))
    return sympy.expand(angle + 2 * sympy.pi * k)


def _perpendicular_unit(v, axis):
    """v projected onto the plane perpendicular to unit ``axis``, normalised (None if 0)."""
    w = _vec(v - axis * v.dot(axis))
    return None if all(_zero(x) for x in w) else _unit(w)


def _frame(x, z):
    return sympy.Matrix.hstack(x, _vec(z.cross(x)), z)


def _is_identity(pose) -> bool:
    R, p = pose
    return all(_zero(x) for x in R - sympy.eye(3)) and all(_zero(x) for x in p)


def _choose_x(R_ref, z):
    """The x axis of a canonical frame with z axis ``z`` closest to frame R_ref: its x axis
    (else y axis) projected perpendicular to z."""
    x = _perpendicular_unit(R_ref[:, 0], z)
    return x if x is not None else _perpendicular_unit(R_ref[:, 1], z)


def _end_frame(sign, u, point, R_ref):
    """(R, p) of a canonical end frame (base or flange) with z = sign u, at ``point``."""
    z = u * sign
    return _frame(_choose_x(R_ref, z), z), point


def _dh_numeric(theta, d3, d5):
    """FK of the canonical LWR table, numpy (for the check of the map)."""
    T = np.eye(4)
    for i in range(7):
        c, s = math.cos(theta[i]), math.sin(theta[i])
        ca, sa = (float(sympy.cos(LWR_ALPHAS[i])), float(sympy.sin(LWR_ALPHAS[i])))
        d = (0, 0, d3, 0, d5, 0, 0)[i]
        T = T @ np.array([[c, -s * ca, s * sa, 0], [s, c * ca, -c * sa, 0], [0, sa, ca, d], [0, 0, 0, 1]])
    return T


def _pose_numeric(pose, values):
    R, p = pose
    T = np.eye(4)
    T[:3, :3] = np.array(R.subs(values).evalf(), float)
    T[:3, 3] = np.array(p.subs(values).evalf(), float).ravel()
    return T


def _model_fk_numeric(model: RobotModel, q, values):
    """The model's FK (tool included), numpy, from its placements (independent of the map)."""
    T = np.eye(4)
    for joint, qi in zip(model.joints, q):
        c, s = math.cos(qi + float(joint.offset)), math.sin(qi + float(joint.offset))
        Rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        T = T @ _pose_numeric(joint.before.matrix(), values) @ Rz @ _pose_numeric(joint.after.matrix(), values)
    return T @ _pose_numeric(model.tool.matrix(), values)


def _map_holds(model, d3, d5, signs, offsets, base, flange) -> bool:
    """FK(q) = B FK_canon(s q + o) F at random configurations (lengths given as names get
    values between 0.3 and 0.6), to MAP_CHECK_TOL times the size of the arm."""
    symbols = sorted({s for e in (d3, d5, *base[1], *flange[1]) for s in sympy.sympify(e).free_symbols}
                     | {s for j in model.joints for P in (j.before, j.after) for e in P.matrix()[1]
                        for s in sympy.sympify(e).free_symbols}, key=str)
    values = {s: 0.3 + 0.05 * k for k, s in enumerate(symbols)}
    B, F = _pose_numeric(base, values), _pose_numeric(flange, values)
    l3, l5 = float(sympy.sympify(d3).subs(values)), float(sympy.sympify(d5).subs(values))
    o = np.array([float(v) for v in offsets])
    s = np.array(signs, float)
    rng = np.random.default_rng(0)
    scale = 1 + abs(l3) + abs(l5) + np.abs(B[:3, 3]).sum() + np.abs(F[:3, 3]).sum()
    for q in rng.uniform(-math.pi, math.pi, (MAP_CHECK_SAMPLES, 7)):
        error = np.abs(_model_fk_numeric(model, q, values) - B @ _dh_numeric(s * q + o, l3, l5) @ F).max()
        if not error <= MAP_CHECK_TOL * scale:
            return False
    return True


@lru_cache(maxsize=None)    # exact geometry and a numeric check: once per model, not per IK form
def lwr_geometry(model: RobotModel) -> Optional[LwrGeometry]:
    """The LWR geometry of ``model`` and its map onto the canonical LWR, or None when the
    arm is not of LWR type (or the model is not a chain).

    LWR type, decided on the exact zero configuration (whatever the description: DH table
    of either convention, joint offsets, origins and axes, tool): seven revolute joints;
    consecutive axes perpendicular; axes 1, 2, 3 through one point S (shoulder), axes 3, 4,
    5 through one point E (elbow), axes 5, 6, 7 through one point W (wrist); S != E != W.
    These properties do not depend on the configuration (each involves axes fixed to one
    link, or points fixed by the joints between), so they hold everywhere.

    The map (see :class:`LwrGeometry`) places the canonical DH frames on the arm at q = 0:
    z_{i-1} = s_i u_i (joint i's axis), x_i = sign(sin alpha_i) z_{i-1} x z_i, origins S, S,
    S, E, E, W, W, W; then o_i is the angle from x_{i-1} to x_i about z_{i-1}, d3 = z_2 . (E - S),
    d5 = z_4 . (W - E). Choices: s_2 .. s_6 = +1 (so a DH table of the canonical type maps
    onto itself with its own offsets, and d3, d5 keep their signs); x_0 (x_7) is the model's
    base (tool) x axis projected perpendicular to z_0 (z_6); s_1 (s_7) is -1 only when that
    makes the base (tool) rotation of the map the identity. The identity is checked
    numerically at random configurations before the map is accepted (MAP_CHECK_TOL).

    >>> from kindyngen.readers.yaml_description import load_robot
    >>> lwr_geometry(load_robot("robots/lwr4.yaml")).d5           # doctest: +SKIP
    39/100
    """
    if model.n != 7 or not model.is_chain:      # a branched tree or a floating base: no closed form here
        return None
    zero = _zero_configuration(model)
    if zero is None:
        return None
    lines, tool = zero
    u = [line[0] for line in lines]
    if not all(_zero(u[i].dot(u[i + 1])) for i in range(6)):
        return None
    S, E, W = _meet(lines[0], lines[1]), _meet(lines[2], lines[3]), _meet(lines[4], lines[5])
    if S is None or E is None or W is None:
        return None
    if not (_on_line(S, lines[2]) and _on_line(E, lines[4]) and _on_line(W, lines[6])):
        return None
    if all(_zero(x) for x in E - S) or all(_zero(x) for x in W - E):
        return None

    # s_1 and s_7: -1 only when that (alone) makes the base / tool rotation the identity
    def end_sign(line, point, R_ref):
        frames = {s: _end_frame(s, line[0], point, R_ref) for s in (1, -1)}
        ok = {s: all(_zero(x) for x in frames[s][0] - R_ref) for s in (1, -1)}
        return -1 if ok[-1] and not ok[1] else 1

    signs = [end_sign(lines[0], S, sympy.eye(3))] + [1] * 5 + [end_sign(lines[6], W, tool[0])]
    z = [u[i] * signs[i] for i in range(7)]
    x = [_choose_x(sympy.eye(3), z[0])]
    x += [_vec(z[i - 1].cross(z[i]) * LWR_ALPHA_SIGNS[i - 1]) for i in range(1, 7)]
    x.append(_choose_x(tool[0], z[6]))
    # theta_i = s_i (q_i + offset_i) + angle_i: the model's offsets folded in
    offsets = tuple(_principal(signs[i] * sympy.sympify(model.joints[i].offset) + _angle(x[i], x[i + 1], z[i]))
                    for i in range(7))
    d3, d5 = _tidy(z[2].dot(E - S)), _tidy(z[4].dot(W - E))
    base = (_frame(x[0], z[0]), S)
    R7 = _frame(x[7], z[6])
    flange = ((R7.T * tool[0]).applyfunc(_tidy), (R7.T * (tool[1] - W)).applyfunc(_tidy))
    if not _map_holds(model, d3, d5, signs, offsets, base, flange):
        return None
    return LwrGeometry(d3=exact(d3), d5=exact(d5), offsets=offsets,
                       lower=tuple(float(j.lower) for j in model.joints),
                       upper=tuple(float(j.upper) for j in model.joints), signs=tuple(signs),
                       base=None if _is_identity(base) else base,
                       flange=None if _is_identity(flange) else flange)


# --- the target in the canonical frames ----------------------------------------------------
def _translation_size(geometry: LwrGeometry) -> float:
    """1 + |p_B| + |p_F| (m): how much the map can lengthen the target's translation (100
    when a length is a name)."""
    total = 1.0
    for pose in (geometry.base, geometry.flange):
        if pose is not None:
            norm = sympy.sqrt(sum(v ** 2 for v in pose[1]))
            if norm.free_symbols:
                return 100.0
            total += float(norm)
    return total


def input_bound(geometry: LwrGeometry, bound: float) -> float:
    """The sanitising bound on the sum of squares of the input: ``bound`` divided by
    (1 + |p_B| + |p_F|)^2, so that the mapped target stays within the unmapped bound (the
    rotations keep norms; a translation grows by at most that factor)."""
    return bound / _translation_size(geometry) ** 2


def canonical_pose(geometry: LwrGeometry, R, p, drop=0):
    """The target (rows of R, p) mapped onto the canonical LWR: B^-1 (R, p) F^-1 (the input
    itself when B and F are identities). ``drop`` (the 0/1 indicator of :func:`sanitize`)
    keeps a replaced input the canonical zero pose (the map's translation would move it)."""
    if geometry.base is None and geometry.flange is None:
        return R, p
    Rm, pm = se.Matrix([list(row) for row in R]), se.Matrix(list(p))
    if geometry.flange is not None:                     # T F^-1 = (R RF^T, p - R RF^T pF)
        RF = se.Matrix([[constant(v) for v in row] for row in geometry.flange[0].T.tolist()])
        pF = se.Matrix([constant(v) for v in geometry.flange[1]])
        Rm = Rm * RF
        pm = pm - Rm * pF
    if geometry.base is not None:                       # B^-1 X = (RB^T XR, RB^T (Xp - pB))
        RBt = se.Matrix([[constant(v) for v in row] for row in geometry.base[0].T.tolist()])
        pB = se.Matrix([constant(v) for v in geometry.base[1]])
        Rm = RBt * Rm
        pm = RBt * (pm - pB)
    pm = pm - pm * drop
    return tuple(tuple(Rm[i, j] for j in range(3)) for i in range(3)), tuple(pm[i] for i in range(3))


def quaternion(R: sympy.Matrix) -> tuple:
    """The unit quaternion (w, x, y, z) of an exact rotation matrix, exact (Shepperd: the
    formula is picked by the largest of 1 + tr R, 1 + 2 R_kk - tr R, on floats; the result
    is exact either way)."""
    R = sympy.Matrix(R)
    tr = R.trace()
    candidates = [1 + tr] + [1 + 2 * R[k, k] - tr for k in range(3)]
    k = max(range(4), key=lambda i: float(candidates[i]))
    root = sympy.sqrt(_tidy(candidates[k])) / 2
    quarter = 1 / (4 * root)
    if k == 0:
        q = (root, (R[2, 1] - R[1, 2]) * quarter, (R[0, 2] - R[2, 0]) * quarter, (R[1, 0] - R[0, 1]) * quarter)
    elif k == 1:
        q = ((R[2, 1] - R[1, 2]) * quarter, root, (R[0, 1] + R[1, 0]) * quarter, (R[0, 2] + R[2, 0]) * quarter)
    elif k == 2:
        q = ((R[0, 2] - R[2, 0]) * quarter, (R[0, 1] + R[1, 0]) * quarter, root, (R[1, 2] + R[2, 1]) * quarter)
    else:
        q = ((R[1, 0] - R[0, 1]) * quarter, (R[0, 2] + R[2, 0]) * quarter, (R[1, 2] + R[2, 1]) * quarter, root)
    return tuple(_tidy(v) for v in q)


# --- small symbolic helpers --------------------------------------------------------------
PI = se.pi


def select(*pairs) -> se.Basic:
    """Piecewise with a final default: select((a, cond), ..., default).

    Every condition built here is used by exactly one select: a comparison shared by two
    selects would become a common subexpression of its own (a boolean temporary tested as
    ``t == True``). A flag needed in several places is turned into a 0/1 number once
    (:func:`indicator`) and used arithmetically. No And/Or/Not either: symengine's CSE does
    not look inside them."""
    *guarded, default = pairs
    return se.Piecewise(*guarded, (default, True))


def indicator(condition) -> se.Basic:
    """1 where ``condition`` holds, else 0 (one select)."""
    return select((1, condition), 0)


def half_angle(c, s):
    """(cos th/2, sin th/2) up to a factor in [sqrt 2, 2] and a sign, from cos th, sin th:
    (1 + c, s) when c >= 0, else (s, 1 - c) (blended by a 0/1 indicator: absolute rounding
    errors of a few ulp in a vector of length >= sqrt 2)."""
    f = indicator(0 <= c)
    return f * (1 + c - s) + s, f * (s + c - 1) + 1 - c


def sanitize(entries, bound: float, flag: bool = False) -> tuple:
    """The input entries, or all zeros when their sum of squares is not below ``bound``
    (entries too large for the squares and products downstream; the zero pose is then
    reported unreachable). A sum of squares of finite numbers is never NaN, so this turns
    every finite input into one for which no intermediate overflows. With ``flag``:
    (entries, drop), drop the 0/1 indicator of the replacement."""
    drop = select((0, sum(e ** 2 for e in entries) < bound), 1)
    # e - e drop, not keep * e: symengine would rewrite (keep e)^2 as keep^2 e^2 (0 * inf)
    out = tuple(e - e * drop for e in entries)
    return (out, drop) if flag else out


def plus_pi(x) -> se.Basic:
    """x + pi wrapped to (-pi, pi], for x in [-pi, pi]: one select."""
    return select((x - PI, 0 < x), x + PI)


def wrap_up(x) -> se.Basic:
    """x wrapped to (-pi, pi], for x in (-pi, 2 pi]: one select."""
    return select((x - 2 * PI, PI < x), x)


# --- position sub-problem ------------------------------------------------------------------
@dataclass(frozen=True)
class Shoulder:
    """One shoulder solution (with th4 >= 0): the DH angles th1, th2 and their (unit)
    cosines and sines."""

    th1: se.Basic
    c1: se.Basic
    s1: se.Basic
    th2: se.Basic
    c2: se.Basic
    s2: se.Basic


def elbow_cosine(p, d3, d5, tol: Tolerances):
    """cos th4 from ||p|| by the law of cosines, clamped and snapped to +-1 near the elbow
    singularity (``tol.elbow_c4``, ``tol.reach_c4``). Returns (c4, unreachable, singular),
    the flags as single comparisons."""
    px, py, pz = p
    k = se.Integer(1) / (2 * d3 * d5)
    c4raw = (px ** 2 + py ** 2 + pz ** 2) * k - (d3 ** 2 + d5 ** 2) * k
    c4 = select((1, 1 - tol.elbow_c4 < c4raw), (-1, c4raw < -1 + tol.elbow_c4), c4raw)
    size = se.Abs(c4raw)
    return c4, 1 + tol.reach_c4 < size, 1 - tol.elbow_c4 < size


def solve_position(p, c3, s3, c4, s4, d3, d5, tol: Tolerances,
                   scale=1) -> tuple[tuple[Shoulder, Shoulder], se.Basic, se.Basic]:
    """Shoulder angles for wrist centre ``p`` given th3 (c3, s3) and th4 (c4, s4 >= 0), with
    the tolerances ``tol`` (``shoulder_axis``, ``shoulder_reach``, ``shoulder_r2``, ``tiny``).

    ``scale`` multiplies every length (the DQ form works with p/2 and d/2).
    Returns the two shoulder solutions (r >= 0 first), the shoulder-reach failure flag and
    the shoulder-singular flag."""
    px, py, pz = p
    # on the z0 axis (within tol.shoulder_axis) the wrist centre is put exactly on it, so that
    # both shoulder solutions coincide with th1 = 0 instead of following rounding noise
    rho2 = px ** 2 + py ** 2
    keep = select((0, rho2 < (tol.shoulder_axis * scale) ** 2), 1)
    px, py, rho2 = keep * px, keep * py, keep * rho2
    rho = se.sqrt(rho2)
    d5s4 = d5 * s4
    u, v, w = d5s4 * c3, d5s4 * s3, d3 + d5 * c4
    v2 = v ** 2
    r2 = rho2 - v2
    rr = se.Max(r2, 0)
    r = se.sqrt(rr)
    reach = tol.shoulder_reach * scale
    unreachable = (rho + reach) ** 2 < v2               # |v| > rho + reach
    singular = r2 < tol.shoulder_r2 * scale ** 2
    # (px, py) = Rz(th1) (r, v):  cos th1 ~ r px + v py, sin th1 ~ r py - v px
    rpx, vpy, rpy, vpx = r * px, v * py, r * py, v * px
    # (r, pz) = Rot(th2) (u, w):  cos th2 ~ u r + w pz, sin th2 ~ u pz - w r
    ur, wpz, upz, wr = u * r, w * pz, u * pz, w * r
    # norms: |(A1, B1)| = sqrt((r^2 + v^2) rho2), |(A2, B2)| = sqrt((u^2 + w^2)(r^2 + pz^2))
    tiny = tol.tiny
    inv1 = 1 / se.Max(se.sqrt(se.Max(rho2, v2)) * rho, tiny)
    inv2 = 1 / se.Max(se.sqrt((u ** 2 + w ** 2) * (rr + pz ** 2)), tiny)
    shoulders = []
    for sign in (1, -1):
        a1, b1 = sign * rpx + vpy + tiny, sign * rpy - vpx
        a2, b2 = sign * ur + wpz + tiny, upz - sign * wr
        shoulders.append(Shoulder(th1=se.atan2(b1, a1), c1=a1 * inv1, s1=b1 * inv1,
                                  th2=se.atan2(b2, a2), c2=a2 * inv2, s2=b2 * inv2))
    return tuple(shoulders), unreachable, singular


# --- the eight branches ----------------------------------------------------------------------
@dataclass(frozen=True)
class Wrist:
    """The wrist angles of one shoulder solution (th4 >= 0, th6 >= 0) and its
    singularity indicator (1 singular, 0 not)."""

    th5: se.Basic
    th6: se.Basic
    th7: se.Basic
    singular: se.Basic


def _joint(theta, sign: int, plan) -> se.Basic:
    """The model's joint angle q = s theta + shift for a canonical angle theta in [-pi, pi],
    in its window (:meth:`LwrGeometry.angle_plan`; theta itself for the canonical table)."""
    shift, lo, hi, wrap = plan
    if sign == 1 and shift == 0 and not wrap:
        return theta
    x = sign * theta + exact(shift)
    if not wrap:
        return x
    if lo == -math.pi:                                   # (-pi, pi]: x in [-2 pi, 2 pi]
        return select((x - 2 * PI, PI < x), (x + 2 * PI, x <= -PI), x)
    pairs = []                                           # [lo, lo + 2 pi), x in [shift - pi, shift + pi]
    if float(shift) - math.pi < lo:
        pairs.append((x + 2 * PI, x < lo))
    if float(shift) + math.pi >= hi:
        pairs.append((x - 2 * PI, hi <= x))
    return select(*pairs, x) if pairs else x


def _outside(x, lower: float, upper: float, symmetric: bool) -> se.Basic:
    """1 if x is outside [lower, upper], else 0 (one select on one comparison)."""
    if symmetric:
        return select((1, upper ** 2 < x ** 2), 0)
    return select((1, 0 < (x - lower) * (x - upper)), 0)


def assemble(geometry: LwrGeometry, theta3: se.Symbol, th4: se.Basic, shoulders, wrists,
             unreachable, shoulder_singular, elbow_singular):
    """Rows of q (8 x 7, flat) and status (8) from the two computed (shoulder, wrist)
    solutions, by the elbow and wrist twins.

    ``unreachable`` is a sequence of comparisons (any true: unreachable), the singular
    flags are comparisons, each wrist's ``singular`` a 0/1 indicator. A row's limit check is
    the sum of per-value 0/1 indicators (shared between rows); unreachability is folded into
    joint 3's indicator as -8, so one select per row decides between 1 and the row's code."""
    signs, plans = geometry.signs, [geometry.angle_plan(i) for i in range(7)]
    # the limits of q_i = s_i theta_i + shift_i (not wrapped) as limits of theta_i (the same
    # test, cheaper when they become symmetric); joint 3 and wrapped joints: on q_i itself
    checks = []
    for i, (lo, up) in enumerate(zip(geometry.lower, geometry.upper)):
        shift, _, _, wrap = plans[i]
        on_theta = i != 2 and not wrap
        if on_theta and not (signs[i] == 1 and shift == 0):
            lo, up = sorted((signs[i] * (lo - float(shift)), signs[i] * (up - float(shift))))
        checks.append((on_theta, lo, up, abs(lo + up) <= 1e-15 * max(1.0, abs(up))))

    def outside(i, q, theta=None):
        on_theta, lo, up, symmetric = checks[i]
        return _outside(theta if on_theta else q, lo, up, symmetric)

    def joint(i, theta):
        return _joint(theta, signs[i], plans[i])

    q3 = theta3
    unreach = select(*[(1, cond) for cond in unreachable], 0)
    global_code = select((UNREACHABLE, 0.5 < unreach), (SHOULDER_SINGULAR, shoulder_singular),
                         (ELBOW_SINGULAR, elbow_singular), VALID)
    wrist_code = select((WRIST_SINGULAR, global_code < 0.5), 0)   # 3 where nothing global
    outside3 = outside(2, q3) - 8 * unreach
    q4 = (joint(3, th4), joint(3, -th4))
    outside4 = tuple(outside(3, x, t) for x, t in zip(q4, (th4, -th4)))

    q_rows, statuses = [], []
    for sh, wr in zip(shoulders, wrists):
        # wrist twin: th5 + pi, th7 + pi; at a wrist singularity (th6 = 0, q5 = q7 = phi/2)
        # the twin is the same configuration (delta = 0)
        singular, regular = wr.singular, 1 - wr.singular
        delta = PI * regular
        # elbow twin: th5 + pi; at a wrist singularity phi + pi is split equally again,
        # th5 = th7 = phi/2 -+ pi/2 (in (-pi/2, pi/2] instead of th5 up to 135 + 180 deg)
        resplit = singular * select((-PI / 2, 0 < wr.th7), PI / 2)
        th5_e = wrap_up(wr.th5 + (delta + resplit))
        th7_e = wr.th7 + resplit
        th5 = {(0, 0): wr.th5, (0, 1): wrap_up(wr.th5 + delta), (1, 0): th5_e, (1, 1): wrap_up(th5_e + delta)}
        th7 = {(0, 0): wr.th7, (0, 1): wrap_up(wr.th7 + delta), (1, 0): th7_e, (1, 1): wrap_up(th7_e + delta)}
        th1 = {0: sh.th1, 1: plus_pi(sh.th1)}
        th2 = {0: sh.th2, 1: -sh.th2}
        th6 = {0: wr.th6, 1: -wr.th6}
        q1 = {e: joint(0, th1[e]) for e in (0, 1)}
        q2 = {e: joint(1, th2[e]) for e in (0, 1)}
        q5 = {k: joint(4, t) for k, t in th5.items()}
        q6 = {w: joint(5, th6[w]) for w in (0, 1)}
        q7 = {k: joint(6, t) for k, t in th7.items()}
        out1 = {e: outside(0, q1[e], th1[e]) for e in (0, 1)}
        out2 = {e: outside(1, q2[e], th2[e]) for e in (0, 1)}
        out5 = {k: outside(4, x, th5[k]) for k, x in q5.items()}
        out6 = {w: outside(5, q6[w], th6[w]) for w in (0, 1)}
        out7 = {k: outside(6, x, th7[k]) for k, x in q7.items()}
        code = global_code + wrist_code * wr.singular
        for elbow in (0, 1):
            for wrist in (0, 1):
                k = (elbow, wrist)
                q_rows.append((q1[elbow], q2[elbow], q3, q4[elbow], q5[k], q6[wrist], q7[k]))
                count = (outside3 + out1[elbow] + out2[elbow] + outside4[elbow] + out5[k]
                         + out6[wrist] + out7[k])
                statuses.append(select((LIMITS, 0.5 < count), code))
    return tuple(e for row in q_rows for e in row), tuple(statuses)


# --- numpy helpers on the outputs ---------------------------------------------------------------


Solver = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


