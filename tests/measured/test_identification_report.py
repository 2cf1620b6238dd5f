"""The identification report of :mod:`kindyngen.measured.identification_report` on a known
small result (three joints, a measured torque and two predictions made here with numpy): the
RMS table's numbers and sums equal numpy's RMS of ``measured - predicted`` per joint, and
the figure has a panel pair per joint whose curves are the inputs and whose residual legends
quote numpy's RMS."""
from __future__ import annotations

import re

import numpy as np
import pytest

from kindyngen.measured.identification_report import rms_table, torque_figure

matplotlib = pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def result():
    rng = np.random.default_rng(26)
    t = np.linspace(0.0, 2.0, 401)
    measured = np.column_stack([np.sin(2 * t), 3 * np.cos(t), 0.5 * t]) + 0.01 * rng.normal(size=(401, 3))
    predicted = {"identified": measured + rng.normal(scale=[0.02, 0.1, 0.5], size=(401, 3)),
                 "nominal": measured + np.array([0.3, -1.0, 2.0])}
    rms = {name: np.sqrt(np.mean((measured - tau) ** 2, axis=0)) for name, tau in predicted.items()}
    return t, measured, predicted, rms


def test_rms_table_numbers_are_the_rms_of_the_residuals(result):
    _, _, _, rms = result
    text = rms_table({name: list(values) for name, values in rms.items()}, 3)
    lines = text.splitlines()
    assert lines[0] == "| | joint 1 | joint 2 | joint 3 | sum |"
    assert lines[1] == "|---|---|---|---|---|"
    assert len(lines) == 2 + len(rms)
    for line, (name, values) in zip(lines[2:], rms.items()):
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[0] == name
        numbers = [float(c) for c in cells[1:]]
        # three significant digits
        assert np.allclose(numbers[:3], values, rtol=5e-3, atol=0)
        assert np.isclose(numbers[3], values.sum(), rtol=5e-3, atol=0)
    # the constant offsets of "nominal" are its RMS exactly
    assert [float(c) for c in lines[3].strip("|").split("|")[1:]] == [0.3, 1.0, 2.0, 3.3]


def test_torque_figure_panels_curves_and_residual_rms(result, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt
    t, measured, predicted, rms = result
    figures = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), close(fig)))
    path = torque_figure(tmp_path / "validation.png", t, measured, predicted, "validation run")
    assert path == tmp_path / "validation.png"
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(header[16:20], "big"), int.from_bytes(header[20:24], "big")
    assert (width, height) == (13 * 90, round(1.9 * 3 * 90))     # figsize (13, 1.9 n) at 90 dpi

    (fig,) = figures
    axes = np.array(fig.axes).reshape(3, 2)
    assert axes[0, 0].get_title() == "validation run"
    for j in range(3):
        torque, residual = axes[j]
        lines = torque.get_lines()
        assert [line.get_label() for line in lines] == ["measured", "identified", "nominal"]
        assert np.array_equal(lines[0].get_ydata(), measured[:, j])
        for line, tau in zip(lines[1:], predicted.values()):
            assert np.array_equal(line.get_xdata(), t) and np.array_equal(line.get_ydata(), tau[:, j])
        curves = [line for line in residual.get_lines() if line.get_label().endswith("N m")]
        for line, (name, tau) in zip(curves, predicted.items()):
            assert np.allclose(line.get_ydata(), measured[:, j] - tau[:, j], rtol=0, atol=1e-15)
            label = re.fullmatch(rf"{name}: RMS (\S+) N m", line.get_label())
            assert label and np.isclose(float(label.group(1)), rms[name][j], rtol=5e-3, atol=0)
        assert [t.get_text() for t in residual.get_legend().get_texts()] == [c.get_label() for c in curves]
