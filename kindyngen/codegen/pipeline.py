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
from contextlib import contextmanager
from pathlib import Path

from ..algorithms.loop_closure import resolved
from ..algorithms.regressors import base_params_document, undecided_notes
from ..json_text import strict_json
from .budget import GenerationMemoryError, memory
from .bundles import bundle_programs, requested
from .catalog import applicable_names, derive, derived_names, mimic_notes, wants_ik_dls
from .interface import listed_files, manifest
from .optimize import Program, optimize
from .render import RENDERERS, casadi_builders
from .count_report import opcounts_json, opcounts_markdown
from ..model.robot_model import RobotModel
from ..output_folder import replace_folder

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

    def begin(self, name: str, what: str = "deriving") -> None:
        """Function ``name`` (the next one) starts, with phase ``what``."""
        self.current += 1
        self.name = name
        self.phase(what)

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
                   scalar: str = "double", bundles=(), memory_limit: int | None = None) -> list[Program]:
    """Derive and optimise every applicable function of ``model`` (of ``only``; for C of type
    ``scalar``), one function after the other, then its description's bundles and ``bundles``
    (--bundle: kindyngen/codegen/bundles.py), reporting each phase as it starts
    (:class:`Progress`). ``memory_limit``: bytes the run may grow by (its address space,
    ``RLIMIT_AS``, while it derives); beyond, :class:`GenerationMemoryError` names the function
    and phase instead of the system killing the process."""
    bundles = requested(model, bundles)          # checked before anything is derived
    names = applicable_names(model, only)
    bar = Progress(f"{model.identifier}", len(names) + len(bundles)) if progress else None
    programs, where = [], ["", "deriving"]        # the function and phase running now

    def begin(name: str, what: str = "deriving") -> None:
        where[:] = [name, what]
        if bar:
            bar.begin(name, what)

    def phase(what: str) -> None:
        where[1] = what
        if bar:
            bar.phase(what)

    with _address_space_limit(memory_limit) as limit:
        try:
            for name in names:
                begin(name)
                function = derive(model, name, params, scalar)
                if function is None:             # a regressor without decided base parameters
                    phase("not generated (its base parameters are undecided)")
                    continue
                programs.append(optimize(function, phase))
            programs += bundle_programs(model, bundles, programs, params, scalar,
                                        lambda name: begin(name, "bundling its members"))
        except MemoryError:
            failed = tuple(where)
        else:
            failed = None
    if failed is not None:
        raise GenerationMemoryError(
            f"{model.name}: {failed[0]} ({failed[1]}) needed more than the memory limit of "
            f"{memory(limit / 2 ** 20)} (the memory available when the run started, or --max-memory; "
            f"docs/reference/cli.md, 'Large robots')")
    if bar:
        bar.close()
    return programs


@contextmanager
def _address_space_limit(extra: int | None):
    """Lower the soft RLIMIT_AS to the current address space plus ``extra`` bytes for the
    block (yields ``extra``; nothing where ``extra`` is None or the platform has no such
    limit), and restore it after."""
    if extra is None:
        yield extra
        return
    _touch_native_state()
    try:
        import resource
        pages = int(Path("/proc/self/statm").read_text().split()[0])
    except (ImportError, OSError, ValueError):
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


def _touch_native_state() -> None:
    """Have symengine throw and catch one C++ exception before the limit drops. Its library
    carries its own C++ runtime, whose per-thread exception state is allocated on the first
    throw in a thread; glibc ends the process when that allocation fails ("cannot allocate
    memory for thread-local data: ABORT", exit 127), so a first throw that is itself the
    std::bad_alloc of running out would kill the run instead of raising MemoryError."""
    import symengine as se
    try:
        se.sympify("1 +* (")            # symengine's parser throws ParseError
    except RuntimeError:
        pass


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
             batch: bool = True, lanes: bool = True, bundles=(), memory_limit: int | None = None,
             left_out=()) -> Path:
    """Write all generated files of ``model`` (``only``: just the named functions) under
    ``out_root/<robot>/``; returns that folder. ``trig``: one of c_trig.TRIG_MODES; ``scalar``
    (the C's type, render.SCALARS), ``batch`` (C batch variants) and ``lanes`` (C single calls
    of lane programs as loops over lanes): see render.render_c; ``bundles``: bundles.Bundle
    requests (--bundle) besides the description's; ``memory_limit``: see :func:`build_programs`;
    ``left_out``: functions the run's plan left out (kindyngen/codegen/budget.py), not in
    ``only``, whose base parameters (a regressor's) are not analysed either.

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
                              bundles=bundles, memory_limit=memory_limit)
    document = manifest(model, programs, params, trig, scalar=scalar, batch=batch, lanes=lanes, ik_dls=dls)
    base_params = base_params_document(model, left_out)  # None for robots with symbolic lengths
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
