"""How much work a run is, said before it starts: per function, the CPU time and the peak
memory of deriving and optimising it, measured on chains (and, for the derivatives of a branched
tree or a floating base, on trees) of growing size; the estimate at a robot's size; and the
limit above which a function is left out of a run (or refused, when it is asked for by name)
unless the user lifts it.

The model (docs/reference/cli.md, "Large robots"): a function's cost at size n (n = nv, the
velocity coordinates: the joints, plus 6 for a floating base) is interpolated between the
sizes it was measured at as a power law (straight on log-log axes), and extrapolated beyond
the largest with the power of the last two sizes (at least 1: a size never gets cheaper).
A function is within its limit at n when

* it did not fail to finish at a size <= n (some grow by far more than any power law: the
  Lagrange route's g took 1.2 s CPU at 29 joints and did not finish in 90 s at 40), and
* its estimate is at most :data:`CPU_LIMIT_S` seconds of CPU and :data:`MEMORY_LIMIT_MB` MB of
  peak memory above the process's own.

How far off that can be (``python -m benchmarks.generation_cost --table``: each measurement
against the estimate from the smaller sizes alone, 27 cases of 1 s CPU or more): CPU 0.77 to
2.4 times the estimate, median 1.14, except Y_g, 13 times at 40 joints (2.2 s at 29, 88 s at
40); peak memory 0.53 to 1.47 times (26 cases of 20 MB or more). Beyond the largest size
measured (40 joints, 38 for a tree's derivatives) a jump like Y_g's is not foreseen: running
out of memory is then still an error naming the function (:class:`GenerationMemoryError`), a
long CPU time is not.

The measurements (``python -m benchmarks.generation_cost``, results/generation_cost.json,
docs/reference/cli.md "Large robots") are CPU seconds on the reference machine (:data:`REFERENCE`); on
a faster or idle one a run takes less. The estimate is printed from :data:`ESTIMATE_FROM`
degrees of freedom on.

>>> e = estimate("M", 40)
>>> e.within_limit, e.cpu_s < CPU_LIMIT_S
(True, True)
>>> estimate("S", 40).within_limit
False
"""
from __future__ import annotations

import math
from dataclasses import dataclass

CPU_LIMIT_S = 60.0
"""CPU seconds (reference machine) a function may be estimated to take and still be derived by default."""
MEMORY_LIMIT_MB = 2048.0
"""Peak memory (MB above the process's own) a function may be estimated to need by default."""
ESTIMATE_FROM = 15
"""Degrees of freedom from which a run prints its estimate (the shipped arms have 7, the G1 35)."""
REFERENCE = "AMD EPYC, 2 vCPU shared with other jobs (load average 1.6-3.8), Python 3.11, symengine 0.15"


@dataclass(frozen=True)
class Measured:
    """One function's measured cost: ``sizes`` (nv), CPU seconds of deriving and optimising
    it at each, and the growth of the process's peak RSS over its size before (MB); ``failed``:
    the size at which it did not finish (``why``), None if it always did."""

    sizes: tuple
    cpu_s: tuple
    peak_mb: tuple
    failed: int | None = None
    why: str = ""


@dataclass(frozen=True)
class Estimate:
    """A function's estimated cost at ``size`` (nv), and whether it is within the limits."""

    name: str
    size: int
    cpu_s: float
    peak_mb: float
    measured_to: int | None          # the largest size measured (beyond: extrapolated); None: not measured
    failed: int | None               # the size it did not finish at, if any is <= size
    why: str = ""

    @property
    def within_limit(self) -> bool:
        return self.failed is None and self.cpu_s <= CPU_LIMIT_S and self.peak_mb <= MEMORY_LIMIT_MB

    def text(self) -> str:
        """``fd_derivatives 6.5 min, 1.3 GB`` (with how it was obtained where it was not
        interpolated).

        >>> Estimate("M", 40, 4.2, 35.0, 29, None).text(), Estimate("S", 40, 0, 0, 29, 29, "more than 90 s CPU").text()
        ('M 4.2 s, 35 MB (extrapolated from 29)', 'S: did not finish at 29 (more than 90 s CPU)')
        """
        if self.failed is not None:
            return f"{self.name}: did not finish at {self.failed} ({self.why})"
        if self.measured_to is None:
            return f"{self.name}: not measured"
        out = f"{self.name} {duration(self.cpu_s)}, {memory(self.peak_mb)}"
        if self.size > self.measured_to:
            out += f" (extrapolated from {self.measured_to})"
        return out


