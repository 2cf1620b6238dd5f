"""discover's fit at the model (kindyngen.measured.discovery._converge) on a one-coefficient
nonlinear reading, y = exp(a x), whose Gauss-Newton steps overshoot from a far start: the
values returned are a model a pass evaluated and found no worse than the start (or the converged
one), never an untried step. Before, the step after the last pass was returned as it was: on the
real Panda log model.yaml then read 15.8 N m summed over the joints of the held-out part where
the fit said 0.75."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from kindyngen.measured import discovery

X = np.linspace(0.0, 2.0, 41)
TRUE_A = 0.4
Y = np.exp(TRUE_A * X)


def rss_at(a: float) -> float:
    return float(np.sum((Y - np.exp(a * X)) ** 2))


class Problem:
    """The linearisation of the reading at ``a``: one column, ``d exp(a x) / d a``."""

    def __init__(self, a):
        self.a, self.p, self.n = a, 1, 1
        self.layout = SimpleNamespace(slices={"a": np.array([0])})
        self.J = X * np.exp(a * X)
        self.r = Y - np.exp(a * X)

    def joint_rss(self, coef):
        return np.array([np.sum((self.r - self.J * coef[0]) ** 2)])

    def fit(self, idx, damping=0.0, fixed=None):
        JJ = float(self.J @ self.J)
        step = float(self.J @ self.r) / (JJ * (1.0 + damping))     # damping on the scaled diagonal
        return {"step": step, "rss": float(self.joint_rss(np.array([step]))[0]), "links": None}


class Fitter:
    def __init__(self):
        self.evaluated = []

    def at(self, values, blocks):
        self.evaluated.append(values["a"])
        return None, None, Problem(values["a"]), {}

    @staticmethod
    def stepped(values, problem, fit, blocks):
        return {"a": values["a"] + fit["step"]}


BLOCKS = [SimpleNamespace(names=("a",), key="a")]


@pytest.mark.parametrize("passes", [2, 3, 5])
def test_an_unconverged_fit_returns_a_model_it_evaluated_and_no_worse_than_the_start(monkeypatch, passes):
    monkeypatch.setattr(discovery, "GN_PASSES", passes)
    fitter, notes = Fitter(), []
    start = {"a": 3.0}            # undamped steps creep down by about 0.5 a pass: far from converged
    values = discovery._converge(fitter, start, BLOCKS, lambda text: None, notes, nonlinear=True)[4]
    assert values["a"] in fitter.evaluated, (values, fitter.evaluated)
    assert rss_at(values["a"]) == min(rss_at(a) for a in fitter.evaluated) <= rss_at(start["a"])
    assert any("did not converge" in note for note in notes), notes


def test_a_converged_fit_reaches_the_truth():
    fitter, notes = Fitter(), []
    values = discovery._converge(fitter, {"a": 1.0}, BLOCKS, lambda text: None, notes, nonlinear=True)[4]
    assert values["a"] == pytest.approx(TRUE_A, abs=1e-3)
    assert any("fitted at the model itself" in note for note in notes), notes
