"""Robot description -> derivations -> CSE and counts -> rendered sources, written to disk.

``generate(model, out_root)`` writes ``out_root/<robot>/`` with ``functions.json`` (the
interface: names, ports, costs, and the list of the files written), ``opcounts.json``,
``opcounts.md`` and one folder per language, replacing an earlier folder whole. Output is
deterministic: the same description gives the same bytes.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from ..algorithms.loop_closure import resolved
from ..algorithms.regressors import base_params_document, undecided_notes
from ..json_text import strict_json
from .bundles import bundle_programs, requested
from .catalog import derive_all, derived_names, mimic_notes, wants_ik_dls
from .interface import listed_files, manifest
from .optimize import Program, optimize
from .render import RENDERERS, casadi_builders
from .count_report import opcounts_json, opcounts_markdown
from ..model.robot_model import RobotModel
from ..output_folder import replace_folder

LANGUAGES = ("c", "python", "casadi", "python_c", "jax", "matlab")


class Progress:
    """One line per step on stderr, redrawn in place on a terminal, with elapsed time."""

    def __init__(self, label: str, total: int, stream=None):
        # sys.stderr looked up per instance, not bound at import: a redirected or replaced
        # stderr (a caller's capture, a test's) is the one written to
        stream = sys.stderr if stream is None else stream
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


def build_programs(model: RobotModel, params: str = "numeric", only=None, progress: bool = True,
                   scalar: str = "double", bundles=()) -> list[Program]:
    """Derive and optimise every applicable function of ``model`` (for C of type ``scalar``),
    then its description's bundles and ``bundles`` (--bundle: kindyngen/codegen/bundles.py)."""
    bundles = requested(model, bundles)          # checked before anything is derived
    functions = derive_all(model, params, only, scalar)
    bar = Progress(f"{model.identifier}", len(functions) + len(bundles)) if progress else None
    programs = []
    for f in functions:
        programs.append(optimize(f))
        if bar:
            bar.step(f.name)
    programs += bundle_programs(model, bundles, programs, params, scalar, bar.step if bar else None)
    if bar:
        bar.close()
    return programs


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")     # names may hold any letters, whatever the locale


def save_casadi_functions(module_source: str, directory: Path) -> None:
    """Build every Function of a CasADi module and save it as <name>.casadi. The pipeline runs
    :func:`kindyngen.codegen.render.casadi_builders`, the module without any user text, never
    the written one: generating runs nothing the description holds."""
    namespace: dict = {}
    exec(compile(module_source, str(directory / "module"), "exec"), namespace)
    for name, build in namespace["BUILDERS"].items():
        build().save(str(directory / f"{name}.casadi"))


def measure_float_error(model, programs, document: dict, trig: str, lanes: bool = True) -> dict:
    """Float C against double C (kindyngen/runtime/float_accuracy.py): ``{name: FloatError}``, or
    ``{}`` with a note when no host C compiler can build them."""
    from ..runtime.evaluate import EvaluationError
    from ..runtime.float_accuracy import measure
    from .render import render_c
    double = render_c(model, programs, trig, "double", batch=False, lanes=lanes)
    single = render_c(model, programs, trig, "float", batch=False, lanes=lanes)
    try:
        return measure(model, double, single, document)
    except (EvaluationError, OSError) as exc:
        if host_compiler_works():      # the generated C itself failed: a defect, never a note
            raise
        print(f"note: float error not measured (no working host C compiler): {str(exc).splitlines()[0]}",
              file=sys.stderr)
        return {}


def host_compiler_works() -> bool:
    """Whether ``$CC`` (else ``cc``) builds a shared library of a one-line C file, as the float
    measurement does."""
    import subprocess
    import tempfile
    with tempfile.TemporaryDirectory(prefix="kindyngen-cc-") as tmp:
        source = Path(tmp) / "probe.c"
        source.write_text("double kdg_probe(double x) { return x + 1.0; }\n")
        try:
            done = subprocess.run([os.environ.get("CC", "cc"), "-std=c99", "-shared", "-fPIC", "-o",
                                   str(Path(tmp) / "probe.so"), str(source)], capture_output=True)
        except OSError:
            return False
        return done.returncode == 0


def generate(model: RobotModel, out_root: Path, languages=LANGUAGES, params: str = "numeric",
             progress: bool = True, only=None, trig: str = "kernel", scalar: str = "double",
             batch: bool = True, lanes: bool = True, bundles=()) -> Path:
    """Write all generated files of ``model`` (``only``: just the named functions) under
    ``out_root/<robot>/``; returns that folder. ``trig``: one of c_trig.TRIG_MODES; ``scalar``
    (the C's type, render.SCALARS), ``batch`` (C batch variants) and ``lanes`` (C single calls
    of lane programs as loops over lanes): see render.render_c; ``bundles``: bundles.Bundle
    requests (--bundle) besides the description's.

    Everything is derived first, then written into a staging folder that replaces
    ``out_root/<robot>/`` whole (kindyngen.output_folder.replace_folder): a failed or killed run
    leaves the previous folder as it was; a finished one leaves exactly the files that
    functions.json's "files" lists, plus the files the user added (not listed last time)."""
    model = resolved(model)           # a tree closed by loops: its coordinates chosen (nq, nv)
    out = Path(out_root) / model.identifier
    # --scalar float: the IK with float's tolerances, in every language written (the python
    # module beside float C is its double reference) and in both builds the float error compares
    # --functions ik_dls: fk_hom and jacobian too (it iterates them); ik_dls only where asked for
    dls = wants_ik_dls(only)
    programs = build_programs(model, params, only=derived_names(only), progress=progress, scalar=scalar,
                              bundles=bundles)
    document = manifest(model, programs, params, trig, scalar=scalar, batch=batch, lanes=lanes, ik_dls=dls)
    base_params = base_params_document(model)          # None for robots with symbolic lengths
    for note in undecided_notes(model, only) + mimic_notes(model, only) if progress else ():
        print(f"note: {note}", file=sys.stderr)
    float_error = measure_float_error(model, programs, document, trig, lanes) if scalar == "float" and "c" in languages else None

    def write(folder: Path) -> None:
        if base_params is not None:
            _write(folder / "base_params.json", strict_json(base_params, indent=1) + "\n")
        _write(folder / "opcounts.json", strict_json(opcounts_json(programs, float_error), indent=1) + "\n")
        _write(folder / "opcounts.md", opcounts_markdown(model.name, programs, model.identifier.startswith("lwr4"),
                                                         float_error))
        for lang in languages:
            options = ({"trig": trig, "scalar": scalar, "batch": batch, "float_error": float_error, "lanes": lanes}
                       if lang == "c" else {})
            options["ik_dls"] = dls
            for filename, text in RENDERERS[lang](model, programs, **options).items():
                _write(folder / lang / filename, text)
            if lang == "casadi":
                save_casadi_functions(casadi_builders(model, programs, ik_dls=dls), folder / lang)
        # written last, listing every file of the output (itself included)
        written = [p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir()]
        document["files"] = sorted(written + ["functions.json"])
        _write(folder / "functions.json", strict_json(document, indent=1) + "\n")

    replace_folder(out, write, previous_files)
    return out


def previous_files(folder: Path) -> list[str] | None:
    """The files an earlier ``generate`` wrote into ``folder`` (its functions.json's "files"), or
    None where that is not known (no or an unreadable functions.json, one written before the list
    existed): then no file of the folder is taken for the generator's."""
    try:
        document = json.loads((Path(folder) / "functions.json").read_text())
    except (OSError, ValueError):
        return None
    return listed_files(document)
