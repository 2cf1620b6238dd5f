"""A log checked against the robot it claims to record: positions inside the description's joint
limits (angles in degrees caught by name), torques, given velocities and accelerations below
stated physical bounds, time stamps in seconds.  A log that fails is not a measurement of this
robot in the units the commands read: a :class:`kindyngen.measured.log_reading.LogError` names
the file, the column, the row and the reason.

One function, :func:`check_samples`, does it for every command: the readers that hand the
commands their samples call it on each chunk as it is read
(:func:`kindyngen.measured.log_formats.iter_chunks`) and on a whole log
(:func:`kindyngen.measured.log_formats.read_any`) when given the robot's :class:`LogBounds`, so
``identify`` (streamed and in memory) and ``discover`` refuse the same logs with the same words.
Non-finite values, time going backwards, column names and the joint count are the readers' own
checks (:mod:`kindyngen.measured.log_reading`); what is checked here needs the robot.

The bounds (each a module constant, in the log's units: rad, m, N m, N, s):

* **positions** of a joint with limits: at most :data:`POSITION_MARGIN_RAD` (revolute) or
  :data:`POSITION_MARGIN_M` (prismatic) beyond them, or :data:`POSITION_MARGIN_FRACTION` of the
  joint's range if that is larger (an encoder offset, a joint pushed a little past a soft limit,
  filter ringing stay inside; angles in degrees do not); a joint without limits: within
  +-:data:`POSITION_MAX_RAD` rad (+-:data:`POSITION_MAX_M` m).
* **torques**: within +-:data:`TORQUE_MAX` N m (N for a prismatic joint).  The description
  format holds no effort limits, so the bound is absolute: ten times the largest joint torque of
  any robot built (the second axis of a 2.3 t payload arm carries about 1e5 N m).
* **velocities** given in the log: within +-:data:`VELOCITY_MAX_RAD_S` rad/s (about 9500 rpm:
  no robot motor turns faster, and a joint turns at most as fast as its motor) or
  +-:data:`VELOCITY_MAX_M_S` m/s (ten times the fastest linear motors).
* **accelerations** given in the log: within +-:data:`ACCELERATION_MAX_RAD_S2` rad/s^2 (that
  velocity bound reached in 10 ms) or +-:data:`ACCELERATION_MAX_M_S2` m/s^2 (1000 g).
* **time step**: the median step at most :data:`MAX_TIME_STEP_S` (10 Hz): slower logs cannot be
  differentiated for dynamics, and a log stamped in milliseconds (or micro-, nanoseconds) reads
  as one; the message says which unit the stamps look like.

Velocities and accelerations the commands derive from the positions are not checked: they follow
from positions inside the limits on a clock in seconds.

>>> import numpy as np
>>> from kindyngen.readers.yaml_description import load_robot
>>> bounds = log_bounds(load_robot("robots/panda.yaml"))
>>> t = np.arange(60) * 0.01
>>> check_samples("run.csv", bounds, t, np.zeros((60, 7)), np.zeros((60, 7)))      # passes
>>> tau = np.zeros((60, 7)); tau[4, 2] = 1e300
>>> check_samples("run.csv", bounds, t, np.zeros((60, 7)), tau, row="data row")
Traceback (most recent call last):
...
kindyngen.measured.log_reading.LogError: run.csv: field 'tau3': 1e+300 N m at data row 5 (t = 0.04 s) is beyond the bound |tau| <= 1e+06 N m, more than any robot joint exerts (torques must be in N m)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .log_reading import MIN_SAMPLES, LogError, number_text

__all__ = ["LogBounds", "JointRange", "log_bounds", "check_samples", "check_raw_log"]

#: A position further than this beyond a revolute joint's limits (rad) ...
POSITION_MARGIN_RAD = 0.35
#: ... or a prismatic joint's (m) ...
POSITION_MARGIN_M = 0.05
#: ... or than this fraction of the joint's range, if larger, is not a measurement of this robot.
POSITION_MARGIN_FRACTION = 0.1
#: Positions of joints without limits (continuous joints, unwrapped over many turns) stay within these.
POSITION_MAX_RAD = 1e6
POSITION_MAX_M = 1e3
#: Joint torques (N m) and forces (N) stay within this.
TORQUE_MAX = 1e6
#: Given joint velocities stay within these (rad/s, m/s) ...
VELOCITY_MAX_RAD_S = 1e3
VELOCITY_MAX_M_S = 1e2
#: ... and given accelerations within these (rad/s^2, m/s^2).
ACCELERATION_MAX_RAD_S2 = 1e5
ACCELERATION_MAX_M_S2 = 1e4
#: The median time step is at most this (s): 10 Hz.
MAX_TIME_STEP_S = 0.1

#: per joint kind: units of position, velocity, acceleration, torque
_UNITS = {"revolute": ("rad", "rad/s", "rad/s^2", "N m"), "prismatic": ("m", "m/s", "m/s^2", "N")}
_SPEED_BOUNDS = {"revolute": (VELOCITY_MAX_RAD_S, ACCELERATION_MAX_RAD_S2),
                 "prismatic": (VELOCITY_MAX_M_S, ACCELERATION_MAX_M_S2)}


@dataclass(frozen=True)
class JointRange:
    """What a log's columns of one joint are checked against: its kind and limits (+-inf: none)."""

    kind: str
    lower: float
    upper: float

    @property
    def limited(self) -> bool:
        return math.isfinite(self.lower) and math.isfinite(self.upper) and self.upper > self.lower

    @property
    def margin(self) -> float:
        """How far beyond the limits a position may lie (rad or m).

        >>> JointRange("revolute", -1.0, 1.0).margin, JointRange("revolute", -10.0, 10.0).margin
        (0.35, 2.0)
        """
        floor = POSITION_MARGIN_RAD if self.kind == "revolute" else POSITION_MARGIN_M
        return max(floor, POSITION_MARGIN_FRACTION * (self.upper - self.lower))


