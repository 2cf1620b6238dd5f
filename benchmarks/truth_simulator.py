"""Known-truth logs for the ``discover`` benchmark (``benchmarks.discover_truth``), made without
any of kindyngen's code: Pinocchio's ``rnea`` on the models of :mod:`benchmarks.truth_robots`
for the rigid bodies, and every hidden effect by its textbook law written here.

A trial's truth is a dict ``{law: parameters}`` (plain lists and floats: it is stored in the
results).  The laws, in the units and conventions of docs/discovery.md:

==================  ============================================================  ==============
law                 what the robot does / what is logged                          discover names
==================  ============================================================  ==============
``viscous``         joint torque ``+ fv_i qd_i``                                  ``fv``
``coulomb``         ``+ fc_i sign(qd_i)`` (sharp)                                 ``fc``
``offset``          ``+ f0_i``                                                    ``f0``
``armature``        ``+ Ia_i qdd_i``                                              ``Ia``
``stribeck``        ``+ fs_i exp(-(qd_i / vs)^2) sign(qd_i)``                     ``fs``
``ripple``          ``+ rs_i sin(k q_i) + rc_i cos(k q_i)`` (k = 6, or ``k`` given) ``rs``, ``rc``
``load``            ``+ fl_i |tau_rigid_i| sign(qd_i)`` (the true rigid torque)   ``fl``
``warm_viscous``    ``+ fv_i (1 + w exp(-t / T)) qd_i``, t from the recording's   ``fv``
                    start: a cold gearbox warming up
``payload``         a rigid body fixed to the last joint (mass, CoM, inertia)     ``payload_mass``
``tilt``            gravity rotated by ``angle`` about a horizontal ``axis``      ``gravity``
``links``           every link's mass, CoM and inertia off the nominal ones       (none today)
``elastic``         logged angle ``q_i + ce_i tau_i`` (motor-side encoder,        ``ce``
                    ``ce = 1 / stiffness``, ``tau`` the joint torque)
``encoder_offset``  logged angle ``q_i + dq_i``                                   ``dq``
``gain``            logged torque ``(1 + gt_i) tau_i``                            ``gt``
==================  ============================================================  ==============

Then noise: white, ``encoder_noise`` rad on every logged angle and ``torque_noise`` N m on every
logged torque.  Only ``t, q1..qn, tau1..taun`` are written (CSV, as a user records them).

**Size of an effect.**  Measured in *noise floors*: the floor of a trial is what discover's
documented noise floor is for white torque noise of std ``torque_noise`` at the log's rate, i.e.
``torque_noise`` times the noise gain of the default preprocessing filter (5 Hz 4th-order
Butterworth, zero phase; :func:`filter_gain`).  An effect's size is the largest, over joints, RMS
of what the nominal model misses because of it (the logged torque minus the nominal rigid-body
torque along the logged motion, noise-free, through the same filter), over the floor.  Each
law's parameters are drawn as a random shape and scaled to the size drawn for it
(:func:`sized`); physical caps (encoder offset 0.03 rad, gain error 0.3, spring deflection 0.03
rad, tilt 5 degrees, payload 3 kg, link errors 30 %) may leave it smaller, and the size reached
is what is recorded.

>>> round(filter_gain(200.0), 3), round(filter_gain(1000.0), 4)
(0.212, 0.0948)
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

CUTOFF_HZ = 5.0            # discover's default low-pass (docs/discovery.md, preprocessing)
ORDER = 4
SIZE_RATE = 100.0          # effect sizes are measured on this grid (smooth signals: rate-free)
TRIM_S = 1.0               # and without this much at each end (filter edges)
SINES = 4                  # sines per joint in the excitation
MARGIN = 0.1               # rad kept from the joint limits (beyond the largest encoder offset)
ENCODER_SHARE = 0.3        # encoder noise is kept below this many floors of torque (encoder_noise_cap)
HOLD_S = 0.5               # a recording from rest to rest stands still this long at each end
RAMP_S = 5.0               # and fades the sines in and out over this long
CAPS = {"dq": 0.03, "gt": 0.3, "deflection": 0.03, "tilt_deg": 5.0, "payload_kg": 3.0, "links": 0.3,
        "links_com_m": 0.03, "fl": 0.3}


def filter_gain(rate_hz: float) -> float:
    """Std of white noise after the 5 Hz 4th-order zero-phase Butterworth at ``rate_hz`` over its
    std before: the root of the sum of the squared impulse response (scipy, run here)."""
    sos = butter(ORDER, CUTOFF_HZ, fs=rate_hz, output="sos")
    length = 2 * int(round(20 * rate_hz / CUTOFF_HZ)) + 1
    impulse = np.zeros(length)
    impulse[length // 2] = 1.0
    return float(np.sqrt(np.sum(sosfiltfilt(sos, impulse) ** 2)))


def acceleration_gain(rate_hz: float) -> float:
    """Std of the acceleration estimate (rad/s^2) that white encoder noise of std 1 rad gives
    through discover's documented preprocessing: the 5 Hz zero-phase filter, then central
    differences twice (``np.gradient``) at ``rate_hz``.

    >>> round(acceleration_gain(200.0)), round(acceleration_gain(1000.0))
    (87, 39)
    """
    sos = butter(ORDER, CUTOFF_HZ, fs=rate_hz, output="sos")
    length = 2 * int(round(20 * rate_hz / CUTOFF_HZ)) + 1
    impulse = np.zeros(length)
    impulse[length // 2] = 1.0
    h = sosfiltfilt(sos, impulse)
    return float(np.sqrt(np.sum((np.gradient(np.gradient(h)) * rate_hz ** 2) ** 2)))


def low_pass(x: np.ndarray, rate_hz: float) -> np.ndarray:
    return sosfiltfilt(butter(ORDER, CUTOFF_HZ, fs=rate_hz, output="sos"), x, axis=0)


# ---------------------------------------------------------------------------------------------
# excitation

def _flat(x):
    """``exp(-1/x)`` for x > 0, else 0 (every derivative 0 at 0), with its first two derivatives."""
    x = np.asarray(x, float)
    safe = np.where(x > 0, x, 1.0)
    value = np.where(x > 0, np.exp(-1.0 / safe), 0.0)
    return value, value / safe ** 2, value * (1 - 2 * safe) / safe ** 4


def _smoothstep(x):
    """The smooth 0 -> 1 ramp ``f(x) / (f(x) + f(1 - x))`` on [0, 1] (``f`` :func:`_flat`: every
    derivative continuous, so nothing of it is above the 5 Hz filter's band) and its first two
    derivatives.

    >>> [round(float(v), 6) for v in _smoothstep(np.array([0.0, 0.5, 1.0]))[0]]
    [0.0, 0.5, 1.0]
    """
    f, f1, f2 = _flat(x)
    g, g1, g2 = _flat(1 - np.asarray(x, float))
    g1, total = -g1, f + g
    num, num1 = f1 * g - f * g1, f2 * g - f * g2
    return f / total, num / total ** 2, (num1 * total - 2 * num * (f1 + g1)) / total ** 3


@dataclass(frozen=True)
class Excitation:
    """Per joint a sum of sines around ``center``: ``q_j(t) = center_j + e(t) sum_k amp_jk
    sin(2 pi freq_jk t + phase_jk)``, with analytic derivatives.  ``sum_k |amp_jk|`` stays
    inside the joint limits less :data:`MARGIN` (so the logged angles pass discover's limit
    check).  The envelope ``e``: with ``ramp`` > 0 the arm stands still for :data:`HOLD_S`, the
    sines fade in over ``ramp`` seconds (:func:`_smoothstep`) and out again before ``duration``: a
    recording from rest to rest; with ``ramp`` 0, ``e = 1``: a recording cut out of a longer
    motion, moving at both ends.

    >>> e = Excitation((0.0,), ((0.5, 0.1),), ((0.2, 0.3),), ((0.0, 1.0),))
    >>> q, qd, qdd = e.motion(np.array([0.0]))
    >>> round(float(q[0, 0]), 4), round(float(qd[0, 0]), 4)
    (0.0841, 0.7302)
    >>> rest = Excitation((0.0,), ((0.5, 0.1),), ((0.2, 0.3),), ((0.0, 1.0),), ramp=2.0, duration=10.0)
    >>> [float(abs(v[0, 0])) for v in rest.motion(np.array([0.2]))[1:]]
    [0.0, 0.0]
    """

    center: tuple
    amp: tuple
    freq: tuple
    phase: tuple
    ramp: float = 0.0
    duration: float = 0.0

    def motion(self, t: np.ndarray):
        t = np.asarray(t, float)
        a, f, p = (np.asarray(x, float) for x in (self.amp, self.freq, self.phase))
        w = 2 * np.pi * f
        arg = w[None] * t[:, None, None] + p[None]
        s = np.sum(a * np.sin(arg), axis=2)
        sd = np.sum(a * w * np.cos(arg), axis=2)
        sdd = -np.sum(a * w ** 2 * np.sin(arg), axis=2)
        if self.ramp > 0:
            up, upd, updd = _smoothstep((t - HOLD_S) / self.ramp)
            down, downd, downdd = _smoothstep((self.duration - HOLD_S - t) / self.ramp)
            e = up * down
            ed = (upd * down - up * downd) / self.ramp
            edd = (updd * down - 2 * upd * downd + up * downdd) / self.ramp ** 2
            e, ed, edd = e[:, None], ed[:, None], edd[:, None]
            s, sd, sdd = e * s, ed * s + e * sd, edd * s + 2 * ed * sd + e * sdd
        return np.asarray(self.center, float) + s, sd, sdd


def draw_excitation(rng: np.random.Generator, home, lower, upper, duration: float, at_rest: bool) -> Excitation:
    """Sums of :data:`SINES` sines of 0.05-0.45 Hz per joint around a pose near ``home`` (within
    +-0.3 rad), each joint's excursion 60-100 % of what its limits allow, at most 1.2 rad;
    ``at_rest``: from rest to rest over ``duration`` s (:data:`RAMP_S` ramps), else cut."""
    home, lower, upper = (np.asarray(x, float) for x in (home, lower, upper))
    lo, hi = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)
    center = np.clip(home + rng.uniform(-0.3, 0.3, len(home)), lo + 0.4, hi - 0.4)
    room = np.minimum(center - lower, upper - center) - MARGIN
    total = np.minimum(room, 1.2) * rng.uniform(0.6, 1.0, len(home))
    weights = rng.uniform(0.3, 1.0, (len(home), SINES))
    amp = weights / weights.sum(axis=1, keepdims=True) * total[:, None]
    freq = rng.uniform(0.05, 0.45, (len(home), SINES))
    phase = rng.uniform(0, 2 * np.pi, (len(home), SINES))
    return Excitation(tuple(center.tolist()), tuple(map(tuple, amp.tolist())), tuple(map(tuple, freq.tolist())),
                      tuple(map(tuple, phase.tolist())), RAMP_S if at_rest else 0.0, float(duration))


# ---------------------------------------------------------------------------------------------
# the laws

def _rotation(axis, angle) -> np.ndarray:
    """Rodrigues: rotation by ``angle`` about the unit ``axis``."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _box_inertia(mass, dims) -> np.ndarray:
    """Inertia about the CoM of a solid box (kg m^2): positive definite, triangle inequality held."""
    a, b, c = dims
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


#: the per-joint parameter vectors of each law (scaled together, and zeroed one by one to measure
#: each coefficient's own size); the scalars not listed are part of the shape
JOINT_VECTORS = {"viscous": ("fv",), "coulomb": ("fc",), "offset": ("f0",), "armature": ("Ia",),
                 "stribeck": ("fs",), "ripple": ("rs", "rc"), "load": ("fl",), "warm_viscous": ("fv",),
                 "elastic": ("ce",), "encoder_offset": ("dq",), "gain": ("gt",)}
#: the body laws' scale parameter
SCALARS = {"payload": "mass", "tilt": "angle", "links": "scale"}
LAWS = tuple(JOINT_VECTORS) + tuple(SCALARS)


def draw_shape(law: str, rng: np.random.Generator, n: int, options: dict | None = None) -> dict:
    """Unit-scale parameters of ``law`` on an ``n``-joint arm: every joint carries the effect,
    with random relative weights in [0.2, 1] (and random signs where the law is signed)."""
    options = options or {}
    w = rng.uniform(0.2, 1.0, n)
    signs = rng.choice([-1.0, 1.0], n)
    if law in ("viscous", "coulomb", "armature", "load", "elastic"):
        return {JOINT_VECTORS[law][0]: w.tolist()}
    if law in ("offset", "encoder_offset", "gain"):
        return {JOINT_VECTORS[law][0]: (w * signs).tolist()}
    if law == "stribeck":
        return {"fs": w.tolist(), "vs": float(math.exp(rng.uniform(math.log(0.03), math.log(0.3))))}
    if law == "ripple":
        angle = rng.uniform(0, 2 * np.pi, n)
        ks = options.get("orders", (6,))
        return {"rs": (w * np.cos(angle)).tolist(), "rc": (w * np.sin(angle)).tolist(), "k": int(rng.choice(ks))}
    if law == "warm_viscous":
        return {"fv": w.tolist(), "w": float(rng.uniform(0.5, 1.5)), "T": float(rng.uniform(8.0, 20.0))}
    if law == "payload":
        com = rng.uniform(-0.06, 0.06, 3) + np.array([0.0, 0.0, 0.05])
        return {"mass": 1.0, "com": com.tolist(), "dims": rng.uniform(0.04, 0.12, 3).tolist()}
    if law == "tilt":
        heading = rng.uniform(0, 2 * np.pi)
        return {"axis": [math.cos(heading), math.sin(heading), 0.0], "angle": math.radians(1.0)}
    if law == "links":
        return {"scale": 1.0, "dm": rng.uniform(-0.1, 0.1, n).tolist(), "dc": rng.uniform(-0.01, 0.01, (n, 3)).tolist(),
                "di": rng.uniform(-0.1, 0.1, n).tolist()}
    raise ValueError(f"unknown law {law!r}")


def scaled(law: str, params: dict, factor: float) -> dict:
    """``params`` with the law's size scaled by ``factor`` (its per-joint vectors or its scalar)."""
    out = dict(params)
    for key in JOINT_VECTORS.get(law, ()):
        out[key] = (np.asarray(params[key]) * factor).tolist()
    if law in SCALARS:
        out[SCALARS[law]] = float(params[SCALARS[law]] * factor)
    return out


def single(law: str, params: dict, index: int) -> dict:
    """``params`` with every per-joint coefficient but joint ``index``'s zeroed."""
    out = dict(params)
    for key in JOINT_VECTORS[law]:
        v = np.zeros(len(params[key]))
        v[index] = params[key][index]
        out[key] = v.tolist()
    return out


def cap(law: str, params: dict, peak_torque: np.ndarray) -> float:
    """The largest factor :func:`scaled` may apply inside the physical caps (:data:`CAPS`);
    ``peak_torque`` per joint (for the springs' deflection), inf where nothing caps."""
    def bound(limit, values):
        top = float(np.max(np.abs(values)))
        return limit / top if top > 0 else np.inf
    if law == "encoder_offset":
        return bound(CAPS["dq"], params["dq"])
    if law == "gain":
        return bound(CAPS["gt"], params["gt"])
    if law == "elastic":
        return bound(CAPS["deflection"], np.asarray(params["ce"]) * peak_torque)
    if law == "load":
        return bound(CAPS["fl"], params["fl"])
    if law == "tilt":
        return math.radians(CAPS["tilt_deg"]) / params["angle"]
    if law == "payload":
        return CAPS["payload_kg"] / params["mass"]
    if law == "links":
        return min(bound(CAPS["links"], np.r_[params["dm"], params["di"]]),
                   bound(CAPS["links_com_m"], np.ravel(params["dc"]))) / params["scale"]
    return np.inf


# ---------------------------------------------------------------------------------------------
# simulation

def truth_model(robot, truth: dict):
    """The Pinocchio model of the robot as it really is: the nominal one with the body laws."""
    import pinocchio as pin
    model = robot.model()
    if "links" in truth:
        p = truth["links"]
        a = p["scale"]
        for i in range(robot.n):
            body = model.inertias[i + 1]
            com = np.array(body.lever) + a * np.asarray(p["dc"][i])
            inertia = np.array(body.inertia) * (1 + a * p["di"][i])
            model.inertias[i + 1] = pin.Inertia(body.mass * (1 + a * p["dm"][i]), com, inertia)
    if "payload" in truth:
        p = truth["payload"]
        body = pin.Inertia(p["mass"], np.asarray(p["com"], float), _box_inertia(p["mass"], p["dims"]))
        model.appendBodyToJoint(model.njoints - 1, body, pin.SE3.Identity())
    if "tilt" in truth:
        model.gravity = pin.Motion(tilted_gravity_vector(model.gravity.linear, truth["tilt"]), np.zeros(3))
    return model


def tilted_gravity_vector(nominal, params: dict) -> np.ndarray:
    """The true gravity vector (m/s^2, base frame) of a ``tilt`` of the ``nominal`` one.

    >>> [round(float(v), 3) for v in tilted_gravity_vector([0, 0, -9.81], {"axis": [1, 0, 0], "angle": 0.1})]
    [0.0, 0.979, -9.761]
    """
    return _rotation(params["axis"], params["angle"]) @ np.asarray(nominal, float)


def rnea(model, q, qd, qdd) -> np.ndarray:
    import pinocchio as pin
    data = model.createData()
    return np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])


