"""Command line: ``kindyngen {generate,count,eval} --help`` (also ``python -m kindyngen``).

Bad input of any kind (robot description, arguments, JSON on standard input) is one line on
standard error starting with ``error:`` and exit code 2; never a traceback.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from ..algorithms.base_parameters import BaseParameterError
from ..codegen.budget import GenerationMemoryError, LimitError
from ..codegen.bundles import BundleError
from ..codegen.trig_kernel import TRIG_MODES
from ..codegen.render import SCALARS
from ..json_text import strict_json
from ..runtime.evaluate import EvaluationError
from ..measured import MeasuredDataError
from ..model.robot_model import RobotDescriptionError
from ..model.user_text import one_line
from ..readers.yaml_description import load_robot
from .interrupts import ending_on_signals


LANGS = ("c", "python", "casadi", "jax", "matlab")
# generate also writes the CPython extension source (python_c), which eval does not run
GENERATE_LANGS = ("c", "python", "casadi", "python_c", "jax", "matlab")
EXIT_BAD_INPUT = 2
#: what each command writes into --out (an earlier run's file of these names that a new run
#: does not write is dropped, so two runs never mix: kindyngen.output_folder.replace_outputs)
IDENTIFY_OUTPUTS = ("identification.json", "model.yaml", "report.md", "validation_torques.png")
DISCOVER_OUTPUTS = ("discovery.json", "model.yaml", "report.md", "report.html", "residuals.png", "steps.png",
                    "heldout_torques.png")
EXCITE_OUTPUTS = ("excitation.csv", "excitation.json")
REPRODUCE_OUTPUTS = ("reproduction.json", "report.md", "fig4_torque_validation.png", "fig6_elements.png",
                     "g2_published.png")
MAX_HOLDOUT = 0.8
MAX_FOLDS = 50
#: excite refuses a design whose regressor condition number exceeds this (identify's default limit)
MAX_EXCITATION_CONDITION = 1e6


class UsageError(ValueError):
    """A command-line request that cannot be served (unknown function name, ...)."""


class _Parser(argparse.ArgumentParser):
    """argparse whose errors are one line (and exit 2), like every other bad input."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"error: {self.prog}: {message} (see --help)\n")


def _robot_options(command: argparse.ArgumentParser) -> None:
    """How a description is read: the chain of a URDF, and whether near-exact angles snap."""
    command.add_argument("--base", metavar="LINK", help="URDF: the chain's first link (default: the root)")
    command.add_argument("--tip", metavar="LINK",
                         help="URDF: the chain's last link, tool frames included (default: the single leaf)")
    command.add_argument("--keep-angles", action="store_true",
                         help="keep angles within 1e-5 of a multiple of pi/12 as written (default: snap them, "
                              "with a note); within 1e-12 they are always read as the exact multiple")


def _tree_options(command: argparse.ArgumentParser) -> None:
    """Reading a whole URDF as a kinematic tree."""
    command.add_argument("--tree", action="store_true",
                         help="every branch of a URDF (a humanoid, a quadruped, a dual arm), or a YAML tree "
                              "(joints with parent)")
    command.add_argument("--floating-base", action="store_true",
                         help="the root link moves freely (implies --tree): Pinocchio's free-flyer layout, q = "
                              "base position, quaternion (x, y, z, w), joints; qd = base twist in the base "
                              "frame, joint velocities")
    command.add_argument("--frames", type=_names, metavar="LINK,LINK,...",
                         help="links (a YAML tree: joints) whose poses and Jacobians fk_hom and jacobian return, "
                              "in this order (implies --tree; default: the tips, the links of joints without children)")


def _names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",")]
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected comma-separated link names, got {text!r}")
    return names


def load(path, args):
    """A robot description read with the command's robot options; what reading changed
    (snapped angles, zero-mass links) is printed to standard error."""
    if getattr(args, "tree", False) or getattr(args, "floating_base", False) or getattr(args, "frames", None):
        if args.base or args.tip:
            raise UsageError("--base and --tip choose one chain; a tree (--tree, --floating-base, --frames) "
                             "has every branch")
        model = load_robot(path, snap_angles=not args.keep_angles, tree=True, frames=args.frames,
                           floating_base=args.floating_base)
    else:
        model = load_robot(path, snap_angles=not args.keep_angles, base=args.base, tip=args.tip)
    for note in model.notes:      # a note may quote an attribute no name check saw (a URDF <mimic joint>)
        print(f"note: {one_line(note)}", file=sys.stderr)
    return model


def writable_out(out, replaced: bool = True) -> Path:
    """``--out`` checked before any work is done: a folder that can be created or replaced there
    (``replaced``: ``out`` is swapped whole, in its parent), or one to write folders into
    (``generate``'s ``OUT``, holding ``OUT/<robot>/``); else a UsageError naming it."""
    from ..output_folder import check_writable
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a folder")
    try:
        check_writable(out.parent if replaced else out)
    except OSError as exc:
        raise UsageError(f"--out {out}: {exc.strerror}") from None
    return out


def _cmd_generate(args) -> int:
    from ..codegen.float32 import FloatRangeError
def _large_robot_options(command: argparse.ArgumentParser) -> None:
    """The limits of a run on a large robot (kindyngen/codegen/budget.py)."""
    command.add_argument("--allow-large", action="store_true",
                         help="derive also the functions estimated above the limits of 60 s CPU and 2 GB each, "
                              "which a large robot leaves out (named) or refuses when asked for (docs/reference/"
                              "cli.md, 'Large robots')")
    command.add_argument("--max-memory", type=_gigabytes, metavar="GB",
                         help="stop with an error naming the function when deriving needs more memory than this "
                              "(default: the memory available when the run starts)")