@dataclass(frozen=True)
class LogBounds:
    """The robot as a log's checks need it (plain numbers, so that process pools and Dask
    workers can carry it): one :class:`JointRange` per joint, in the description's order."""

    joints: tuple[JointRange, ...]

    @property
    def n(self) -> int:
        return len(self.joints)


def log_bounds(model) -> LogBounds:
    """The :class:`LogBounds` of a robot description (its joints' kinds and limits).

    >>> from kindyngen.readers.yaml_description import load_robot
    >>> log_bounds(load_robot("robots/panda.yaml")).joints[3]
    JointRange(kind='revolute', lower=-3.0718, upper=-0.0698)
    """
    return LogBounds(tuple(JointRange(joint.kind, float(joint.lower), float(joint.upper)) for joint in model.joints))


def _where(row: str, first_row: int, t: np.ndarray, i: int) -> str:
    return f"{row} {first_row + i + 1} (t = {number_text(t[i])} s)"


def _worst(a: np.ndarray, bad: np.ndarray) -> tuple[int, int]:
    """(row, column) of the largest magnitude among the ``bad`` entries, in the first bad column."""
    j = int(np.flatnonzero(bad.any(axis=0))[0])
    rows = np.flatnonzero(bad[:, j])
    return int(rows[np.argmax(np.abs(a[rows, j]))]), j


def _check_positions(source, bounds, t, q, first_row, row) -> None:
    for j, joint in enumerate(bounds.joints):
        unit = _UNITS[joint.kind][0]
        column = q[:, j]
        if joint.limited:
            margin = joint.margin
            bad = np.flatnonzero((column < joint.lower - margin) | (column > joint.upper + margin))
        else:
            margin = POSITION_MAX_RAD if joint.kind == "revolute" else POSITION_MAX_M
            bad = np.flatnonzero(np.abs(column) > margin)
        if not bad.size:
            continue
        i = int(bad[np.argmax(np.abs(column[bad]))])
        largest = float(np.abs(column).max())
        hint = ""
        if joint.kind == "revolute" and largest > 2 * math.pi:
            hint = (f"; values up to {largest:.4g} look like degrees: the log must give angles in radians "
                    f"(multiply by pi/180 = 0.01745)")
        elif joint.kind == "prismatic" and joint.limited and largest > 100 * max(abs(joint.lower), abs(joint.upper)):
            hint = (f"; values up to {largest:.4g} look like millimetres: the log must give positions in metres "
                    f"(multiply by 0.001)")
        if joint.limited:
            reason = (f"is far outside the joint limits [{joint.lower:.4g}, {joint.upper:.4g}] {unit} of the "
                      f"description (more than {margin:.3g} {unit} beyond)")
        else:
            reason = f"is beyond the bound |q| <= {margin:g} {unit} of a joint without limits"
        raise LogError(source, f"q{j + 1}", f"{column[i]:.4g} {unit} at {_where(row, first_row, t, i)} {reason}{hint}")