def duration(seconds: float) -> str:
    """
    >>> duration(0.04), duration(42), duration(390), duration(7300)
    ('0.0 s', '42 s', '6.5 min', '2.0 h')
    """
    if seconds < 10:
        return f"{seconds:.1f} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def memory(mb: float) -> str:
    """
    >>> memory(35.2), memory(2500)
    ('35 MB', '2.4 GB')
    """
    return f"{mb:.0f} MB" if mb < 1024 else f"{mb / 1024:.1f} GB"


def power_law(sizes, values, n: float) -> float:
    """``values`` at ``n``: straight on log-log axes between the two measured sizes around it,
    beyond the last with the power of the last two (at least 1), below the first the first
    value. Values are floored at a hundredth (of a second or MB) for the logarithms.

    >>> power_law((10, 20), (1.0, 4.0), 40), power_law((10, 20), (1.0, 4.0), 5)
    (16.0, 1.0)
    """
    if n <= sizes[0] or len(sizes) == 1:
        return values[0] if n <= sizes[0] else values[0] * n / sizes[0]
    k = next((k for k in range(1, len(sizes)) if n <= sizes[k]), len(sizes) - 1)
    (n0, n1), (v0, v1) = sizes[k - 1:k + 1], (max(values[k - 1], 0.01), max(values[k], 0.01))
    power = math.log(v1 / v0) / math.log(n1 / n0)
    if n > sizes[-1]:
        power = max(power, 1.0)
    return v1 * (n / n1) ** power


def estimate(name: str, size: int, tree_route: bool = False) -> Estimate:
    """The cost of function ``name`` at ``size`` degrees of freedom (``tree_route``: the
    world-frame derivatives that a branched tree or a floating base gets)."""
    cost = COSTS.get(f"{name} (world frame)" if tree_route and f"{name} (world frame)" in COSTS else name)
    if cost is None:        # not measured: the closed-form IK (7 joints), a closed mechanism's loop functions
        return Estimate(name, size, 0.0, 0.0, None, None)
    failed = cost.failed if cost.failed is not None and cost.failed <= size else None
    return Estimate(name, size, power_law(cost.sizes, cost.cpu_s, size), power_law(cost.sizes, cost.peak_mb, size),
                    cost.sizes[-1], failed, cost.why)


def size_of(model) -> int:
    """The size the costs are measured against: the joints (mimic joints and the joints of
    closed loops included: their derivations run over the whole tree), plus 6 for a floating
    base; a chain's nv."""
    return model.n + (6 if model.floating_base else 0)


def uses_tree_route(model) -> bool:
    """Whether ``model`` gets the world-frame derivatives (a branched tree or a floating base)."""
    return not model.is_chain