def logged(robot, truth: dict, t, q, qd, qdd, model=None):
    """Noise-free ``(q_logged, tau_logged, tau_joint)`` of a recording whose clock starts at
    ``t[0]``: the rigid bodies of :func:`truth_model`, the joint laws added to their torque,
    then the measurement laws."""
    model = truth_model(robot, truth) if model is None else model
    rigid = rnea(model, q, qd, qdd)
    tau = rigid.copy()
    for law, p in truth.items():
        if law == "viscous":
            tau += np.asarray(p["fv"]) * qd
        elif law == "coulomb":
            tau += np.asarray(p["fc"]) * np.sign(qd)
        elif law == "offset":
            tau += np.asarray(p["f0"])
        elif law == "armature":
            tau += np.asarray(p["Ia"]) * qdd
        elif law == "stribeck":
            tau += np.asarray(p["fs"]) * np.exp(-(qd / p["vs"]) ** 2) * np.sign(qd)
        elif law == "ripple":
            tau += np.asarray(p["rs"]) * np.sin(p["k"] * q) + np.asarray(p["rc"]) * np.cos(p["k"] * q)
        elif law == "load":
            tau += np.asarray(p["fl"]) * np.abs(rigid) * np.sign(qd)
        elif law == "warm_viscous":
            tau += np.asarray(p["fv"]) * (1 + p["w"] * np.exp(-(t - t[0]) / p["T"]))[:, None] * qd
    q_log, tau_log = q.copy(), tau.copy()
    if "elastic" in truth:
        q_log += np.asarray(truth["elastic"]["ce"]) * tau
    if "encoder_offset" in truth:
        q_log += np.asarray(truth["encoder_offset"]["dq"])
    if "gain" in truth:
        tau_log *= 1 + np.asarray(truth["gain"]["gt"])
    return q_log, tau_log, tau