def _check_magnitudes(source, bounds, t, channel: str, a, first_row, row) -> None:
    """Torques (``tau``), given velocities (``qd``) or accelerations (``qdd``) within their bounds."""
    kinds = [joint.kind for joint in bounds.joints]
    if channel == "tau":
        limit = np.full(len(kinds), TORQUE_MAX)
    else:
        limit = np.array([_SPEED_BOUNDS[kind][0 if channel == "qd" else 1] for kind in kinds])
    bad = np.abs(a) > limit
    if not bad.any():
        return
    i, j = _worst(a, bad)
    unit = _UNITS[kinds[j]][{"qd": 1, "qdd": 2, "tau": 3}[channel]]
    why, what = {"tau": ("more than any robot joint exerts", "torques"),
                 "qd": ("faster than any robot motor turns", "velocities"),
                 "qdd": ("more than any robot joint reaches", "accelerations")}[channel]
    raise LogError(source, f"{channel}{j + 1}", f"{a[i, j]:.4g} {unit} at {_where(row, first_row, t, i)} is beyond "
                                                f"the bound |{channel}| <= {limit[j]:g} {unit}, {why} ({what} must "
                                                f"be in {unit})")


def _check_time_step(source, t) -> None:
    steps = np.diff(t)
    steps = steps[steps > 0]
    if len(steps) < MIN_SAMPLES - 1:      # a log's short last chunk: its earlier chunks were checked
        return
    step = float(np.median(steps))
    if step <= MAX_TIME_STEP_S:
        return
    unit = ("milliseconds", "0.001") if step < 500 else ("microseconds", "1e-6") if step < 5e5 else \
        ("nanoseconds", "1e-9")
    raise LogError(source, "t", f"the median time step is {step:.4g} s ({1 / step:.3g} Hz): slower than "
                                f"{1 / MAX_TIME_STEP_S:g} Hz, too slow to differentiate for dynamics; time stamps "
                                f"must be in seconds (these look like {unit[0]}: multiply by {unit[1]})")


def check_samples(source: str, bounds: LogBounds, t, q, tau, qd=None, qdd=None, first_row: int = 0,
                  row: str = "row") -> None:
    """Refuse samples that cannot be this robot's measurement in the commands' units (see the
    module text): a :class:`LogError` naming ``source``, the column (``q3``, ``tau3``, ``qd3``,
    ``qdd3``, ``t``), the ``row`` (counted from 1 over the whole log: ``first_row`` is the 0-based
    row of the first sample given) with its time stamp, the value, the bound and what to do.
    Positions come first (a log in degrees is refused as such, whatever else it holds), then
    torques, velocities, accelerations, and the time step.  The arrays are finite (the readers'
    check comes first) and shaped ``(m,)`` and ``(m, bounds.n)``."""
    t = np.asarray(t, float)
    _check_positions(source, bounds, t, np.asarray(q, float), first_row, row)
    for channel, a in (("tau", tau), ("qd", qd), ("qdd", qdd)):
        if a is not None:
            _check_magnitudes(source, bounds, t, channel, np.asarray(a, float), first_row, row)
    _check_time_step(source, t)


def check_raw_log(raw, bounds: LogBounds, row: str = "row") -> None:
    """:func:`check_samples` on a whole :class:`kindyngen.measured.log_reading.RawLog`."""
    check_samples(raw.source, bounds, raw.t, raw.q, raw.tau, raw.qd, raw.qdd, 0, row)
