"""``discover``'s reports: ``report.md`` (figures as PNG files beside it) and ``report.html``
(one file, the figures embedded as base64 PNG, every text from the user or the data escaped).

Figures (matplotlib, files only): the residual per joint on the held-out data before (nominal)
and after (model.yaml) over time, against velocity and against position (``residuals.png``);
the held-out RMS per joint after each step of the selection beside the noise floor
(``steps.png``); measured and predicted torques (``heldout_torques.png``).

Example:

>>> write_reports(result, result_document(result), "out")          # doctest: +SKIP
"""
from __future__ import annotations

import base64
import html
import math
from pathlib import Path

import numpy as np

from ..model.user_text import markdown as markdown_text
from .discovery import EXPLAINED_FACTOR
from .identification_report import rms_table, torque_figure


def _plt():
    import matplotlib
    matplotlib.use("Agg")        # files only, never a display
    import matplotlib.pyplot as plt
    return plt


def residual_figure(path: Path, result) -> Path:
    """Per joint: the residual of the nominal model and of model.yaml on the held-out data over
    time, against the joint's velocity and against its position."""
    plt = _plt()
    q, qd, _ = result.heldout_motion
    before = result.heldout_tau - result.heldout_nominal
    after = result.heldout_tau - result.heldout_after
    n = before.shape[1]
    fig, axes = plt.subplots(n, 3, figsize=(14, 1.9 * n), squeeze=False)
    for j in range(n):
        for k, (x, label) in enumerate(((result.heldout_t, "t [s]"), (qd[:, j], "qd [rad/s]"),
                                        (q[:, j], "q [rad]"))):
            ax = axes[j][k]
            style = dict(lw=0.6) if k == 0 else dict(ls="none", marker=".", ms=1.2)
            ax.plot(x, before[:, j], color="C3", alpha=0.7, label="nominal", **style)
            ax.plot(x, after[:, j], color="C0", label="model.yaml", **style)
            ax.axhline(0, color="grey", lw=0.5)
            if j == n - 1:
                ax.set_xlabel(label)
            if k == 0:
                ax.set_ylabel(f"r{j + 1} [N m]")
    axes[0][0].legend(fontsize=7, loc="upper right", markerscale=6)
    axes[0][0].set_title("held-out residual (measured - predicted) over time", loc="left", fontsize=9)
    axes[0][1].set_title("against the joint's velocity", loc="left", fontsize=9)
    axes[0][2].set_title("against its position", loc="left", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def steps_figure(path: Path, result) -> Path:
    """Held-out RMS per joint: nominal, after each step (cross-validated), the final fit, the
    held-out data with model.yaml, and the noise floor."""
    plt = _plt()
    d = result.discovery
    bars = [("nominal (cross-validated)", d.rms_before)]
    bars += [(f"+ {s.effect}{'' if s.kept else ' (dropped)'}", s.rms_after) for s in d.steps]
    bars += [("final fit (cross-validated)", d.rms_after), ("model.yaml, held-out data", result.rms_after)]
    n = len(d.rms_before)
    width = 0.8 / len(bars)
    fig, ax = plt.subplots(figsize=(10, 3.6))
    for k, (label, values) in enumerate(bars):
        ax.bar(np.arange(n) + k * width, values, width, label=label)
    centre = np.arange(n) + 0.4 - width / 2
    ax.plot(centre, d.noise_floor, "k_", ms=18, mew=2, label="noise floor")
    ax.plot(centre, EXPLAINED_FACTOR * d.noise_floor, "_", color="grey", ms=18, mew=1,
            label=f"{EXPLAINED_FACTOR:g} x noise floor")
    ax.set_xticks(centre, [f"joint {j + 1}" for j in range(n)])
    ax.set_ylabel("RMS torque error [N m]")
    ax.set_yscale("log")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _figures(result, out: Path) -> dict:
    return {"residuals": residual_figure(out / "residuals.png", result),
            "steps": steps_figure(out / "steps.png", result),
            "torques": torque_figure(out / "heldout_torques.png", result.heldout_t, result.heldout_tau,
                                     {"model.yaml": result.heldout_after, "nominal": result.heldout_nominal},
                                     "held-out data: measured torques, nominal model and model.yaml")}


def _coefficient_lines(doc) -> list[str]:
    """One line per fitted candidate: its values per joint in model.yaml's units."""
    out = []
    for candidate, values in doc["per_joint"].items():
        if isinstance(values, list):
            shown = []
            for i, v in enumerate(values):
                if v is None:
                    continue
                if isinstance(v, dict):
                    shown.append(f"joint {i + 1}: " + ", ".join(f"{k} {x:.4g}" if isinstance(x, float) else f"{k} {x}"
                                                              for k, x in v.items()))
                else:
                    shown.append(f"joint {i + 1}: {v:.4g}")
            out.append((candidate, "; ".join(shown) or "none written"))
        elif candidate == "rigid_bodies":
            out.append((candidate, "the links' inertial parameters (see model.yaml)"))
        else:
            out.append((candidate, ", ".join(f"{k} {v}" for k, v in values.items())))
    return out


def markdown(result, doc, figures) -> str:
    d = result.discovery
    n = len(result.rms_before)
    # the description's and the logs' names (and the preprocessing notes naming a log's keys) are
    # the user's: literal Markdown text
    lines = [f"# Discrepancy between {markdown_text(Path(result.request.robot).name)} and the data", "",
             f"Data: {', '.join(markdown_text(str(path)) for path in result.request.data)}; the last {100 * result.request.holdout:g} % of each "
             f"file's time span is held out ({result.samples['held_out']} samples after filtering); the selection saw "
             f"{result.samples['selection']} samples ({d.folds}-fold time-blocked cross-validation).", "",
             "Preprocessing: " + "; ".join(map(markdown_text, result.preprocessing_notes)) + ".", "",
             "Parallel filtering: every model column is computed from the filtered motion, then the columns and the "
             "*unfiltered* torque pass through the same linear filter and decimation: "
             + ("; ".join(d.filtering) if d.filtering else "none (the data as given)") + ".", "",
             "## Verdict", ""]
    if doc["explained"]:
        lines.append(f"**Explained**: every joint's held-out RMS is within {EXPLAINED_FACTOR:g} x its noise floor.")
    else:
        lines += [f"**Not explained**: the residual left stays above {EXPLAINED_FACTOR:g} x the noise floor (an "
                  f"effect outside the library, or a drift):", ""] + [f"- {w}" for w in doc["unexplained"]]
    lines += ["", f"Named: **{', '.join(d.effects) or 'none'}**."]
    for member, others in d.stand_ins.items():
        lines.append(f"- In model.yaml as a stand-in, not named: {member} (the data cannot tell it from "
                     f"{', '.join(others)}).")
    for group, reason in d.indistinguishable:
        lines.append(f"- Cannot tell apart on this data: {', '.join(group)} ({reason}).")
    lines += ["", rms_table({"nominal, held-out data": list(result.rms_before),
                             "model.yaml, held-out data": list(result.rms_after),
                             "nominal, cross-validated": list(d.rms_before),
                             "final fit, cross-validated": list(d.rms_after),
                             "noise floor": list(d.noise_floor)}, n), "",
              f"Noise floor: {d.noise_method}.", "",
              f"![residuals]({figures['residuals'].name})", "",
              "## How it was decided", "", "Rules:", ""]
    lines += [f"- {k}: {v}" for k, v in doc["rules"].items()]
    lines += ["", "| step | effect | searched | summed held-out MSE fall | kept |", "|---|---|---|---|---|"]
    for k, s in enumerate(d.steps, start=1):
        lines.append(f"| {k} | {s.effect} | {s.detail} | {100 * s.improvement:.3g} % | {'yes' if s.kept else 'no'} |")
    lines += ["", f"![steps]({figures['steps'].name})", "", "## model.yaml", "",
              "Every coefficient in the units the schema defines (the fit itself: the prediction of model.yaml is "
              "the fitted one):", ""]
    lines += [f"- {c}: {text}" for c, text in _coefficient_lines(doc)]
    if doc["not_determined"]:
        lines += ["", "Not determined by the data (not written; the joint keeps the description's default):", ""]
        lines += [f"- {nm} (fitted {v['fitted']:.4g}, not a measurement): {v['reason']}"
                  for nm, v in doc["not_determined"].items()]
    if doc["drift"]:
        lines += ["", "Drifting (a coefficient that changes during the recording):", ""]
        lines += [f"- {v['where']}" for v in doc["drift"].values()]
    lines += ["", f"![held-out torques]({figures['torques'].name})", "", "## Notes", ""]
    lines += [f"- {note}" for note in d.notes]
    return "\n".join(lines) + "\n"


def _img(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}" style="max-width:100%">'


def _table(rows: dict, n: int) -> str:
    head = "".join(f"<th>joint {j + 1}</th>" for j in range(n))
    body = []
    for label, values in rows.items():
        cells = "".join(f"<td>{v:.3g}</td>" if math.isfinite(v) else "<td>-</td>" for v in values)
        body.append(f"<tr><th>{html.escape(label)}</th>{cells}<td>{np.nansum(values):.3g}</td></tr>")
    return f"<table><tr><th></th>{head}<th>sum</th></tr>{''.join(body)}</table>"


def html_report(result, doc, figures) -> str:
    d = result.discovery
    e = html.escape
    n = len(result.rms_before)
    verdict = ("<p class='ok'><b>Explained</b>: every joint's held-out RMS is within "
               f"{EXPLAINED_FACTOR:g} x its noise floor.</p>" if doc["explained"] else
               f"<p class='bad'><b>Not explained</b>: the residual stays above {EXPLAINED_FACTOR:g} x the noise "
               "floor on:</p><ul>" + "".join(f"<li>{e(w)}</li>" for w in doc["unexplained"]) + "</ul>")
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>{e('discover: ' + Path(str(result.request.robot)).name)}</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
        "table{border-collapse:collapse;font-size:90%}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
        ".ok{color:#060}.bad{color:#a00}code{background:#f4f4f4}</style></head><body>",
        f"<h1>{e('Discrepancy between ' + Path(str(result.request.robot)).name + ' and the data')}</h1>",
        f"<p>{e('Data: ' + ', '.join(map(str, result.request.data)))}; the last "
        f"{100 * result.request.holdout:g} % of each file is held out ({result.samples['held_out']} samples after "
        f"filtering); the selection saw {result.samples['selection']} samples.</p>",
        "<h2>Verdict</h2>", verdict,
        f"<p>Named: <b>{e(', '.join(d.effects) or 'none')}</b>.</p>",
    ]
    if d.stand_ins or d.indistinguishable:
        parts.append("<ul>" + "".join(f"<li>{e(member)} is in model.yaml as a stand-in, not named (the data cannot "
                                      f"tell it from {e(', '.join(others))})</li>" for member, others in
                                      d.stand_ins.items())
                     + "".join(f"<li>Cannot tell apart: {e(', '.join(g))} ({e(r)})</li>"
                               for g, r in d.indistinguishable) + "</ul>")
    parts += [
        _table({"nominal, held-out data": list(result.rms_before), "model.yaml, held-out data": list(result.rms_after),
                "nominal, cross-validated": list(d.rms_before), "final fit, cross-validated": list(d.rms_after),
                "noise floor": list(d.noise_floor)}, n),
        f"<p>Noise floor: {e(d.noise_method)}.</p>",
        "<h2>Residual before and after</h2>", _img(figures["residuals"], "residuals"),
        "<h2>Each step's gain</h2>", _img(figures["steps"], "steps"),
        "<table><tr><th>step</th><th>effect</th><th>searched</th><th>summed held-out MSE fall</th><th>kept</th></tr>"
        + "".join(f"<tr><td>{k}</td><td>{e(s.effect)}</td><td>{e(s.detail)}</td><td>{100 * s.improvement:.3g} %</td>"
                  f"<td>{'yes' if s.kept else 'no'}</td></tr>" for k, s in enumerate(d.steps, start=1)) + "</table>",
        "<h3>Rules</h3><ul>" + "".join(f"<li><b>{e(k)}</b>: {e(v)}</li>" for k, v in doc["rules"].items()) + "</ul>",
        "<h2>model.yaml</h2><ul>" + "".join(f"<li><b>{e(c)}</b>: {e(text)}</li>" for c, text in _coefficient_lines(doc))
        + "</ul>",
    ]
    if doc["not_determined"]:
        parts.append("<p>Not determined by the data (not written):</p><ul>" + "".join(
            f"<li>{e(nm)} (fitted {v['fitted']:.4g}): {e(v['reason'])}</li>" for nm, v in doc["not_determined"].items())
            + "</ul>")
    if doc["drift"]:
        parts.append("<p>Drifting:</p><ul>" + "".join(f"<li>{e(v['where'])}</li>" for v in doc["drift"].values())
                     + "</ul>")
    parts += ["<h2>Held-out torques</h2>", _img(figures["torques"], "held-out torques"),
              "<h2>Notes</h2><ul>" + "".join(f"<li>{e(note)}</li>" for note in d.notes) + "</ul>",
              "<p>Preprocessing: " + e("; ".join(result.preprocessing_notes)) + "</p>", "</body></html>"]
    return "\n".join(parts) + "\n"


def write_reports(result, doc, out: Path) -> None:
    """report.md with its figures beside it, and report.html with them embedded."""
    figures = _figures(result, out)
    (out / "report.md").write_text(markdown(result, doc, figures))
    (out / "report.html").write_text(html_report(result, doc, figures))