# ----------------------------------------------------------------------------- the measurements
# python -m benchmarks.generation_cost (results/generation_cost.json); chains of nv joints
# written as YAML (joints by origin and axis, axes turning x, y, z), trees with four limbs and
# a floating base (benchmarks.tree_scaling.synthetic_tree). CPU s and MB above the process.
COSTS: dict[str, Measured] = {
    'fk_hom': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.022, 0.033, 0.048, 0.083, 0.144), peak_mb=(0.7, 0.8, 0.9, 0.9, 0.8)),
    'fk_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.057, 0.08, 0.156, 0.184, 0.218), peak_mb=(2.8, 3.0, 3.0, 3.4, 4.1)),
    'jacobian': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.024, 0.044, 0.073, 0.124, 0.199), peak_mb=(0.7, 0.8, 0.8, 1.0, 0.8)),
    'pose_jacobian_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.103, 0.262, 0.412, 0.614, 1.212), peak_mb=(3.3, 5.7, 7.1, 14.4, 17.0)),
    'jacobian_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.119, 0.323, 0.282, 0.356, 0.503), peak_mb=(3.3, 4.2, 5.6, 9.1, 13.1)),
    'M': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.062, 0.241, 0.405, 0.892, 2.062), peak_mb=(1.1, 3.3, 11.3, 21.5, 34.2)),
    'g': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.026, 0.036, 0.052, 0.076, 0.156), peak_mb=(0.7, 0.8, 0.8, 1.0, 0.9)),
    'c': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.072, 0.226, 0.327, 0.493, 0.68), peak_mb=(1.2, 2.4, 4.5, 8.6, 13.2)),
    'S': Measured(sizes=(7, 14), cpu_s=(0.301, 5.024), peak_mb=(6.1, 63.7), failed=20, why='more than 90 s CPU'),
    'tau': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.079, 0.244, 0.322, 0.399, 0.554), peak_mb=(1.3, 2.5, 4.7, 8.8, 13.5)),
    'fd': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.369, 1.106, 1.859, 3.898, 8.762), peak_mb=(7.6, 19.5, 32.4, 60.5, 134.2)),
    'com': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.107, 0.286, 0.563, 1.133, 2.945), peak_mb=(1.4, 6.3, 13.6, 28.6, 45.7)),
    'tau_derivatives': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.676, 3.803, 10.544, 23.529, 50.969), peak_mb=(14.9, 53.9, 87.1, 210.7, 420.2)),
    'fd_derivatives': Measured(sizes=(7, 14), cpu_s=(1.126, 11.386), peak_mb=(20.9, 138.2), failed=20, why='more than 90 s CPU'),
    'fd_derivatives_no_minv': Measured(sizes=(7, 14), cpu_s=(1.289, 13.952), peak_mb=(19.5, 134.7), failed=20, why='more than 90 s CPU'),
    'M_lagrange': Measured(sizes=(7, 14, 20), cpu_s=(0.204, 2.505, 21.822), peak_mb=(3.7, 39.1, 89.8), failed=29, why='more than 90 s CPU'),
    'g_lagrange': Measured(sizes=(7, 14, 20, 29), cpu_s=(0.035, 0.138, 0.264, 1.162), peak_mb=(0.9, 1.6, 4.8, 14.7), failed=40, why='more than 90 s CPU'),
    'c_christoffel': Measured(sizes=(7, 14), cpu_s=(0.272, 4.085), peak_mb=(6.2, 62.3), failed=20, why='more than 90 s CPU'),
    'M_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.107, 0.303, 0.514, 1.098, 2.066), peak_mb=(3.4, 7.6, 15.5, 26.3, 42.2)),
    'g_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.067, 0.098, 0.167, 0.215, 0.367), peak_mb=(2.8, 3.0, 3.0, 3.3, 3.7)),
    'c_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.157, 0.265, 0.354, 0.507, 0.695), peak_mb=(3.3, 5.5, 9.6, 14.6, 16.3)),
    'tau_dq': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.161, 0.263, 0.349, 0.536, 0.816), peak_mb=(3.4, 6.7, 9.9, 14.8, 16.5)),
    'Y_dq': Measured(sizes=(7, 14, 20), cpu_s=(0.497, 1.945, 6.42), peak_mb=(12.0, 44.6, 79.5), failed=29, why='more than 90 s CPU'),
    'Y_g': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.126, 0.547, 0.641, 2.233, 87.88), peak_mb=(5.0, 8.5, 13.9, 24.5, 44.6)),
    'Y_m': Measured(sizes=(7, 14, 20), cpu_s=(0.638, 5.834, 42.295), peak_mb=(6.7, 50.4, 152.0), failed=29, why='more than 90 s CPU'),
    'Y': Measured(sizes=(7, 14, 20, 29, 40), cpu_s=(0.599, 1.197, 2.53, 4.813, 9.285), peak_mb=(7.8, 24.9, 46.3, 87.6, 158.8)),
    'tau_derivatives (world frame)': Measured(sizes=(14, 22, 30, 38), cpu_s=(0.429, 1.313, 2.46, 4.24), peak_mb=(14.7, 31.6, 48.9, 79.7)),
    'fd_derivatives (world frame)': Measured(sizes=(14, 22, 30, 38), cpu_s=(1.492, 4.706, 9.667, 14.334), peak_mb=(43.1, 118.1, 197.8, 314.8)),
    'fd_derivatives_no_minv (world frame)': Measured(sizes=(14, 22, 30, 38), cpu_s=(1.35, 3.826, 7.087, 11.671), peak_mb=(35.7, 89.5, 157.2, 243.3)),
}