def missed_torque(robot, truth: dict, excitations, seconds) -> np.ndarray:
    """What the nominal model misses, noise-free, filtered, on the :data:`SIZE_RATE` grid of
    every recording (rows stacked, :data:`TRIM_S` cut at each end): the logged torque minus
    the nominal rigid-body torque along the logged motion (its derivatives: the motion's
    analytic ones plus the numerical ones of what the measurement laws add)."""
    nominal, model = robot.model(), truth_model(robot, truth)
    out = []
    for exc, length in zip(excitations, seconds):
        t = np.arange(0.0, length, 1.0 / SIZE_RATE)
        q, qd, qdd = exc.motion(t)
        q_log, tau_log, _ = logged(robot, truth, t, q, qd, qdd, model)
        extra = q_log - q
        d1 = np.gradient(extra, 1.0 / SIZE_RATE, axis=0)
        d2 = np.gradient(d1, 1.0 / SIZE_RATE, axis=0)
        r = tau_log - rnea(nominal, q_log, qd + d1, qdd + d2)
        trim = int(TRIM_S * SIZE_RATE)
        out.append(low_pass(r, SIZE_RATE)[trim:-trim])
    return np.concatenate(out)


def size_of(residual: np.ndarray, floor: float) -> float:
    """The largest joint RMS of ``residual`` in noise floors."""
    return float(np.max(np.sqrt(np.mean(residual ** 2, axis=0)))) / floor


