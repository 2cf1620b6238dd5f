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
  Lagrange route's g took 1.2 s CPU at 29 joints and did not finish in 5 minutes at 40), and
* its estimate is at most :data:`CPU_LIMIT_S` seconds of CPU and :data:`MEMORY_LIMIT_MB` MB of
  peak memory above the process's own.

The measurements (``python -m benchmarks.generation_cost``, results/generation_cost.json,
docs/measurements/trees.md) are CPU seconds on the reference machine (:data:`REFERENCE`); on
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
REFERENCE = "AMD EPYC (Zen 4), 2 vCPU shared with other jobs (load average 6-9), Python 3.11, symengine 0.15"


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
    measured_to: int                 # the largest size measured (beyond: extrapolated)
    failed: int | None               # the size it did not finish at, if any is <= size
    why: str = ""

    @property
    def within_limit(self) -> bool:
        return self.failed is None and self.cpu_s <= CPU_LIMIT_S and self.peak_mb <= MEMORY_LIMIT_MB

    def text(self) -> str:
        """``fd_derivatives 6.5 min, 1.3 GB`` (with how it was obtained where it was not
        interpolated)."""
        out = f"{self.name} {duration(self.cpu_s)}, {memory(self.peak_mb)}"
        if self.failed is not None:
            return f"{self.name}: did not finish at {self.failed} ({self.why})"
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
    if cost is None:                       # not measured: the IK (fixed 7 joints), ...
        return Estimate(name, size, 0.0, 0.0, size, None)
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
COSTS: dict[str, Measured] = {}


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
            cpu, peak = sum(e.cpu_s for e in kept), sum(e.peak_mb for e in kept)
            out.append(f"{robot}: {self.size} degrees of freedom; estimated CPU time and peak memory of each "
                       f"function derived ({MODEL_TEXT}): " + "; ".join(e.text() for e in kept)
                       + f"; all {duration(cpu)}, at most {memory(peak)} above the process's own")
        if self.left_out:
            out.append(f"{robot}: left out above the limits of {CPU_LIMIT_S:.0f} s CPU and {memory(MEMORY_LIMIT_MB)} per "
                       f"function: " + "; ".join(e.text() for e in self.left_out)
                       + " (ask for them with --functions NAME --allow-large)")
        return out


MODEL_TEXT = "measured on chains and trees on the reference machine, docs/reference/cli.md 'Large robots'"


def plan(model, names, asked: bool, allow_large: bool = False) -> Plan:
    """The :class:`Plan` of deriving ``names`` (applicable functions of ``model``, in output
    order). Above its limit a function is left out, or, when ``asked`` (named by the user),
    refused with :class:`LimitError` naming its estimate and ``--allow-large``; with
    ``allow_large`` nothing is left out or refused.

    >>> from kindyngen.readers.yaml_description import load_robot
    >>> p = plan(load_robot("robots/lwr4.yaml"), ("fk_hom", "S"), asked=False)
    >>> p.names, p.left_out, p.notes("lwr4")
    (('fk_hom', 'S'), (), [])
    """
    size, tree = size_of(model), uses_tree_route(model)
    estimates = tuple(estimate(name, size, tree) for name in names)
    above = tuple(e for e in estimates if not e.within_limit) if not allow_large else ()
    if above and asked:
        raise LimitError(f"{model.name}: above the limits of {CPU_LIMIT_S:.0f} s CPU and {memory(MEMORY_LIMIT_MB)} "
                         f"per function at {size} degrees of freedom ({MODEL_TEXT}): "
                         + "; ".join(e.text() for e in above)
                         + "; pass --allow-large to derive anyway, or leave them out of the list of functions")
    left = {e.name for e in above}
    return Plan(size, tuple(n for n in names if n not in left), estimates, above)
