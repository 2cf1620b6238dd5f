"""`make bench`: time every generated function of lwr4 (and panda) in every implementation,
plus Pinocchio C++ for the same computations; write results/timings.json.

    python -m benchmarks.run [--quick] [--out DIR] [--generated DIR]

Implementations: "c" (-O3), "c_native" (-O3 -march=native), "casadi_codegen" (CasADi's C,
-O3), "python" (numpy, one configuration per call), "python_batch" / "python_batch_<N>"
(numpy on N configurations, time per configuration), "casadi" (saved Function called from
Python), "pinocchio_cpp" (Pinocchio's C++ algorithms in double), "pinocchio_casadi_c" (Pinocchio
traced with casadi::SX, CasADi's C, -O3 -march=native: the strongest Pinocchio-based peer),
"c_batch" (the <name>_batch variants, -O3 -march=native, N configurations per call, time per
configuration, with the single-call time of the same run), "python_c" (the generated C as a
Python extension, one configuration per call) against "pinocchio_python" (Pinocchio's Python
bindings). All
comparisons are ratios within one run on one machine; nothing here asserts on a time. --quick
is the smoke-test setting: tiny counts, lwr4 only, neither Pinocchio peer (their header-only
builds take minutes), no c_batch and no python_c.
"""
from __future__ import annotations

import argparse
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json
from kindyngen.readers.yaml_description import load_robot

from . import (c_batch, casadi_codegen, compiled, inputs, pinocchio_casadi, pinocchio_cpp, python_c_timing,
               python_timing, scaling, tree_scaling, trees)
from .build import BUILD
from .common import GENERATED, RESULTS, ROBOTS, machine, manifest, summary

FULL = dict(K=1000, repeats=15, rounds=3, c_target_ns=2e7, py_target_s=0.05, batch_sizes=(1000, 100_000),
            batch_repeats=5, robots=("lwr4", "panda"), pinocchio=True, c_native=True, c_batch_n=1000,
            compiled_python=True,
            scaling_max_n=12, scaling_budget_s=60.0, c_flags=None)
QUICK = dict(K=50, repeats=3, rounds=1, c_target_ns=2e5, py_target_s=0.002, batch_sizes=(200,),
             batch_repeats=2, robots=("lwr4",), pinocchio=False, c_native=False, c_batch_n=None,
             compiled_python=False,
             scaling_max_n=3, scaling_budget_s=5.0,
             # a smoke run: times are not meant, and -O3 of the whole lwr4 C alone takes 35 s cold
             c_flags=["-O0"])
PRIMARY = "lwr4"          # the robot of the paper: every implementation
SECONDARY_IMPLS = ("c", "c_native", "pinocchio_cpp", pinocchio_casadi.IMPL,  # other robots: the ratios only
                   c_batch.IMPL, "python_c")
PEERS = ("pinocchio_cpp", pinocchio_casadi.IMPL)  # the implementations the ratios divide by


def log(message: str) -> None:
    print(message, flush=True)


def _flat(value) -> np.ndarray:
    return np.asarray(value, dtype=float).ravel()


def reference_outputs(module, function: dict, sample: dict) -> list[np.ndarray]:
    """Outputs of the generated numpy code for input 0: the yardstick of the wiring checks."""
    result = getattr(module, function["name"])(*(sample[p["name"]][0] for p in function["inputs"]))
    if len(function["outputs"]) == 1:
        result = (result,)
    return [_flat(r) for r in result]


def _seconds(built) -> float | None:
    return None if built.seconds is None else round(built.seconds, 2)


def _max_error(got: list, want: list) -> float | None:
    """Largest relative difference; None when the outputs do not even have the same sizes
    or are not finite (kept JSON-valid: no Infinity/NaN in timings.json)."""
    if len(got) != len(want) or any(g.size != w.size for g, w in zip(got, want)):
        return None
    error = max((float(np.max(np.abs(g - w) / (1 + np.abs(w)))) for g, w in zip(got, want) if w.size),
                default=0.0)
    return error if np.isfinite(error) else None