def sized(robot, law: str, shape: dict, target: float, floor: float, excitations, seconds) -> tuple[dict, float]:
    """``(parameters, size reached)``: ``shape`` scaled so that the law alone makes the nominal
    model miss ``target`` noise floors (:func:`size_of`), within :func:`cap`; laws that are not
    linear in their scale (springs, offsets, tilt, link errors) are re-measured and re-scaled
    three times (they are close to linear at these sizes)."""
    peak = np.max(np.abs(np.concatenate([rnea(robot.model(), *e.motion(np.arange(0.0, s, 1.0 / SIZE_RATE)))
                                         for e, s in zip(excitations, seconds)])), axis=0) if law == "elastic" else None
    params, limit = dict(shape), cap(law, shape, peak)
    factor = 1.0
    for _ in range(4):
        size = size_of(missed_torque(robot, {law: params}, excitations, seconds), floor)
        if size == 0:
            return params, 0.0
        step = target / size
        new = min(factor * step, limit)
        if abs(new / factor - 1) < 1e-3:
            return params, size
        factor = new
        params = scaled(law, shape, factor)
    return params, size_of(missed_torque(robot, {law: params}, excitations, seconds), floor)


def coefficient_sizes(robot, law: str, params: dict, floor: float, excitations, seconds) -> list[float]:
    """Per joint, the size (floors) of the law with only that joint's coefficients: which
    coefficients the data can be asked about.  Joint laws act on their own joint (one filter of
    the law's torque); the measurement laws on every joint (one simulation per joint)."""
    if law not in JOINT_VECTORS:
        return []
    if law in ("elastic", "encoder_offset"):
        return [size_of(missed_torque(robot, {law: single(law, params, i)}, excitations, seconds), floor)
                for i in range(robot.n)]
    r = missed_torque(robot, {law: params}, excitations, seconds)
    return (np.sqrt(np.mean(r ** 2, axis=0)) / floor).tolist()


