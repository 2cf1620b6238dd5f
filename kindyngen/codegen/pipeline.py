"""Robot description -> derivations -> CSE and counts -> rendered sources, written to disk.

``generate(model, out_root)`` writes ``out_root/<robot>/`` with ``functions.json`` (the
interface: names, ports, costs), ``opcounts.json``, ``opcounts.md`` and one folder per
language. Output is deterministic: the same description gives the same bytes.
"""
from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..algorithms.regressors import base_params_document, undecided_notes
from ..json_text import strict_json
from .budget import GenerationMemoryError, memory
from .catalog import applicable_names, derive
from .interface import manifest
from .optimize import Program, optimize
from .render import RENDERERS, casadi_builders
from .count_report import opcounts_json, opcounts_markdown
from ..model.robot_model import RobotModel

LANGUAGES = ("c", "python", "casadi", "python_c", "jax", "matlab")


class Progress:
    """Where a run is, on stderr: one line per phase of each function as it starts (its number,
    name and phase: deriving, CSE, ...), with the time since the run began; redrawn in place on
    a terminal, one line each otherwise.

    >>> import io
    >>> out = io.StringIO()
    >>> bar = Progress("arm", 2, out, clock=iter(range(10)).__next__)
    >>> bar.begin("fk_hom"); bar.phase("CSE"); bar.begin("M"); bar.close()
    >>> print(out.getvalue(), end="")
    arm [..........] 1/2 fk_hom: deriving (1.0 s)
    arm [..........] 1/2 fk_hom: CSE (2.0 s)
    arm [#####.....] 2/2 M: deriving (3.0 s)
    arm: 2 functions derived and optimised in 4.0 s
    """

    WIDTH = 10

    def __init__(self, label: str, total: int, stream=None, clock=time.perf_counter):
        # sys.stderr looked up per instance, not bound at import: a redirected or replaced
        # stderr (a caller's capture, a test's) is the one written to
        stream = sys.stderr if stream is None else stream
        self.label, self.total, self.stream, self.clock = label, total, stream, clock
        self.current, self.name = 0, ""
        self.start = clock()
        self.tty = stream.isatty()

    def begin(self, name: str) -> None:
        """Function ``name`` (the next one) starts: its derivation first."""
        self.current += 1
        self.name = name
        self.phase("deriving")

    def phase(self, what: str) -> None:
        """The current function enters phase ``what``."""
        filled = self.WIDTH * (self.current - 1) // max(self.total, 1)
        line = (f"{self.label} [{'#' * filled}{'.' * (self.WIDTH - filled)}] {self.current}/{self.total} "
                f"{self.name}: {what} ({self.clock() - self.start:.1f} s)")
        self._write(line)

    def _write(self, line: str) -> None:
        self.stream.write(("\r" + line.ljust(100)) if self.tty else line + "\n")
        self.stream.flush()

    def close(self) -> None:
        line = (f"{self.label}: {self.current} function{'s' if self.current != 1 else ''} derived and optimised in "
                f"{self.clock() - self.start:.1f} s")
        self.stream.write(("\r" + line.ljust(100) + "\n") if self.tty else line + "\n")
        self.stream.flush()


def build_programs(model: RobotModel, params: str = "numeric", only=None, progress: bool = True,
                   scalar: str = "double", memory_limit: int | None = None) -> list[Program]:
    """Derive and optimise every applicable function of ``model`` (of ``only``; for C of type
    ``scalar``), one function after the other, reporting each phase as it starts
    (:class:`Progress`). ``memory_limit``: bytes the run may grow by (its address space,
    ``RLIMIT_AS``, while it derives); beyond, :class:`GenerationMemoryError` names the function
    and phase instead of the system killing the process."""
    names = applicable_names(model, only)
    bar = Progress(f"{model.identifier}", len(names)) if progress else None
    report = bar.phase if bar else (lambda phase: None)
    programs, where = [], ["deriving"]

    def phase(what: str) -> None:
        where[0] = what
        report(what)

    with _address_space_limit(memory_limit) as limit:
        for name in names:
            where[0] = "deriving"
            if bar:
                bar.begin(name)
            try:
                function = derive(model, name, params, scalar)
                if function is None:             # a regressor without decided base parameters
                    phase("not generated (its base parameters are undecided)")
                    continue
                programs.append(optimize(function, phase))
            except MemoryError:
                failed = name
                break
        else:
            failed = None
    if failed is not None:
        raise GenerationMemoryError(
            f"{model.name}: {failed} ({where[0]}) needed more than the memory limit of {memory(limit / 2 ** 20)} "
            f"(the memory available when the run started, or --max-memory; docs/reference/cli.md, 'Large robots')")
    if bar:
        bar.close()
    return programs


@contextmanager
def _address_space_limit(extra: int | None):
    """Lower the soft RLIMIT_AS to the current address space plus ``extra`` bytes for the
    block (yields ``extra``; nothing where ``extra`` is None or the platform has no such
    limit), and restore it after."""
    try:
        import resource
        pages = int(Path("/proc/self/statm").read_text().split()[0])
    except (ImportError, OSError, ValueError):
        yield extra
        return
    if extra is None:
        yield extra
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = pages * resource.getpagesize() + extra
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield extra
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


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
        print(f"note: float error not measured (no working host C compiler): {str(exc).splitlines()[0]}",
              file=sys.stderr)
        return {}


def generate(model: RobotModel, out_root: Path, languages=LANGUAGES, params: str = "numeric",
             progress: bool = True, only=None, trig: str = "kernel", scalar: str = "double",
             batch: bool = True, lanes: bool = True, memory_limit: int | None = None) -> Path:
    """Write all generated files of ``model`` (``only``: just the named functions) under
    ``out_root/<robot>/``; returns that folder. ``trig``: one of c_trig.TRIG_MODES; ``scalar``
    (the C's type, render.SCALARS), ``batch`` (C batch variants) and ``lanes`` (C single calls
    of lane programs as loops over lanes): see render.render_c; ``memory_limit``: see
    :func:`build_programs`."""
    out = Path(out_root) / model.identifier
    # --scalar float: the IK with float's tolerances, in every language written (the python
    # module beside float C is its double reference) and in both builds the float error compares
    programs = build_programs(model, params, only=only, progress=progress, scalar=scalar,
                              memory_limit=memory_limit)
    document = manifest(model, programs, params, trig, scalar=scalar, batch=batch, lanes=lanes)
    _write(out / "functions.json", strict_json(document, indent=1) + "\n")
    base_params = base_params_document(model)          # None for robots with symbolic lengths
    for note in undecided_notes(model, only) if progress else ():
        print(f"note: {note}", file=sys.stderr)
    if base_params is not None:
        _write(out / "base_params.json", strict_json(base_params, indent=1) + "\n")
    float_error = measure_float_error(model, programs, document, trig, lanes) if scalar == "float" and "c" in languages else None
    _write(out / "opcounts.json", strict_json(opcounts_json(programs, float_error), indent=1) + "\n")
    _write(out / "opcounts.md", opcounts_markdown(model.name, programs, model.identifier.startswith("lwr4"),
                                                  float_error))
    for lang in languages:
        options = ({"trig": trig, "scalar": scalar, "batch": batch, "float_error": float_error, "lanes": lanes}
                   if lang == "c" else {})
        for filename, text in RENDERERS[lang](model, programs, **options).items():
            _write(out / lang / filename, text)
        if lang == "casadi":
            save_casadi_functions(casadi_builders(model, programs), out / lang)
    return out
