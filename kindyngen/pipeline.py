"""Robot description -> derivations -> CSE and counts -> rendered sources, written to disk.

``generate(model, out_root)`` writes ``out_root/<robot>/`` with ``functions.json`` (the
interface: names, ports, costs), ``opcounts.json``, ``opcounts.md`` and one folder per
language. Output is deterministic: the same description gives the same bytes.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from .catalog import base_params_document, derive_all, undecided_notes
from .interface import manifest
from .optimize import Program, optimize
from .render import RENDERERS
from .report import opcounts_json, opcounts_markdown
from .model import RobotModel
from .tree_model import TreeModel

LANGUAGES = ("c", "python", "casadi", "python_c", "jax", "matlab")


class Progress:
    """One line per step on stderr, redrawn in place on a terminal, with elapsed time."""

    def __init__(self, label: str, total: int, stream=sys.stderr):
        self.label, self.total, self.stream, self.done = label, total, stream, 0
        self.start = time.perf_counter()
        self.tty = stream.isatty()

    def step(self, what: str) -> None:
        self.done += 1
        width = 20
        filled = width * self.done // max(self.total, 1)
        line = (f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} "
                f"{what} ({time.perf_counter() - self.start:.1f} s)")
        self.stream.write(("\r" + line.ljust(100)) if self.tty else line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def build_programs(model: RobotModel | TreeModel, params: str = "numeric", only=None, progress: bool = True) -> list[Program]:
    """Derive and optimise every applicable function of ``model``."""
    functions = derive_all(model, params, only)
    bar = Progress(f"{model.identifier}", len(functions)) if progress else None
    programs = []
    for f in functions:
        programs.append(optimize(f))
        if bar:
            bar.step(f.name)
    if bar:
        bar.close()
    return programs


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def save_casadi_functions(module_source: str, directory: Path) -> None:
    """Build every Function of the rendered CasADi module and save it as <name>.casadi."""
    namespace: dict = {}
    exec(compile(module_source, str(directory / "module"), "exec"), namespace)
    for name, build in namespace["BUILDERS"].items():
        build().save(str(directory / f"{name}.casadi"))


def generate(model: RobotModel | TreeModel, out_root: Path, languages=LANGUAGES, params: str = "numeric",
             progress: bool = True, only=None, trig: str = "kernel") -> Path:
    """Write all generated files of ``model`` (``only``: just the named functions) under
    ``out_root/<robot>/``; returns that folder. ``trig``: one of c_trig.TRIG_MODES."""
    out = Path(out_root) / model.identifier
    programs = build_programs(model, params, only=only, progress=progress)
    _write(out / "functions.json", json.dumps(manifest(model, programs, params, trig), indent=1) + "\n")
    base_params = base_params_document(model)          # None for robots with symbolic lengths
    for note in undecided_notes(model, only) if progress else ():
        print(f"note: {note}", file=sys.stderr)
    if base_params is not None:
        _write(out / "base_params.json", json.dumps(base_params, indent=1) + "\n")
    _write(out / "opcounts.json", json.dumps(opcounts_json(programs), indent=1) + "\n")
    _write(out / "opcounts.md", opcounts_markdown(model.name, programs, model.identifier.startswith("lwr4")))
    for lang in languages:
        options = {"trig": trig} if lang == "c" else {}
        for filename, text in RENDERERS[lang](model, programs, **options).items():
            _write(out / lang / filename, text)
            if lang == "casadi":
                save_casadi_functions(text, out / lang)
    return out