def encoder_noise_cap(robot, excitations, seconds, rate: float, floor: float) -> float:
    """The largest encoder noise (rad) whose torque through the estimated acceleration, ``M(q)``
    times :func:`acceleration_gain` x the noise on every joint, stays within
    :data:`ENCODER_SHARE` noise floors on every joint all along the motion.  discover's floor is
    the torque sensor's noise; encoder noise beyond this would be a second, unstated noise."""
    import pinocchio as pin
    model = robot.model()
    data = model.createData()
    worst = 0.0
    for exc, length in zip(excitations, seconds):
        q = exc.motion(np.arange(0.0, length, 0.25))[0]
        for x in q:
            M = pin.crba(model, data, x)
            M = np.triu(M) + np.triu(M, 1).T
            worst = max(worst, float(np.max(np.sqrt(np.sum(M ** 2, axis=1)))))
    return ENCODER_SHARE * floor / (acceleration_gain(rate) * worst)


def write_csv(path: Path, t, q, tau) -> Path:
    """``t, q1..qn, tau1..taun`` (s, rad, N m), as a user records them."""
    n = q.shape[1]
    header = ",".join(["t"] + [f"q{i + 1}" for i in range(n)] + [f"tau{i + 1}" for i in range(n)])
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=header, comments="",
               fmt=["%.6f"] + ["%.10g"] * (2 * n))
    return path


def record(path: Path, robot, truth: dict, excitation: Excitation, seconds: float, rate: float,
           torque_noise: float, encoder_noise: float, rng: np.random.Generator) -> Path:
    """One recording of ``seconds`` at ``rate`` Hz from t = 0, noise added, written as CSV."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    q, qd, qdd = excitation.motion(t)
    q_log, tau_log, _ = logged(robot, truth, t, q, qd, qdd)
    q_log = q_log + encoder_noise * rng.standard_normal(q_log.shape)
    tau_log = tau_log + torque_noise * rng.standard_normal(tau_log.shape)
    return write_csv(path, t, q_log, tau_log)
