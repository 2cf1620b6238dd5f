"""Command line: ``python -m generator {generate,count,eval} --help``."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .robot import RobotDescriptionError, load_robot

LANGS = ("c", "python", "casadi")


def _languages(text: str) -> tuple[str, ...]:
    langs = tuple(x.strip() for x in text.split(",") if x.strip())
    bad = [x for x in langs if x not in LANGS]
    if bad or not langs:
        raise argparse.ArgumentTypeError(f"unknown language(s) {bad}; choose from {','.join(LANGS)}")
    return langs


def _cmd_generate(args) -> int:
    from .pipeline import generate
    for path in args.robots:
        model = load_robot(path)
        out = generate(model, Path(args.out), args.lang, args.params, progress=not args.quiet)
        if not args.quiet:
            print(f"wrote {out}", file=sys.stderr)
    return 0


def _cmd_count(args) -> int:
    from .pipeline import build_programs
    from .report import opcounts_json, opcounts_markdown
    for path in args.robots:
        model = load_robot(path)
        programs = build_programs(model, args.params, only=set(args.only) if args.only else None, progress=False)
        if args.format == "json":
            print(json.dumps({model.identifier: opcounts_json(programs)}, indent=1))
        else:
            print(opcounts_markdown(model.name, programs, model.identifier.startswith("lwr4")))
    return 0


def _cmd_eval(args) -> int:
    from .evaluate import load_generated
    text = sys.stdin.read()
    try:
        inputs = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SystemExit(f"error: standard input is not JSON: {exc}")
    if not isinstance(inputs, dict):
        raise SystemExit("error: standard input must be a JSON object of named inputs, e.g. {\"q\": [...]}")
    outputs = load_generated(args.generated_dir, args.lang).call(args.function, inputs)
    print(json.dumps({k: np.asarray(v).tolist() for k, v in outputs.items()}))
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m generator", description=(
        "KinDynGen: derive the kinematics and dynamics of a serial arm from its YAML description "
        "and generate C, Python and CasADi code with operation counts."))
    sub = p.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="derive and write generated code for one or more robots",
                       description="Derive, optimise and render every function of each robot into OUT/<robot>/.")
    g.add_argument("robots", nargs="+", metavar="ROBOT.yaml")
    g.add_argument("--out", required=True, metavar="DIR", help="output root; each robot goes to DIR/<robot>/")
    g.add_argument("--lang", type=_languages, default=LANGS, help="comma-separated subset of c,python,casadi (default: all)")
    g.add_argument("--params", choices=("numeric", "symbolic"), default="numeric",
                   help="inertial parameters baked in from the YAML (numeric) or an extra input p (symbolic)")
    g.add_argument("--quiet", action="store_true", help="no progress output")
    g.set_defaults(run=_cmd_generate)

    c = sub.add_parser("count", help="print the operation-count table (before and after CSE)",
                       description="Derive each robot's functions and print their operation counts.")
    c.add_argument("robots", nargs="+", metavar="ROBOT.yaml")
    c.add_argument("--params", choices=("numeric", "symbolic"), default="numeric")
    c.add_argument("--only", nargs="*", metavar="FUNCTION", help="restrict to these function names")
    c.add_argument("--format", choices=("md", "json"), default="md")
    c.set_defaults(run=_cmd_count)

    e = sub.add_parser("eval", help="evaluate a generated function on JSON inputs from stdin",
                       description=("Read a JSON object of named inputs from standard input (each an array, "
                                    "optionally with a leading batch dimension), evaluate FUNCTION with the "
                                    "generated code in the chosen language, print a JSON object of outputs."))
    e.add_argument("generated_dir", metavar="GENERATED_DIR", help="a robot folder, e.g. generated/lwr4")
    e.add_argument("function", metavar="FUNCTION", help="e.g. fk_hom, fk_dq, jacobian")
    e.add_argument("--lang", choices=LANGS, default="c")
    e.set_defaults(run=_cmd_eval)
    return p


def main(argv=None) -> int:
    from .evaluate import EvaluationError
    args = parser().parse_args(argv)
    try:
        return args.run(args)
    except (RobotDescriptionError, EvaluationError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