# ----------------------------------------------------------------------------- a run's plan

class LimitError(ValueError):
    """A function asked for by name is above its limit (the command line: one ``error:`` line)."""


class GenerationMemoryError(Exception):
    """Deriving or optimising a function needed more memory than the run's limit
    (:func:`kindyngen.codegen.pipeline.build_programs`; the command line: one ``error:`` line)."""


@dataclass(frozen=True)
class Plan:
    """What a run derives: ``names`` in output order; ``estimates`` of every function it was
    to derive (those left out included); ``left_out``: the estimates above the limits of
    functions not asked for by name."""

    size: int
    names: tuple
    estimates: tuple
    left_out: tuple

    def notes(self, robot: str) -> list[str]:
        """What to tell the user before deriving: the estimate (from :data:`ESTIMATE_FROM` degrees
        of freedom on, or whenever something is left out) and what is left out."""
        out = []
        if self.size >= ESTIMATE_FROM or self.left_out:
            kept = [e for e in self.estimates if e.name in self.names]
            cpu, peak = sum(e.cpu_s for e in kept), max((e.peak_mb for e in kept), default=0.0)
            out.append(f"{robot}: {self.size} degrees of freedom; estimated CPU time and peak memory of each "
                       f"function derived ({MODEL_TEXT}): " + "; ".join(e.text() for e in kept)
                       + f"; all {duration(cpu)}, each at most {memory(peak)} above the process's own")
        if self.left_out:
            out.append(f"{robot}: left out above the limits of {CPU_LIMIT_S:.0f} s CPU and {memory(MEMORY_LIMIT_MB)} per "
                       f"function: " + "; ".join(e.text() for e in self.left_out)
                       + " (ask for them with --functions NAME --allow-large)")
        return out


MODEL_TEXT = "measured on chains and trees on the reference machine, docs/reference/cli.md 'Large robots'"


def plan(model, names, asked: bool, allow_large: bool = False, required=()) -> Plan:
    """The :class:`Plan` of deriving ``names`` (applicable functions of ``model``, in output
    order). Above its limit a function is left out, or, when ``asked`` (named by the user) or
    ``required`` (a bundle's member: derived whatever the selection), refused with
    :class:`LimitError` naming its estimate and ``--allow-large``; with ``allow_large`` nothing
    is left out or refused.

    >>> from kindyngen.readers.yaml_description import load_robot
    >>> p = plan(load_robot("robots/lwr4.yaml"), ("fk_hom", "S"), asked=False)
    >>> p.names, p.left_out, p.notes("lwr4")
    (('fk_hom', 'S'), (), [])
    """
    size, tree = size_of(model), uses_tree_route(model)
    estimates = tuple(estimate(name, size, tree) for name in names)
    above = tuple(e for e in estimates if not e.within_limit) if not allow_large else ()
    needed = tuple(estimate(name, size, tree) for name in required if name not in names)
    refused = (above if asked else tuple(e for e in above if e.name in required)) + \
        tuple(e for e in needed if not e.within_limit and not allow_large)
    if refused:
        raise LimitError(f"{model.name}: above the limits of {CPU_LIMIT_S:.0f} s CPU and {memory(MEMORY_LIMIT_MB)} "
                         f"per function at {size} degrees of freedom ({MODEL_TEXT}): "
                         + "; ".join(e.text() for e in refused)
                         + "; pass --allow-large to derive anyway, or leave them out of the list of functions"
                         + (" and bundles" if required else ""))
    left = {e.name for e in above}
    return Plan(size, tuple(n for n in names if n not in left), estimates, above)
