"""Figures and Markdown of an identification run: measured against predicted joint torques per
joint along the validation motion (the kind of figure of the identification paper's Fig. 4),
residuals, and a table of the numbers.

Example:

>>> torque_figure("fig.png", t, tau, {"identified": predicted}, "validation")   # doctest: +SKIP
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def torque_figure(path: str | Path, t: np.ndarray, measured: np.ndarray, predicted: dict[str, np.ndarray],
                  title: str) -> Path:
    """One PNG: a panel per joint with the measured torque and every prediction, and under
    each the residual ``measured - prediction``; returns the path."""
    import matplotlib
    matplotlib.use("Agg")   # files only, never a display
    import matplotlib.pyplot as plt

    n = measured.shape[1]
    fig, axes = plt.subplots(n, 2, figsize=(13, 1.9 * n), sharex=True, squeeze=False,
                             gridspec_kw={"width_ratios": [3, 2]})
    for j in range(n):
        ax, res = axes[j]
        ax.plot(t, measured[:, j], color="black", lw=0.8, label="measured")
        for k, (name, tau) in enumerate(predicted.items()):
            color = f"C{k}"
            ax.plot(t, tau[:, j], color=color, lw=0.8, label=name)
            rms = float(np.sqrt(np.mean((measured[:, j] - tau[:, j]) ** 2)))
            res.plot(t, measured[:, j] - tau[:, j], color=color, lw=0.6, label=f"{name}: RMS {rms:.3g} N m")
        ax.set_ylabel(f"tau{j + 1} [N m]")
        res.axhline(0, color="grey", lw=0.5)
        res.legend(fontsize=7, loc="upper right")
        if j == 0:
            ax.legend(fontsize=7, loc="upper right", ncol=len(predicted) + 1)
            ax.set_title(title, fontsize=9)
            res.set_title("residual (measured - predicted) [N m]", fontsize=9)
    axes[-1][0].set_xlabel("t [s]")
    axes[-1][1].set_xlabel("t [s]")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def rms_table(rows: dict[str, list[float]], n: int) -> str:
    """Markdown table: one row per model/data set, RMS per joint and summed (N m).

    >>> print(rms_table({"a": [1.0, 2.0]}, 2))
    | | joint 1 | joint 2 | sum |
    |---|---|---|---|
    | a | 1 | 2 | 3 |
    """
    head = "| | " + " | ".join(f"joint {j + 1}" for j in range(n)) + " | sum |"
    lines = [head, "|" + "---|" * (n + 2)]
    for label, values in rows.items():
        lines.append(f"| {label} | " + " | ".join(f"{v:.3g}" for v in values) + f" | {sum(values):.3g} |")
    return "\n".join(lines)
