"""The MPC in a closed loop at two rates: the tracking MPC (kindyngen/control/mpc.py) every
interval h, and at the plant's rate (1 kHz) an inner loop that

- estimates the state (each measurement blended with the model's one-sample prediction) and
  the torque disturbance (inverse dynamics of the generated ``tau`` at the estimate's
  finite-difference acceleration, minus the torque applied; a slow low-pass that jumps to a fast
  one where they part, see LoopOptions): whatever acts on the joints that the model lacks (a
  payload, a push, a torque step, wrong masses) is one torque d, which the MPC's model includes
  at every re-solve (averaged over the last interval) and the inner loop cancels from the next
  sample on (its change since the re-solve);
- follows the MPC's prediction between its nodes (cubic Hermite between the measured state and
  the plan's node 1) with a joint-space PD scaled by the mass matrix (natural frequency
  ``feedback_hz``), so that a deviation is corrected within milliseconds, not at the next re-solve;
- clips the command to the torque limits (the drive's saturation; the MPC plans within
  (1 - reserve) of them).

Fallback: when a re-solve fails or runs past its time budget (MPCOptions.budget_s), the previous
plan shifted by one interval is applied; after ``max_fallback`` such steps in a row, or when no
plan is left, the braking controller takes over (tau = inverse dynamics at the acceleration
-qd / brake_time, disturbance cancelled, clipped) until a re-solve succeeds again.

The limit guard, at every sample and whatever the mode (MPC, shifted plan, brake): where the
command would take a joint past its speed limit within the next sample, or where a joint moving
towards a position limit could no longer stop before it with the torque it has left (a
conservative deceleration: half of what the torque limit leaves beyond the gravity, Coriolis and
disturbance torques, over the joint's own inertia), that joint's acceleration is replaced by the
one that brings it back to (1 - guard_speed) of its speed limit, or to the speed from which it
can still stop ``guard_margin`` short of the limit, within ``guard_time``; the correction's
torque (the mass matrix times the change of acceleration) is added to the command scaled as a
whole into the torque limits. The MPC's plans never trigger it
(they keep 5 % of every speed limit); it acts where no re-solve can (a step that puts a joint
past its speed limit within one sample, a re-solve that misses its budget while a joint heads
for a limit), so that no position limit is passed as long as the torque suffices to stop.

The plant is the caller's: ``step(x, tau, dt, t) -> x`` and ``measure(x, t) -> x_measured``
(benchmarks/control_plant.py: Pinocchio's ABA with disturbances and sensor noise).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mpc import TrackingMPC


@dataclass(frozen=True)
class LoopOptions:
    """``feedback_hz``, ``damping``: the inner PD; ``observer_alpha``, ``observer_slow``: the fast and
    the slow disturbance estimates' low-pass gains per sample (0.8: with 0.3 a 24 N m step on the
    LWR's last joint, 5.8e-4 kg m^2, was cancelled only after 5-10 ms, when the joint had spun
    past its position limit; with 0.8 it stays 2.4 rad inside), ``jump``: the fast one is taken where
    the difference between them would change a joint's speed by more than ``jump`` of its
    limit within ``jump_window`` seconds (M^-1's diagonal, updated at every re-solve); ``filter_gain``: the state estimate's gain on the measurement per
    sample (1: the raw measurement; below 1 a one-sample model prediction is blended in, which
    keeps sensor noise out of the MPC's initial state and the estimate); ``brake_time``; and
    after how many failed re-solves in a row the brake takes over; ``guard``: the limit guard
    (module docstring), which brings a joint past its speed limit back to (1 - guard_speed) of
    it and stops a joint ``guard_margin`` (rad) short of its position limit, aiming to get there
    within ``guard_time`` (measured on the LWR's torque steps: 1 ms stopped the decoupled wrist
    fastest, 11 samples past its speed limit against 26 with 3 ms and 137 without the guard,
    but on joints 1 and 3, nearly parallel there, an error of the disturbance estimate in their
    light relative motion grew under 1 ms corrections to peaks of 8 times the speed limit against
    3.4 with 3 ms and 2.6 without the guard; 10 ms gave 59 samples on the wrist)."""
    plant_hz: float = 1000.0
    feedback_hz: float = 10.0
    damping: float = 1.0
    observer_alpha: float = 0.8
    observer_slow: float = 0.05
    jump: float = 0.05
    jump_window: float = 0.01
    filter_gain: float = 0.3
    brake_time: float = 0.05
    max_fallback: int = 3
    feedback: bool = True
    observer: bool = True
    guard: bool = True
    guard_speed: float = 0.02
    guard_margin: float = 0.005
    guard_time: float = 0.003


@dataclass
class LoopLog:
    """Per plant sample: t, x (true), tau (applied command), d_hat, guard (the joints the limit
    guard took over, a bit mask); per MPC step: its report."""
    t: list = field(default_factory=list)
    x: list = field(default_factory=list)
    tau: list = field(default_factory=list)
    d_hat: list = field(default_factory=list)
    guard: list = field(default_factory=list)
    steps: list = field(default_factory=list)


def _hermite(x0, x1, s, h, n):
    """Cubic Hermite of q between (q0, qd0) and (q1, qd1) at s in [0, 1] over h; its speed."""
    q0, v0, q1, v1 = x0[:n], x0[n:], x1[:n], x1[n:]
    h00, h10, h01, h11 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s, -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
    d00, d10, d01, d11 = 6 * s ** 2 - 6 * s, 3 * s ** 2 - 4 * s + 1, -6 * s ** 2 + 6 * s, 3 * s ** 2 - 2 * s
    q = h00 * q0 + h10 * h * v0 + h01 * q1 + h11 * h * v1
    v = (d00 * q0 + d01 * q1) / h + d10 * v0 + d11 * v1
    return q, v


class Controller:
    """The two-rate controller. ``control(t, x_measured)`` at every plant sample returns the
    torque to hold until the next one."""

    def __init__(self, mpc: TrackingMPC, options: LoopOptions = LoopOptions()):
        self.mpc, self.o = mpc, options
        n = self.n = mpc.n
        self.dt = 1.0 / options.plant_hz
        self.per_step = int(round(mpc.h * options.plant_hz))
        if abs(self.per_step * self.dt - mpc.h) > 1e-9:
            raise ValueError(f"the MPC interval {mpc.h} s is not a whole number of plant samples")
        self.kp = (2 * np.pi * options.feedback_hz) ** 2
        self.kd = 2 * options.damping * 2 * np.pi * options.feedback_hz
        self.d_hat = np.zeros(n)
        self.d_fast = np.zeros(n)
        self.minv_diag = np.zeros(n)
        self.m_diag = None          # the mass matrix's diagonal at the last re-solve (the guard's)
        self.guarded = 0            # bit mask of the joints the guard took over at the last sample
        self.d_model = np.zeros(n)
        self.d_sum, self.d_sum_count, self.jumped = np.zeros(n), 0, np.zeros(n, bool)
        self.prev = None             # (x_measured, tau) of the last sample
        self.sample = 0
        self.i = 0                   # MPC step
        self.X = self.U = None
        self.ws = None
        self.plan_x0 = None
        self.plan_age = 0
        self.fallbacks = 0
        self.mode = "mpc"
        self.d_at_solve = np.zeros(n)
        self.reports = []

    def _observe(self, x):
        """The state estimate from the measurement x (blended with the model's one-sample
        prediction from the last estimate) and the disturbance estimate from the estimate's
        change; returns the estimate."""
        o, n, dt = self.o, self.n, self.dt
        if self.prev is None:
            return x
        xp, up = self.prev
        if o.filter_gain < 1.0:
            a = self.mpc.lib.fd(xp[:n], xp[n:], up + self.d_hat)
            v_pred = xp[n:] + dt * a
            pred = np.concatenate([xp[:n] + dt * (xp[n:] + v_pred) / 2, v_pred])
            # a joint whose measured speed leaves the prediction by more than ``jump`` of its speed
            # limit in one sample is not noise (a step, a collision): its measurement is taken as
            # it is, so that the disturbance estimate sees the whole change at once (blended, the
            # LWR's wrist under a 24 N m step showed the estimate a third of it and spun on for
            # 3 ms more)
            vmax = self.mpc.limits.array("qd_max")
            gain = np.where(np.abs(x[n:] - pred[n:]) > o.jump * vmax, 1.0, o.filter_gain)
            x = pred + np.concatenate([gain, gain]) * (x - pred)
        if o.observer:
            # two low-pass estimates of the finite-difference disturbance: a slow one, which keeps
            # sensor noise out (a noisy estimate is a random torque on the light wrists), and a fast
            # one; where their difference would move a joint off its speed within milliseconds (a
            # push, a step, a payload) the slow one takes the fast one's value at once
            qm, vm = (x[:n] + xp[:n]) / 2, (x[n:] + xp[n:]) / 2
            raw = self.mpc.lib.tau(qm, vm, (x[n:] - xp[n:]) / dt) - up
            self.d_fast = self.d_fast + o.observer_alpha * (raw - self.d_fast)
            slow = self.d_hat + o.observer_slow * (raw - self.d_hat)
            jump = np.abs(self.d_fast - slow) * self.minv_diag * o.jump_window > o.jump * self.mpc.limits.array("qd_max")
            self.d_hat = np.where(jump, self.d_fast, slow)
            self.jumped |= jump
            self.d_sum = self.d_sum + self.d_hat
            self.d_sum_count += 1
        return x

    def _resolve(self, x):
        mpc = self.mpc
        # the model's disturbance: the estimate averaged over the last interval (an inertia
        # mismatch makes the estimate follow the accelerations; fed back sample by sample into
        # every re-solve it set the Panda's wrist swinging by 5-15 mm); a jump is taken at once
        if self.d_sum_count:
            avg = self.d_sum / self.d_sum_count
            self.d_model = np.where(self.jumped, self.d_hat, avg)
        self.d_sum, self.d_sum_count, self.jumped = np.zeros(self.n), 0, np.zeros(self.n, bool)
        z = np.zeros(self.n)
        g = mpc.lib.tau(x[:self.n], z, z)
        M = np.array([mpc.lib.tau(x[:self.n], z, e) - g for e in np.eye(self.n)])
        self.minv_diag = np.diag(np.linalg.inv(M)).copy()
        self.m_diag = np.diag(M).copy()
        mpc.d = self.d_model.copy() if self.o.observer else mpc.d
        if self.ws is None:
            X, U = mpc.initial_guess(self.i)
            active = None
        else:                      # the last usable solution, shifted to this step
            X, U, active, i_ws, d_ws = self.ws
            # the plan's torques re-expressed under the new disturbance estimate: U + d, what the
            # model applies, stays as planned, so the warm start keeps its gaps closed (with U
            # itself every node's gap moves by B (d - d_ws): on the Panda under a 5 kg payload a
            # jump of the estimate left gaps of 1.85 at all 20 nodes and DAQP at its cap)
            U = U + (d_ws - mpc.d)
            for j in range(i_ws, self.i):
                X, U = mpc.shifted(X, U, j)
                active = mpc.shifted_active(active)
        sol = mpc.solve(x, self.i, X, U, active)
        usable = sol.status != "fallback"
        # a failed step starts the next one from the reference, not from a warm start that led there
        self.ws = (sol.X, sol.U, sol.active, self.i, mpc.d.copy()) if usable else None
        rep = {"step": self.i, "t": self.sample * self.dt, "status": sol.status, "late": sol.late,
               "iterations": sol.iterations, "qp_iterations": sol.qp_iterations, "cpu_ms": 1e3 * sol.cpu_s,
               "wall_ms": 1e3 * sol.wall_s, "slack": sol.slack, "d_hat": self.d_hat.tolist()}
        if usable and not sol.late:
            # the model's state at the next re-solve under the plan's first torque (the plant's
            # later state against it: the prediction error)
            rep["predicted_next"] = mpc.predict(x, sol.U[0]).tolist()
            self.X, self.U = sol.X, sol.U
            self.plan_x0, self.plan_age, self.fallbacks = x.copy(), 0, 0
            self.mode = "mpc"
            self.d_at_solve = mpc.d.copy()
        else:
            # no plan for this interval in time: the previous plan one interval on, then the brake
            self.fallbacks += 1
            if self.X is not None and self.fallbacks <= self.o.max_fallback and self.plan_age + 1 < len(self.U):
                self.plan_age += 1
                self.mode = "shifted plan"
            else:
                self.mode = "brake"
        rep["mode"] = self.mode
        self.reports.append(rep)
        self.i += 1

    def control(self, t, x):
        n, mpc = self.n, self.mpc
        x = self._observe(np.asarray(x, float))
        k = self.sample % self.per_step
        if k == 0:
            self._resolve(x)
        s = k / self.per_step
        tau_max = mpc.tau_max
        if self.mode == "brake":
            a = -x[n:] / self.o.brake_time
            u = mpc.lib.tau(x[:n], x[n:], a) - self.d_hat
        else:
            j = self.plan_age
            start = self.plan_x0 if j == 0 else self.X[j - 1]
            u = self.U[j] + (self.d_at_solve - self.d_hat if self.o.observer else 0.0)
            if self.o.feedback:
                q_ref, v_ref = _hermite(start, self.X[j], s, mpc.h, n)
                acc = self.kp * (q_ref - x[:n]) + self.kd * (v_ref - x[n:])
                u = u + mpc.lib.tau(x[:n], np.zeros(n), acc) - mpc.lib.tau(x[:n], np.zeros(n), np.zeros(n))
        u = np.clip(u, -tau_max, tau_max)
        if self.o.guard:
            u = self._guard(x, u)
        self.prev = (x, u)
        self.sample += 1
        return u

    def _guard(self, x, u):
        """The limit guard (module docstring): ``u`` where it keeps every limit, else the command
        with the offending joints' accelerations replaced."""
        n, mpc, o, dt = self.n, self.mpc, self.o, self.dt
        q, v = x[:n], x[n:]
        lim = mpc.limits
        vmax, lo, hi = lim.array("qd_max"), lim.array("q_lo"), lim.array("q_hi")
        d = self.d_hat if o.observer else np.zeros(n)
        a = mpc.lib.fd(q, v, u + d)                         # what the command does, by the model
        v1 = v + dt * a
        bias = mpc.lib.tau(q, v, np.zeros(n)) - d           # the torque that holds the speed
        m_diag = self.m_diag if self.m_diag is not None else np.array(
            [mpc.lib.tau(q, np.zeros(n), e)[j] - mpc.lib.tau(q, np.zeros(n), np.zeros(n))[j]
             for j, e in enumerate(np.eye(n))])
        decel = np.maximum(0.5 * (mpc.tau_max - np.abs(bias)) / m_diag, 1e-3)
        towards = np.where(v1 >= 0, hi - q, q - lo) - o.guard_margin   # room left in the direction of motion
        # the speed from which the joint still stops in that room (and one sample's travel)
        v_stop = np.sqrt(2 * decel * np.maximum(towards - np.abs(v1) * (dt + o.guard_time), 0.0))
        past = (q > hi) | (q < lo)
        hot = (np.abs(v1) > vmax) | (np.abs(v1) > v_stop) | past
        if not hot.any():
            self.guarded = 0
            return u
        target = np.sign(v1) * np.minimum(np.minimum(np.abs(v1), (1 - o.guard_speed) * vmax), v_stop)
        # past a position limit: back inside at a tenth of the speed limit
        target = np.where(q > hi, -0.1 * vmax, np.where(q < lo, 0.1 * vmax, target))
        da = np.where(hot, (target - v) / o.guard_time - a, 0.0)
        self.guarded = int(sum(1 << j for j in np.flatnonzero(hot)))
        # the correction's torque M da, scaled as a whole into the torque limits (clipped joint by
        # joint it would lose its direction: on the LWR, whose joints 1 and 3 are nearly parallel
        # near q2 = 0, a clipped correction of joint 3 drove joint 1 on to 36 times its speed limit)
        z = np.zeros(n)
        dtau = mpc.lib.tau(q, z, da) - mpc.lib.tau(q, z, z)
        room = np.where(dtau > 0, mpc.tau_max - u, -mpc.tau_max - u)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(dtau != 0, room / dtau, np.inf)
        alpha = float(np.clip(np.min(scale), 0.0, 1.0))
        return np.clip(u + alpha * dtau, -mpc.tau_max, mpc.tau_max)


def simulate(controller: Controller, plant, x0, duration: float) -> LoopLog:
    """Run the loop for ``duration`` seconds from the true state x0, with BLAS on one thread
    (a re-solve of a few milliseconds gains nothing from a second one, whose spinning doubled
    its CPU time on a 2-core machine and, on a loaded one, made every step miss its budget) and
    Python's cyclic garbage collector paused (a full collection in a process holding the solvers
    took 31 ms, measured, three budgets' worth, and landed in a re-solve: the control benchmark's
    two p99s over 10 ms were single-iteration steps of 14 and 33 ms; reference counting still
    frees everything but cycles, which the collector takes when it resumes after the loop)."""
    import gc
    from threadpoolctl import threadpool_limits
    collecting = gc.isenabled()
    gc.disable()
    try:
        with threadpool_limits(1):
            return _simulate(controller, plant, x0, duration)
    finally:
        if collecting:
            gc.enable()


def _simulate(controller, plant, x0, duration):
    log = LoopLog()
    x = np.asarray(x0, float)
    dt = controller.dt
    steps = int(round(duration / dt))
    for s in range(steps):
        t = s * dt
        u = controller.control(t, plant.measure(x, t))
        log.t.append(t)
        log.tau.append(u)
        log.d_hat.append(controller.d_hat.copy())
        log.guard.append(controller.guarded)
        x = plant.step(x, u, dt, t)
        log.x.append(x)
    log.steps = controller.reports
    return log