def _gigabytes(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of gigabytes, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of gigabytes, got {text!r}")
    return value


def available_memory() -> int | None:
    """Bytes of memory available now (/proc/meminfo's MemAvailable), or None where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _planned(model, requested, args, bundles=()) -> tuple:
    """The functions of ``model`` to derive, of ``requested`` (names the user gave, or None for
    all), decided before anything is derived (kindyngen/codegen/budget.py): the estimate and
    what is left out printed as notes, a function asked for (or a member of the description's
    bundles and ``bundles``) above its limit refused."""
    from ..codegen.budget import plan
    from ..codegen.bundles import requested as requested_bundles
    from ..codegen.catalog import applicable_names
    names = applicable_names(model, requested)
    members = tuple(m for bundle in requested_bundles(model, bundles) for m in bundle.members)
    chosen = plan(model, names, asked=requested is not None, allow_large=args.allow_large,
                  required=applicable_names(model, set(members)))
    for note in chosen.notes(model.name):
        print(f"note: {one_line(note)}", file=sys.stderr)
    return chosen.names


def _memory_limit(args) -> int | None:
    return int(args.max_memory * 2 ** 30) if args.max_memory else available_memory()


def _cmd_generate(args) -> int:
    from ..codegen.float32 import FloatRangeError
    from ..codegen.catalog import applicable_names, derived_names, wants_ik_dls
    from ..codegen.pipeline import generate
    writable_out(args.out, replaced=False)
    only = set(args.functions) if args.functions else None
    if args.scalar == "float" and "python_c" in args.lang:
        if args.lang is not GENERATE_LANGS:      # asked for explicitly
            raise UsageError("--lang python_c: the CPython extension wraps double C; "
                             "drop python_c from --lang or use --scalar double")
        args.lang = tuple(lang for lang in args.lang if lang != "python_c")
    models = [(path, load(path, args)) for path in args.robots]      # every file read before any work
    seen = {}
    for path, model in models:
        if model.identifier in seen:
            raise UsageError(f"{path}: the robot's identifier {model.identifier} is that of {seen[model.identifier]} "
                             f"too: both would be written to {Path(args.out) / model.identifier}; rename one")
        seen[model.identifier] = path
    # every robot's plan (estimate, what is left out or refused) before any work
    bundles = tuple(args.bundle or ())
    plans = [_planned(model, derived_names(only), args, bundles) for _, model in models]
    for (path, model), names in zip(models, plans):
        left_out = set(applicable_names(model, derived_names(only))) - set(names)
        # the selection without what the plan leaves out (ik_dls where it was wanted)
        chosen = only if not left_out else set(names) | ({"ik_dls"} if wants_ik_dls(only) else set())
        try:
            out = generate(model, Path(args.out), args.lang, args.params, progress=not args.quiet, trig=args.trig,
                           only=chosen, scalar=args.scalar, batch=not args.no_batch, lanes=not args.no_lanes,
                           bundles=bundles, memory_limit=_memory_limit(args), left_out=tuple(sorted(left_out)))
        except FloatRangeError as exc:      # a derived constant float cannot hold: the description's numbers
            raise UsageError(f"{path}: --scalar float: {exc}; generate it with --scalar double") from None
        written = {f["name"] for f in json.loads((out / "functions.json").read_text())["functions"]}
        for name in sorted((only or set()) - written):
            print(f"note: --functions: {name} does not apply to {model.name}; not generated", file=sys.stderr)
        for name in sorted((derived_names(only) or set()) - (only or set())):
            print(f"note: --functions: {name} generated too (ik_dls iterates it)", file=sys.stderr)
        if not args.quiet:
            print(f"wrote {out}", file=sys.stderr)
    return 0


def _cmd_describe(args) -> int:
    import yaml
    from ..readers.yaml_writer import describe
    model = load(args.robot, args)
    try:
        data = describe(model)
    except ValueError as exc:       # a standard DH table: its link frames are off the joint axes
        raise UsageError(f"{args.robot}: {exc}") from None
    header = "# " + one_line(f"{model.name}: written by kindyngen describe from {Path(args.robot).name}"
                             + (f" (base {model.base_name}, tip {args.tip})" if args.tip or args.base else "")) + "\n"
    text = header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
    if args.out:
        from ..output_folder import replace_file
        try:
            replace_file(args.out, text)
        except OSError as exc:
            raise UsageError(f"--out {args.out}: cannot write: {exc.strerror}") from None
    else:
        sys.stdout.write(text)
    return 0


def _cmd_count(args) -> int:
    from ..algorithms.regressors import undecided_notes
    from ..codegen.catalog import NAMES, applicable_names
    from ..codegen.pipeline import build_programs
    from ..codegen.count_report import opcounts_json, opcounts_markdown
    only = None
    if args.only is not None:
        if not args.only:
            raise UsageError("--only needs at least one function name")
        known = NAMES
        unknown = [name for name in args.only if name not in known]
        if unknown:
            raise UsageError(f"--only: unknown function(s) {', '.join(unknown)}; known: {', '.join(known)}")
        only = set(args.only)
    for path in args.robots:
        model = load(path, args)
        missing = sorted(only - set(applicable_names(model, only))) if only else []
        if missing:
            raise UsageError(f"--only: {', '.join(missing)} not generated for {model.name} "
                             f"(does not apply to this arm; see the README's function table)")
        names = _planned(model, only, args)
        programs = build_programs(model, args.params, only=set(names), progress=not args.quiet,
                                  memory_limit=_memory_limit(args))
        for note in undecided_notes(model, set(names)):    # not of what the plan left out: costly to decide
            print(f"note: {note}", file=sys.stderr)
        undecided = sorted(set(names) - {p.function.name for p in programs})
        if only and undecided:              # asked for, base parameters undecided (the note above)
            raise UsageError(f"--only: {', '.join(undecided)} not generated for {model.name}")
        if args.format == "json":
            print(strict_json({model.identifier: opcounts_json(programs)}, indent=1))
        else:
            print(opcounts_markdown(model.name, programs, model.identifier.startswith("lwr4")))
    return 0


def _strict_numbers(value, where: str):
    """Refuse anything in a numeric input that is not a finite number (null, booleans,
    strings, NaN, Infinity), naming the input; nested lists are walked."""
    if isinstance(value, list):
        for k, item in enumerate(value):
            _strict_numbers(item, f"{where}[{k}]")
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise EvaluationError(f"input {where} must be a number, got {json.dumps(value)}")
    if not math.isfinite(value):
        raise EvaluationError(f"input {where} must be finite, got {value}")


def _cmd_eval(args) -> int:
    from ..runtime.evaluate import load_generated
    text = sys.stdin.read()
    try:
        inputs = json.loads(text)
    except json.JSONDecodeError as exc:
        raise EvaluationError(f"standard input is not JSON: {exc}") from None
    if not isinstance(inputs, dict):
        raise EvaluationError("standard input must be a JSON object of named inputs, e.g. {\"q\": [...]}")
    for name, value in inputs.items():
        _strict_numbers(value, name)
    with np.errstate(all="ignore"):   # overflow is reported in the output itself (see kindyngen.json_text)
        outputs = load_generated(args.generated_dir, args.lang).call(args.function, inputs)
    print(strict_json({k: np.asarray(v).tolist() for k, v in outputs.items()}))
    return 0


def _cmd_build_python(args) -> int:
    from ..runtime.python_c import BuildError, load
    try:
        module = load(args.generated_dir)
    except BuildError as exc:
        raise UsageError(str(exc)) from None
    print(module.__file__)
    return 0


def _all_function_names() -> tuple[str, ...]:
    from ..codegen.catalog import SELECTABLE_NAMES
    return SELECTABLE_NAMES


def _names_argument(what: str, known, allow_empty: bool = False):
    """An argparse type: comma-separated names, each one of ``known()`` (called when parsing,
    so the measured-data modules are imported only by the commands that use them)."""
    def parse(text: str) -> tuple[str, ...]:
        choices = known()
        names = tuple(x.strip() for x in text.split(",") if x.strip())
        bad = [x for x in names if x not in choices]
        if bad or not (names or allow_empty):
            raise argparse.ArgumentTypeError(f"unknown {what}(s) {', '.join(bad) or '(none)'}; choose from "
                                             f"{','.join(choices)}")
        return names
    return parse


def _effect_names():
    from ..measured.effect_columns import EFFECTS, SENSING_EFFECTS
    return EFFECTS + SENSING_EFFECTS


def _candidate_names():
    from ..measured.discovery import CANDIDATES
    return CANDIDATES


_languages = _names_argument("language", lambda: GENERATE_LANGS)
_function_names = _names_argument("function", _all_function_names)


def _bundle(text: str):
    """An argparse type: ``NAME=FUNCTION,FUNCTION,...`` (kindyngen.codegen.bundles.parse_option)."""
    from ..codegen.bundles import parse_option
    try:
        return parse_option(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
_effects = _names_argument("effect", _effect_names, allow_empty=True)
_candidates = _names_argument("candidate", _candidate_names)


def _number_argument(expected: str, accept, none_allowed: bool = False):
    """An argparse type: a finite float that ``accept`` takes (or 'none' when allowed)."""
    def parse(text: str):
        if none_allowed and text.strip().lower() == "none":
            return None
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and accept(value)):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value
    return parse


_cutoff = _number_argument("a positive frequency in Hz or 'none'", lambda v: v > 0, none_allowed=True)
_fraction = _number_argument("a fraction between 0 and 1", lambda v: 0 < v < 1)
_positive = _number_argument("a positive number", lambda v: v > 0)


def _count(text: str) -> int:
    """An argparse type: a positive integer."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _folds(text: str) -> int:
    """An argparse type: a number of cross-validation blocks (at least 2)."""
    value = _count(text)
    if value < 2:
        raise argparse.ArgumentTypeError(f"expected at least 2 blocks (one is fitted, one validates), got {text!r}")
    return value


def _cmd_identify(args) -> int:
    from ..measured.effect_columns import SENSING_EFFECTS
    from ..measured.identify import IdentificationRequest, identify, write_outputs
    from ..measured.log_preparing import Preprocessing
    from ..measured.streaming import FitLimits, check_fit, identify_streamed
    from ..output_folder import replace_outputs
    if not args.validate and args.split is None:
        raise UsageError("give validation data (--validate FILE) or --split FRACTION: a model judged only on "
                         "the data it was fitted to says little")
    writable_out(args.out)
    settings = Preprocessing(cutoff_hz=args.cutoff, rate_hz=args.rate)
    request = IdentificationRequest(robot=args.robot, data=tuple(args.data), validate=tuple(args.validate or ()),
                                    effects=args.effects, consistent=args.consistent, weighted=args.weighted,
                                    split=args.split, preprocessing=settings,
                                    base=args.base, tip=args.tip, snap_angles=not args.keep_angles)

    def progress(text):
        if not args.quiet:
            print(f"identify: {text}", file=sys.stderr, flush=True)

    limits = FitLimits(min_samples_per_column=args.min_samples_per_column, max_condition=args.max_condition,
                       override=args.accept_poor_fit)
    client = None
    if args.scheduler:
        try:
            from dask.distributed import Client
            client = Client(args.scheduler, timeout=30)
        except (OSError, TimeoutError, ValueError) as exc:
            raise UsageError(f"--scheduler {args.scheduler}: cannot connect to the Dask scheduler ({exc})") from None
    try:
        if set(args.effects) & set(SENSING_EFFECTS):
            # the effects on the measurement are linearised at the identified parameters and
            # fitted again: the regressor rows change between fits, so they are not folded once
            progress(f"{', '.join(e for e in args.effects if e in SENSING_EFFECTS)}: identified in memory "
                     f"(re-linearised fits; not streamed, --workers and --scheduler unused)")
            result = identify(request, progress,
                              check_fit=lambda samples, columns, condition: check_fit(samples, columns, condition,
                                                                                      limits))
        else:
            result = identify_streamed(request, progress, workers=args.workers, client=client, limits=limits)
    finally:
        if client is not None:
            client.close()
    replace_outputs(args.out, lambda folder: write_outputs(result, folder), IDENTIFY_OUTPUTS)
    out = Path(args.out)
    summary = {"rms_train": [round(float(v), 4) for v in result.rms_train]}
    if result.rms_validation is not None:
        summary["rms_validation"] = [round(float(v), 4) for v in result.rms_validation]
        summary["rms_validation_sum"] = round(float(np.sum(result.rms_validation)), 4)
    summary["physically_consistent"] = result.physically_consistent
    print(strict_json(summary))
    progress(f"wrote {out}/identification.json, report.md" + (", model.yaml" if result.model_yaml else ""))
    return 0


def _cmd_discover(args) -> int:
    from ..measured.discovery import CANDIDATES
    from ..measured.discrepancy import DiscrepancyRequest, run_discrepancy, write_outputs
    from ..measured.log_preparing import Preprocessing
    request = DiscrepancyRequest(robot=args.robot, data=tuple(args.data), holdout=args.holdout,
                                 candidates=args.candidates or CANDIDATES, folds=args.folds,
                                 preprocessing=Preprocessing(cutoff_hz=args.cutoff, rate_hz=args.rate),
                                 base=args.base, tip=args.tip, snap_angles=not args.keep_angles)

    def progress(text):
        if not args.quiet:
            print(f"discover: {text}", file=sys.stderr, flush=True)

    from ..output_folder import replace_outputs
    writable_out(args.out)
    if args.holdout > MAX_HOLDOUT:
        raise UsageError(f"--holdout {args.holdout:g} leaves {100 * (1 - args.holdout):.3g} % of the log to find "
                         f"effects in; at most {MAX_HOLDOUT:g} may be held out")
    if args.folds > MAX_FOLDS:
        raise UsageError(f"--folds {args.folds}: at most {MAX_FOLDS} cross-validation blocks (each block must hold "
                         f"seconds of motion, not a handful of samples)")
    result = run_discrepancy(request, progress)
    replace_outputs(args.out, lambda folder: write_outputs(result, folder), DISCOVER_OUTPUTS)
    out = Path(args.out)
    d = result.discovery
    print(strict_json({"effects": list(d.effects),
                       "indistinguishable": [list(group) for group, _ in d.indistinguishable],
                       "rms_before": [round(float(v), 4) for v in result.rms_before],
                       "rms_after": [round(float(v), 4) for v in result.rms_after]}))
    progress(f"wrote {out}/discovery.json, report.md" + (", model.yaml" if result.model_yaml else ""))
    return 0


def _cmd_reproduce(args) -> int:
    from ..measured.fri_source import FriSource, MissingPinocchioError
    from ..measured.paper_reproduction import PAPER_TABLE_II, reproduce, write_report
    from ..output_folder import replace_outputs
    writable_out(args.out)
    model = load_robot(args.robot)

    def progress(text):
        if not args.quiet:
            print(f"reproduce-identification: {text}", file=sys.stderr, flush=True)

    noise = {}
    if args.noise == "paper":
        # the noise the paper's Table II (training column) implies: sqrt of its mean square per
        # joint (joint 1 has no entry), 1e-5 on M, 0.05 N m on the torque sensors
        g_noise = np.sqrt([1e-9] + [float(x) for x in PAPER_TABLE_II["TS"][1:]])
        noise = dict(g_noise=g_noise, m_noise=1e-5, tau_noise=0.05, seed=args.seed + 1)
    try:
        source = FriSource.perturbed(model, truth_seed=args.seed, **noise)
    except MissingPinocchioError as exc:
        raise UsageError(str(exc).splitlines()[0]) from None
    result = reproduce(source, model, n_train=args.train, n_val=args.validate, seed=args.seed,
                       tip_mass=args.tip_mass, progress=progress)
    summary = {}
    replace_outputs(args.out, lambda folder: summary.update(write_report(result, folder)),
                    REPRODUCE_OUTPUTS)
    print(strict_json({"tip_mass": summary.get("tip_mass")}))
    progress(f"wrote {args.out}/reproduction.json, report.md")
    return 0


def _cmd_excite(args) -> int:
    from ..measured.excitation import (default_limits, optimise_excitation, write_trajectory_csv,
                                       write_trajectory_json)
    writable_out(args.out)
    model = load(args.robot, args)
    limits = default_limits(model, velocity=args.velocity, acceleration=args.acceleration, margin=args.margin)

    def progress(text):
        if not args.quiet:
            print(f"excite: {text}", file=sys.stderr, flush=True)

    from ..measured.log_reading import MIN_SAMPLES
    from ..output_folder import replace_outputs
    rows = int(math.floor(args.periods / args.frequency * args.rate + 1e-9)) + 1
    if rows < MIN_SAMPLES:
        raise UsageError(f"--rate {args.rate:g} Hz over {args.periods} period(s) of {1 / args.frequency:g} s gives "
                         f"{rows} row(s); a log needs at least {MIN_SAMPLES} (identification filters and "
                         f"differentiates it): raise --rate")
    result = optimise_excitation(model, limits, harmonics=args.harmonics, base_frequency_hz=args.frequency,
                                 friction=not args.no_friction, seed=args.seed, max_iterations=args.iterations,
                                 progress=progress)
    if not result.feasible:
        raise UsageError(f"no trajectory within the limits was found (velocity {args.velocity:g} rad/s, acceleration "
                         f"{args.acceleration:g} rad/s^2, margin {args.margin:g} rad): relax them or raise --iterations")
    if not result.condition_number <= MAX_EXCITATION_CONDITION:
        raise UsageError(f"the best trajectory within the limits has a regressor condition number of "
                         f"{result.condition_number:.3g} (limit {MAX_EXCITATION_CONDITION:.0e}): velocity "
                         f"{args.velocity:g} rad/s and acceleration {args.acceleration:g} rad/s^2 leave too little "
                         f"motion to excite every parameter; raise them")
    out = Path(args.out)

    def write(folder):
        write_trajectory_csv(folder / "excitation.csv", result.trajectory, args.rate, periods=args.periods)
        write_trajectory_json(folder / "excitation.json", result)
    replace_outputs(out, write, EXCITE_OUTPUTS)
    print(strict_json({"condition_number": round(result.condition_number, 3),
                       "initial_condition_number": round(result.initial_condition_number, 3),
                       "iterations": result.iterations, "feasible": result.feasible, "rows": rows}))
    progress(f"wrote {out}/excitation.csv ({rows} rows at {args.rate:g} Hz) and excitation.json")
    return 0


def _cmd_plan(args) -> int:
    """A reach (and with --track the MPC tracking it in a simulated loop): kindyngen/control."""
    from ..control import plan_command
    from ..control.robot import ControlError
    from ..output_folder import replace_outputs
    writable_out(args.out)

    def progress(text):
        if not args.quiet:
            print(f"plan: {text}", file=sys.stderr, flush=True)
    model = load(args.robot, args)
    try:
        plan, robot, limits, task = plan_command.plan_reach(model, Path(args.robot), args, progress)
        tracked = plan_command.track(robot, limits, task, args, progress) if args.track else None
    except (ControlError, ValueError) as exc:
        raise UsageError(str(exc).splitlines()[0]) from None
    replace_outputs(Path(args.out), lambda folder: plan_command.write(folder, plan, tracked), plan_command.OUTPUTS)
    progress(f"wrote {args.out}/plan.json" + (", track.json" if tracked else ""))
    return 0


def _log_arguments(command: argparse.ArgumentParser) -> None:
    """The preprocessing and output options every command that reads logs shares."""
    command.add_argument("--cutoff", type=_cutoff, default=5.0, metavar="HZ|none",
                         help="zero-phase low-pass cutoff for q, qd, tau before differentiation (default 5 Hz; "
                              "'none': use the data as stored)")
    command.add_argument("--rate", type=_positive, default=None, metavar="HZ",
                         help="uniform resampling rate (default: the log's median rate)")
    command.add_argument("--out", required=True, metavar="DIR")
    command.add_argument("--quiet", action="store_true", help="no progress output")


def parser() -> argparse.ArgumentParser:
    p = _Parser(prog="kindyngen", description=(
        "KinDynGen: derive the kinematics and dynamics of a serial arm or a kinematic tree (YAML or URDF) "
        "and generate C, Python, CasADi, JAX and MATLAB/Octave code with operation counts. Bad input: one line on "
        "standard error and exit code 2."))
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    g = sub.add_parser("generate", help="derive and write generated code for one or more robots",
                       description="Derive, optimise and render every function of each robot into OUT/<robot>/.")
    g.add_argument("robots", nargs="+", metavar="ROBOT", help="robot descriptions: YAML or URDF (.urdf)")
    _robot_options(g)
    _tree_options(g)
    g.add_argument("--out", required=True, metavar="DIR", help="output root; each robot goes to DIR/<robot>/")
    g.add_argument("--lang", type=_languages, default=GENERATE_LANGS,
                   help="comma-separated subset of c,python,casadi,python_c,jax,matlab (default: all; python_c "
                        "and matlab's MEX gateway need c)")
    g.add_argument("--params", choices=("numeric", "symbolic"), default="numeric",
                   help="inertial parameters baked in from the description (numeric) or an extra input p "
                        "(symbolic: 10 per body, a floating base's root body first)")
    g.add_argument("--trig", choices=TRIG_MODES, default="kernel",
                   help="C: sin/cos of joint angles by a vectorisable polynomial kernel emitted into the .c, "
                        "within 1 ulp of glibc (kernel, default), or every sin/cos by libm (libm)")
    g.add_argument("--scalar", choices=SCALARS, default="double",
                   help="C scalar type: double (default), or float for single-precision FPUs such as "
                        "Cortex-M4F (float literals, sinf/cosf/sqrtf, a float sincos kernel; no ik_dls; "
                        "python_c is left out)")
    g.add_argument("--functions", type=_function_names, metavar="NAME,NAME,...",
                   help="generate only these functions, e.g. fk_hom,jacobian,tau; ik_dls brings the fk_hom and "
                        "jacobian it iterates (default: all that apply)")
    g.add_argument("--bundle", type=_bundle, action="append", metavar="NAME=FUNCTION,FUNCTION,...",
                   help="also generate NAME, one function computing all these functions' outputs with one CSE "
                        "over them (the sin/cos of q once), e.g. step=fk_hom,jacobian,M,g,tau (repeatable; a "
                        "description's bundles: section adds its own)")
    g.add_argument("--no-batch", action="store_true",
                   help="C: leave out the <name>_batch variants (a firmware compiles only what it calls)")
    g.add_argument("--no-lanes", action="store_true",
                   help="C: print the derivatives' single calls as their scalar program instead of a loop over "
                        "lanes or, for a large tree's tau_derivatives, loops over its joints (fewer operations, "
                        "less stack; for cores without vector units, e.g. Cortex-M)")
    g.add_argument("--quiet", action="store_true", help="no progress output")
    _large_robot_options(g)
    g.set_defaults(run=_cmd_generate)

    c = sub.add_parser("count", help="print the operation-count table (before and after CSE)",
                       description="Derive each robot's functions and print their operation counts.")
    c.add_argument("robots", nargs="+", metavar="ROBOT", help="robot descriptions: YAML or URDF (.urdf)")
    _robot_options(c)
    _tree_options(c)
    c.add_argument("--params", choices=("numeric", "symbolic"), default="numeric",
                   help="inertial parameters baked in (numeric) or an extra input p (symbolic), as for generate")
    c.add_argument("--only", nargs="*", metavar="FUNCTION",
                   help="restrict to these function names (an unknown or inapplicable name is an error)")
    c.add_argument("--format", choices=("md", "json"), default="md")
    c.add_argument("--quiet", action="store_true", help="no progress output")
    _large_robot_options(c)
    c.set_defaults(run=_cmd_count)

    w = sub.add_parser("describe", help="write a robot (a URDF's chain, say) as a YAML description",
                       description=("Read a robot description (URDF or YAML) and write it as a YAML description "
                                    "with joints by origin and axis (dh: none): the chain, merged fixed links, "
                                    "tool and limits as KinDynGen reads them, ready to edit and to load again. "
                                    "A standard DH table is refused (its link frames are off the joint axes)."))
    w.add_argument("robot", metavar="ROBOT", help="a URDF or YAML description")
    _robot_options(w)
    w.add_argument("--out", metavar="FILE", help="write here instead of standard output")
    w.set_defaults(run=_cmd_describe)

    e = sub.add_parser("eval", help="evaluate a generated function on JSON inputs from stdin",
                       description=("Read a JSON object of named inputs from standard input (each an array of "
                                    "finite numbers, optionally with a leading batch dimension), evaluate FUNCTION "
                                    "with the generated code in the chosen language, print a JSON object of "
                                    "outputs. A NaN or infinite output is written as the string \"NaN\", "
                                    "\"Infinity\" or \"-Infinity\" (JSON has no number for them)."))
    e.add_argument("generated_dir", metavar="GENERATED_DIR", help="a robot folder, e.g. generated/lwr4")
    e.add_argument("function", metavar="FUNCTION", help="e.g. fk_hom, fk_dq, jacobian")
    e.add_argument("--lang", choices=LANGS, default="c",
                   help="c (compiled on first use), python, casadi, jax (through jax.jit, 64-bit) or matlab "
                        "(the .m files in GNU Octave)")
    e.set_defaults(run=_cmd_eval)

    b = sub.add_parser("build-python", help="compile a robot's python_c extension and print its path",
                       description=("Compile GENERATED_DIR/python_c/<robot>_ext.c (the generated C as a CPython "
                                    "extension: the numpy module's functions at compiled speed, one configuration "
                                    "per call) with this interpreter's compiler settings into the cache "
                                    "($KINDYNGEN_CACHE, default ~/.cache/kindyngen), import it once, print the "
                                    "module's path. From Python: kindyngen.runtime.python_c.load(GENERATED_DIR)."))
    b.add_argument("generated_dir", metavar="GENERATED_DIR", help="a robot folder, e.g. generated/lwr4")
    b.set_defaults(run=_cmd_build_python)

    i = sub.add_parser("identify", help="identify the dynamic model from logged motion",
                       description=("Fit the robot's base parameters (and chosen joint effects) to logged joint "
                                    "torques; write DIR/identification.json, DIR/report.md with plots, and "
                                    "DIR/model.yaml (the identified robot description) when the result is "
                                    "physical. Logs: CSV with header t, q1..qn, tau1..taun (optional qd1.., "
                                    "qdd1..; s, rad, N m) or npz with times, positions, velocities, "
                                    "accelerations, torques; Parquet with the CSV's column names; ROS 2 bags "
                                    "(a rosbag2 folder, MCAP or SQLite) and ROS 1 .bag files of "
                                    "sensor_msgs/msg/JointState, joints matched by name. Logs are read and "
                                    "preprocessed, parallel-filtered and folded into a QR factor in chunks, in bounded memory "
                                    "whatever the length. Each file is one experiment (with --split, each file's first "
                                    "FRACTION trains); files are never differentiated or filtered across."))
    i.add_argument("--robot", required=True, metavar="ROBOT", help="the robot description, YAML or URDF (geometry, prior)")
    _robot_options(i)
    i.add_argument("--data", required=True, action="append", metavar="LOG", help="training log (repeatable)")
    i.add_argument("--validate", action="append", metavar="LOG", help="validation log (repeatable)")
    i.add_argument("--split", type=_fraction, metavar="FRACTION",
                   help="train on the first FRACTION of each --data file's time span, validate on the rest of it")
    i.add_argument("--effects", type=_effects, default=(), metavar="LIST",
                   help="comma-separated subset of viscous_friction,coulomb_friction,torque_offset,armature "
                        "(joint torques) and motor_side_elasticity,encoder_offset,torque_sensor_gain (effects on "
                        "the measurement, as discover names them: fitted to first order, re-linearised at the "
                        "identified parameters, in memory; a coefficient the data does not determine is reported "
                        "and left out of model.yaml)")
    i.add_argument("--consistent", action="store_true",
                   help="physically consistent identification (semidefinite program): positive definite "
                        "pseudo-inertias, non-negative friction and armature")
    i.add_argument("--weighted", action="store_true", help="weighted least squares (per-joint noise levels)")
    i.add_argument("--workers", type=_count, default=1, metavar="N",
                   help="fold the log files in N local processes (default 1; the result is the same bit for bit)")
    i.add_argument("--scheduler", metavar="ADDRESS",
                   help="fold the log files on a dask.distributed cluster (e.g. tcp://host:8786)")
    i.add_argument("--min-samples-per-column", type=_positive, default=10.0, metavar="K",
                   help="refuse fits with fewer training samples per regressor column (default 10)")
    i.add_argument("--max-condition", type=_positive, default=1e6, metavar="C",
                   help="refuse fits whose stacked regressor's condition number exceeds C (default 1e6)")
    i.add_argument("--accept-poor-fit", action="store_true",
                   help="fit despite those two limits; the report and identification.json flag it")
    _log_arguments(i)
    i.set_defaults(run=_cmd_identify)

    x = sub.add_parser("excite", help="design an excitation trajectory for identification",
                       description=("Optimise a periodic finite-Fourier-series joint trajectory (Swevers) for the "
                                    "condition number of the base torque regressor (plus viscous, Coulomb and "
                                    "offset columns), within the description's joint limits less a margin and "
                                    "the given velocity and acceleration limits, starting and ending at rest. "
                                    "Writes DIR/excitation.csv (t, q1..qn, qd1..qdn, qdd1..qddn; s, rad, rad/s, "
                                    "rad/s^2) to command, and DIR/excitation.json (coefficients, limits, "
                                    "condition numbers)."))
    x.add_argument("--robot", required=True, metavar="ROBOT", help="the robot description, YAML or URDF")
    _robot_options(x)
    x.add_argument("--harmonics", type=int, default=5, help="Fourier harmonics per joint (default 5)")
    x.add_argument("--frequency", type=_positive, default=0.1, metavar="HZ",
                   help="base frequency (default 0.1 Hz: a 10 s period)")
    x.add_argument("--velocity", type=_positive, default=1.0, metavar="RAD_S", help="velocity limit (default 1.0)")
    x.add_argument("--acceleration", type=_positive, default=3.0, metavar="RAD_S2",
                   help="acceleration limit (default 3.0)")
    x.add_argument("--margin", type=float, default=0.1, metavar="RAD",
                   help="kept away from each joint limit (default 0.1)")
    x.add_argument("--no-friction", action="store_true", help="condition the rigid-body columns only")
    x.add_argument("--seed", type=int, default=0, help="start point of the optimisation (deterministic)")
    x.add_argument("--iterations", type=_count, default=60, help="iteration budget (default 60)")
    x.add_argument("--rate", type=_positive, default=1000.0, metavar="HZ", help="CSV sampling rate (default 1000)")
    x.add_argument("--periods", type=_count, default=1, help="periods written to the CSV (default 1)")
    x.add_argument("--out", required=True, metavar="DIR")
    x.add_argument("--quiet", action="store_true", help="no progress output")
    x.set_defaults(run=_cmd_excite)

    r = sub.add_parser("reproduce-identification",
                       help="reproduce the identification paper's procedure (static M and g, tip mass)",
                       description=("The identification paper's procedure (Gaz, Flacco, De Luca, ICRA 2014) on a "
                                    "simulated control interface (Pinocchio, with a 'true' parameter set the "
                                    "identification never reads): static identification of the gravity and "
                                    "inertia coefficients from random configurations, its Tables II and III, "
                                    "the 0.25 kg tip-mass experiment (eqs. 31-32) and the torque validation "
                                    "along (pi/2) cos(pi t / 7). Writes DIR/reproduction.json and "
                                    "DIR/report.md with figures. Needs Pinocchio (pip install pin)."))
    r.add_argument("--robot", default="robots/lwr4.yaml", metavar="ROBOT.yaml",
                   help="the arm (default robots/lwr4.yaml: the paper's DH table)")
    r.add_argument("--train", type=_count, default=1000, help="training configurations (default 1000)")
    r.add_argument("--validate", type=_count, default=200, help="validation configurations (default 200)")
    r.add_argument("--noise", choices=("paper", "none"), default="paper",
                   help="noise on the reported g, M and torques of the size the paper's tables imply "
                        "(default), or none")
    r.add_argument("--tip-mass", type=_positive, default=0.25, metavar="KG", help="tip mass (default 0.25)")
    r.add_argument("--seed", type=int, default=2014, help="random configurations and the 'true' parameters")
    r.add_argument("--out", required=True, metavar="DIR")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    r.set_defaults(run=_cmd_reproduce)

    d = sub.add_parser("discover", help="find which effect the model is missing, add it, show the gap shrink",
                       description=("Compare the nominal model's torques with a log, name the missing effects "
                                    "(greedy selection with time-blocked cross-validation and an "
                                    "autocorrelation-aware criterion; confusable effects are reported, not "
                                    "guessed), write DIR/discovery.json, DIR/report.md with plots and "
                                    "DIR/model.yaml (the description plus the named effects). The last "
                                    "--holdout fraction of the log is held out for the before/after figures."))
    d.add_argument("--robot", required=True, metavar="ROBOT", help="the nominal robot description, YAML or URDF")
    _robot_options(d)
    d.add_argument("--data", required=True, action="append", metavar="LOG",
                   help="measured log (repeatable; each file its own experiment, with its own clock)")
    d.add_argument("--holdout", type=_fraction, default=0.3, metavar="FRACTION",
                   help="fraction of each file's time span held out (default 0.3)")
    d.add_argument("--candidates", type=_candidates, default=None, metavar="LIST",
                   help="comma-separated candidate effects (default: all)")
    d.add_argument("--folds", type=_folds, default=5, help="cross-validation blocks, 2 to 50 (default 5)")
    _log_arguments(d)
    d.set_defaults(run=_cmd_discover)

    pl = sub.add_parser("plan", help="plan a reach with joint limits (optimal control), optionally track it by MPC",
                        description=("Plan a reach on a fixed-base arm: from rest at --q0, the flange to --goal (m, base "
                                     "frame) and at rest after --T s, minimising the integral of |tau|^2 under the joint "
                                     "position, speed and torque limits (the URDF's <limit>, or --limits FILE). The "
                                     "robot's dynamics are generated and compiled once (cached). With --track the plan "
                                     "is tracked by the MPC in a simulated 1 kHz loop. Writes plan.json (and "
                                     "track.json) into --out."))
    pl.add_argument("robot", metavar="ROBOT", help="robot description, YAML or URDF")
    _robot_options(pl)
    where = pl.add_mutually_exclusive_group(required=True)
    where.add_argument("--goal", type=float, nargs=3, metavar=("X", "Y", "Z"), help="flange goal position in m")
    where.add_argument("--offset", type=float, nargs=3, metavar=("DX", "DY", "DZ"),
                       help="flange goal relative to its position at --q0, in m")
    pl.add_argument("--q0", type=float, nargs="+", metavar="Q", help="start configuration (default: 0 clipped to the limits)")
    pl.add_argument("--limits", metavar="FILE", help="YAML with velocity: [...] and effort: [...] (default: the URDF's)")
    pl.add_argument("--T", type=_positive, default=1.0, help="duration in s (default 1)")
    pl.add_argument("--N", type=_count, default=20, help="shooting intervals (default 20)")
    pl.add_argument("--integrator", choices=("rk4", "midpoint", "euler"), default="rk4", help="default rk4")
    pl.add_argument("--substeps", type=_count, default=1, help="integrator steps per interval (default 1)")
    pl.add_argument("--speed-margin", type=_fraction, default=0.0, metavar="FRACTION",
                    help="fraction of every speed limit the plan keeps free (default 0)")
    pl.add_argument("--position-margin", type=float, default=0.0, metavar="RAD",
                    help="rad the plan keeps from every position limit (default 0); plan.json's between_nodes "
                         "says what the limits at the nodes leave between them")
    pl.add_argument("--track", action="store_true", help="also track the plan by MPC in a simulated 1 kHz loop")
    pl.add_argument("--settle", type=float, default=1.0, help="--track: seconds simulated after --T (default 1)")
    pl.add_argument("--budget-ms", type=_positive, default=10.0, help="--track: CPU budget per re-solve (default 10)")
    pl.add_argument("--noise", type=float, nargs=2, default=(0.0, 0.0), metavar=("RAD", "RAD_S"),
                    help="--track: measurement noise (standard deviations)")
    pl.add_argument("--torque-step", type=float, nargs=4, metavar=("JOINT", "NM", "START", "DURATION"),
                    help="--track: a torque step on a joint (1-based) of NM newton metres from START for DURATION s")
    pl.add_argument("--out", required=True, metavar="DIR")
    pl.add_argument("--quiet", action="store_true", help="no progress output")
    pl.set_defaults(run=_cmd_plan)
    return p


def main(argv=None) -> int:
    """Run one command; its exit code (2: bad input, 130 / 143: interrupted, kindyngen.cli.interrupts)."""
    return ending_on_signals(lambda: _run(argv))


def _run(argv) -> int:
    args = parser().parse_args(argv)
    try:
        return args.run(args)
    except (RobotDescriptionError, EvaluationError, UsageError, BaseParameterError, BundleError) as exc:
        message = str(exc)
    except (LimitError, GenerationMemoryError) as exc:     # a large robot (codegen/budget.py)
        message = str(exc)
    except MeasuredDataError as exc:   # logs, estimation, the solver, excitation
        message = str(exc)
    except OSError as exc:  # an unwritable --out, a vanished file: still one line, no traceback
        message = f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")
    # no control character a file or its names hold reaches the terminal (an escape sequence, a
    # carriage return); newlines stay where a message has them on purpose (a compiler's output)
    print("error: " + "\n".join(one_line(line) for line in message.split("\n")), file=sys.stderr)
    return EXIT_BAD_INPUT