class Bench:
    """The timings, checks and notes of one run, filled robot by robot."""

    def __init__(self, settings: dict, generated: Path, workdir: Path):
        self.settings, self.generated, self.workdir = settings, generated, workdir
        self.notes: list[str] = []
        self.robots: dict = {}
        self.pinocchio_build: dict | None = None
        self.pinocchio_casadi_build: dict | None = None

    def note(self, text: str) -> None:
        log("note: " + text)
        self.notes.append(text)

    def robot(self, name: str, impls: tuple | None) -> None:
        robot_dir = self.generated / name
        spec = manifest(robot_dir)
        if spec is None:
            self.note(f"{name}: no {robot_dir}/functions.json, skipped")
            return
        model = load_robot(ROBOTS / f"{name}.yaml")
        py_path = robot_dir / "python" / f"{name}.py"
        module = python_timing.load_module(py_path) if py_path.exists() else None
        functions = [f for f in spec["functions"] if module is None or hasattr(module, f["name"])]
        samples = {f["name"]: inputs.sample(f, model, self.settings["K"], module) for f in functions}
        refs = {f["name"]: reference_outputs(module, f, samples[f["name"]]) for f in functions} if module else {}
        entry = {"n": spec.get("n", model.n), "functions": {f["name"]: {} for f in functions},
                 "opcounts": {f["name"]: f.get("opcount") for f in functions}, "checks": {}, "build_seconds": {}}
        self.robots[name] = entry
        wanted = (lambda impl: impls is None or impl in impls)

        self._compiled(name, model, module, robot_dir, functions, samples, refs, entry, wanted)
        if module is not None and wanted("python"):
            self._guarded(name, "python", self._python, name, module, model, functions, samples, entry)
        if wanted("casadi"):
            self._guarded(name, "casadi", self._casadi_python, name, robot_dir, functions, samples, refs, entry)
        if wanted(c_batch.IMPL):
            self._guarded(name, c_batch.IMPL, self._c_batch, name, model, module, robot_dir, functions, entry)
        if wanted("python_c"):
            self._guarded(name, "python_c", self._python_c, name, entry)
        entry["ratios"] = ratios(entry["functions"])

    def _guarded(self, robot, impl, method, *args):
        """One implementation failing (a build error, a crash) costs its column, not the run."""
        try:
            return method(*args)
        except Exception as exc:  # noqa: BLE001 - reported in the results and on the console
            self._failed(robot, impl, exc)
            return None

    def _failed(self, robot, impl, exc):
        detail = getattr(exc, "stderr", None) or ""
        self.note(f"{robot}: {impl} failed and was skipped: {type(exc).__name__}: {exc} {detail}"[:3000])

    # -- compiled implementations, timed interleaved -----------------------------------------
    def _compiled(self, name, model, module, robot_dir, functions, samples, refs, entry, wanted):
        s, work = self.settings, self.workdir / name
        timers = {}
        for impl in ("c", "c_native"):
            if wanted(impl) and (impl != "c_native" or s["c_native"]):
                log(f"{name}: {impl}: building")
                timers[impl] = self._guarded(name, impl, compiled.generated_c, name, impl, robot_dir,
                                             functions, samples, work, s["c_flags"])
        if wanted("casadi_codegen"):
            log(f"{name}: casadi_codegen: generating and building")
            timers["casadi_codegen"] = self._guarded(name, "casadi_codegen", compiled.casadi_c, name, robot_dir,
                                                     functions, samples, work, s["c_flags"])
        data = inputs.dynamics_inputs(model, s["K"])
        if wanted("pinocchio_cpp"):
            timers["pinocchio_cpp"] = self._guarded(name, "pinocchio_cpp", self._pinocchio_timer, name, model,
                                                    functions, data, work)
        peer = pinocchio_casadi.IMPL
        if wanted(peer):
            timers[peer] = self._guarded(name, peer, self._pinocchio_casadi_timer, name, model, samples, work)
        timers = {impl: t for impl, t in timers.items() if t is not None}
        if not timers:
            return
        log(f"{name}: timing {', '.join(timers)} in {s['rounds']} interleaved rounds")
        pooled, outputs = compiled.interleave(timers, s["repeats"], s["rounds"], s["c_target_ns"],
                                              lambda impl, exc: self._failed(name, impl, exc))
        peer_notes = {}
        if peer in pooled:  # its derivative candidates: the faster one stays
            pooled[peer], outputs[peer], peer_notes = pinocchio_casadi.keep_faster(pooled[peer], outputs[peer])
        for impl, per_function in pooled.items():
            for fname, values in per_function.items():
                # A peer may time a function generated/ does not have (yet): it gets a row.
                stats = entry["functions"].setdefault(fname, {})[impl] = summary(values)
                if impl == "pinocchio_cpp":
                    stats["note"] = pinocchio_cpp.note_for(fname)
                elif impl == peer:
                    stats["note"] = peer_notes.get(fname, "")
            if timers[impl].build_seconds is not None:
                entry["build_seconds"][impl] = round(timers[impl].build_seconds, 2)
        # Wiring checks: every output for input 0 against the generated numpy code (Pinocchio:
        # on its own inputs, for the functions where it computes the very same array).
        for impl, got in outputs.items():
            if impl == "pinocchio_cpp":
                want = {f["name"]: reference_outputs(module, f, data) for f in functions
                        if f["name"] in got and module is not None and {p["name"] for p in f["inputs"]} <= data.keys()}
                if "fk_hom" in want:
                    want["fk_hom"] = [want["fk_hom"][0][:12]]  # Pinocchio prints the top 3 rows
            elif impl == peer:  # where it computes the same function, on the same inputs
                want = {f: w for f, w in refs.items() if f in got}
            else:
                want = refs
            entry["checks"][impl] = {f: _max_error(got.get(f, []), w) for f, w in want.items()}

    def _pinocchio_timer(self, name, model, functions, data, work):
        if not self.settings["pinocchio"]:
            self.note("Pinocchio C++ skipped (--quick: its header-only build takes minutes)")
            return None
        if model.length_symbols:
            self.note(f"{name}: symbolic DH lengths, no Pinocchio model, pinocchio_cpp skipped")
            return None
        log("pinocchio_cpp: building (header-only, minutes unless cached)")
        built = pinocchio_cpp.build_binary()
        if self.pinocchio_build is None:
            self.pinocchio_build = {"binary": built.path.name, "cached": built.cached, "seconds": _seconds(built)}
            log(f"pinocchio_cpp: {'cached' if built.cached else 'new'} build, {_seconds(built)} s to compile")
        return compiled.pinocchio(model, functions, data, built.path, work)

    def _pinocchio_casadi_timer(self, name, model, samples, work):
        if not self.settings["pinocchio"]:
            self.note("pinocchio_casadi_c skipped (--quick: its header-only tracer build takes minutes)")
            return None
        if model.length_symbols:
            self.note(f"{name}: symbolic DH lengths, no Pinocchio model, pinocchio_casadi_c skipped")
            return None
        log("pinocchio_casadi_c: building the tracer (header-only Pinocchio with casadi::SX, minutes unless cached)")
        built = pinocchio_casadi.build_tracer()
        if self.pinocchio_casadi_build is None:
            self.pinocchio_casadi_build = {"binary": built.path.name, "cached": built.cached, "seconds": _seconds(built),
                                           "tracer_flags": " ".join(pinocchio_casadi.FLAGS),
                                           "c_flags": " ".join(compiled.C_FLAGS[pinocchio_casadi.IMPL])}
            log(f"pinocchio_casadi_c: {'cached' if built.cached else 'new'} tracer build, {_seconds(built)} s to compile")
        log(f"{name}: pinocchio_casadi_c: tracing, generating C and building")
        return pinocchio_casadi.timer(model, built.path, samples, self.settings["K"], work)

    # -- from Python -------------------------------------------------------------------------
    def _python(self, name, module, model, functions, samples, entry):
        s = self.settings
        for f in functions:
            fn = getattr(module, f["name"])
            ports = [p["name"] for p in f["inputs"]]
            args = list(zip(*(samples[f["name"]][p] for p in ports)))
            log(f"{name}: python: {f['name']}")
            entry["functions"][f["name"]]["python"] = python_timing.per_call(fn, args, s["repeats"], s["py_target_s"])
            # Large outputs (regressors) are capped at ~256 MB per batch, so a big N does not
            # turn into a memory-bandwidth test; the N used is stored with the figure.
            out_size = sum(int(np.prod(p["shape"])) for p in f["outputs"])
            for count in s["batch_sizes"]:
                key = "python_batch" if count == max(s["batch_sizes"]) else f"python_batch_{count}"
                count = min(count, max(1000, 2**28 // (8 * out_size)))
                batch = inputs.sample(f, model, count, module, seed=1)
                stats = python_timing.per_configuration(
                    fn, tuple(batch[p] for p in ports), count, s["batch_repeats"] if count > 10_000 else s["repeats"])
                entry["functions"][f["name"]][key] = dict(stats, n=count)

    def _casadi_python(self, name, robot_dir, functions, samples, refs, entry):
        s = self.settings
        for f in functions:
            cf = casadi_codegen.load(robot_dir, f["name"])
            if cf is None:
                continue
            args = list(zip(*(samples[f["name"]][p["name"]] for p in f["inputs"])))
            log(f"{name}: casadi: {f['name']}")
            entry["functions"][f["name"]]["casadi"] = python_timing.per_call(cf, args, s["repeats"], s["py_target_s"])
            if f["name"] in refs:
                out = cf(*args[0])
                out = out if isinstance(out, (list, tuple)) else [out]
                got = [_flat(np.array(o)) for o in out]
                entry["checks"].setdefault("casadi", {})[f["name"]] = _max_error(got, refs[f["name"]])

    def _c_batch(self, name, model, module, robot_dir, functions, entry):
        """The batch variants against single calls of the same library (-O3 -march=native), N
        configurations per batch call; stored per configuration with the single-call time of
        the same run and their ratio."""
        n = self.settings["c_batch_n"]
        if n is None:
            self.note(f"{name}: c_batch skipped (--quick: two more builds of the whole library)")
            return
        log(f"{name}: c_batch: building and timing N = {n}")
        results = c_batch.time_batch(robot_dir, model, functions, n=n, repeats=self.settings["repeats"] // 3 or 1,
                                     rounds=self.settings["rounds"], target_ns=self.settings["c_target_ns"] / 10,
                                     workdir=self.workdir / name / "c_batch", python_module=module)
        for fname, row in results.items():
            entry["functions"][fname][c_batch.IMPL] = dict(row[c_batch.IMPL], n=n,
                                                           single_median_ns=row["c_single"]["median_ns"],
                                                           single_over_batch=row["ratio"])
            entry["checks"].setdefault(c_batch.IMPL, {})[fname] = row["max_error"]

    def _python_c(self, name, entry):
        """The generated C called from Python (python_c) against Pinocchio's Python bindings
        (pinocchio_python), one configuration per call, repeats taken in turn."""
        if not self.settings["compiled_python"]:
            self.note(f"{name}: python_c skipped (--quick: its extension build takes seconds)")
            return
        log(f"{name}: python_c and pinocchio_python")
        results = python_c_timing.measure(name, K=self.settings["K"], repeats=max(5, self.settings["repeats"] // 2),
                                          target_s=self.settings["py_target_s"], generated=self.generated,
                                          progress=log)
        for fname, row in results.items():
            for impl, stats in row.items():
                entry["functions"].setdefault(fname, {})[impl] = stats

    def warn_on_checks(self) -> None:
        for robot, entry in self.robots.items():
            for impl, per_function in entry["checks"].items():
                for fname, error in per_function.items():
                    if error is None or error > 1e-6:
                        self.note(f"{robot}: {impl} {fname} disagrees with the generated Python "
                                  f"code on input 0 (relative error {error}): its time may be meaningless")


def ratios(functions: dict) -> dict:
    """t(peer) / t(impl) for each peer in PEERS, keyed "peer/impl": above 1 means the
    generated implementation is faster."""
    out = {}
    for fname, impls in functions.items():
        row = {f"{peer}/{impl}": impls[peer]["median_ns"] / st["median_ns"]
               for peer in PEERS if peer in impls
               for impl, st in impls.items()
               if impl in ("c", "c_native", "casadi_codegen") and st["median_ns"] > 0}
        if impls.get("pinocchio_python") and impls.get("python_c"):
            row["pinocchio_python/python_c"] = impls["pinocchio_python"]["median_ns"] / impls["python_c"]["median_ns"]
        if row:
            out[fname] = row
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="tiny smoke-test setting, no Pinocchio C++ and no pinocchio_casadi_c")
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for timings.json and scaling.json")
    parser.add_argument("--generated", type=Path, default=GENERATED, help="generated code (default generated/)")
    parser.add_argument("--no-scaling", action="store_true", help="skip the generation-time scaling study")
    args = parser.parse_args(argv)
    settings = dict(QUICK if args.quick else FULL)
    started = time.perf_counter()
    bench = Bench(settings, args.generated, BUILD / ("work-quick" if args.quick else "work"))
    if args.quick:
        bench.note("quick mode: few repeats, small N, lwr4 only, C and CasADi's C at -O0 (times not meant), "
                   "no c_native, Pinocchio C++ and pinocchio_casadi_c skipped")
    for robot in settings["robots"]:
        bench.robot(robot, None if robot == PRIMARY else SECONDARY_IMPLS)
    bench.warn_on_checks()

    primary = bench.robots.get(PRIMARY, {"functions": {}, "ratios": {}, "opcounts": {}, "checks": {}})
    result = {
        "machine": machine(),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()} | {"quick": args.quick},
        "robot": PRIMARY,
        "functions": primary["functions"],
        "ratios": primary["ratios"],
        "opcounts": primary["opcounts"],
        "checks": primary["checks"],
        "build_seconds": primary.get("build_seconds", {}),
        "robots": {k: v for k, v in bench.robots.items() if k != PRIMARY},
        "pinocchio_build": bench.pinocchio_build,
        "pinocchio_casadi_build": bench.pinocchio_casadi_build,
        "notes": bench.notes,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "timings.json").write_text(strict_json(result, indent=1) + "\n")
    log(f"wrote {args.out / 'timings.json'} ({time.perf_counter() - started:.0f} s)")

    # kinematic trees with a floating base against both Pinocchio peers (results/trees.json);
    # not in --quick: compiling a humanoid's C takes minutes (python -m benchmarks.trees --quick
    # is its own smoke run)
    if not args.quick:
        trees.write(trees.run(dict(trees.FULL), log), args.out, log)

    if not args.no_scaling:
        study = scaling.study(range(2, settings["scaling_max_n"] + 1), settings["scaling_budget_s"], log=log)
        (args.out / "scaling.json").write_text(strict_json(study, indent=1) + "\n")
        log(f"wrote {args.out / 'scaling.json'} ({time.perf_counter() - started:.0f} s)")
        # trees: generation time and counts against n, and against Featherstone's formulas
        study = tree_scaling.study(dict(tree_scaling.QUICK if args.quick else tree_scaling.FULL), log=log)
        tree_scaling.write(study, args.out)
        log(f"wrote {args.out / 'tree_scaling.json'} ({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
