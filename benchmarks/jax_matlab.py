"""JAX and MATLAB/Octave targets: timings in one run, against adam's JAX backend.

    .venv/bin/python -m benchmarks.jax_matlab [--robots lwr4,panda] [--batches 1,1000,100000]

JAX on CPU, 64-bit: the generated ``M`` and ``tau`` under ``jax.jit`` (batch 1: one configuration;
larger batches: ``jax.jit(jax.vmap(f))``) against adam-robotics' JAX backend on the same robot
(the URDF examples/dh_to_urdf.py writes of the DH description, checked there against Pinocchio):
adam's CRBA ``mass_matrix`` for M and ``mass_matrix @ [0; qdd] + bias_force`` (its RNEA) for tau,
fixed base (identity base transform, zero base velocity), jitted and vmapped the same way. Both
results are compared first (max difference in the JSON). Times are the median of repeats after
a warm-up call (compilation excluded; compile times reported separately), per batch, with
block_until_ready.

Octave: the generated .m files (vectorised over the trailing batch dimension) and the MEX
gateway around the generated C (built with mkoctfile --mex -O2), timed inside one Octave process
with tic/toc, per batch.

Writes benchmarks/results/jax_matlab.json and jax_matlab.png.
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json
from kindyngen.output_folder import replace_files

from .common import GENERATED, RESULTS, ROOT, cpu_model

sys.path.insert(0, str(ROOT / "examples"))
sys.path.insert(0, str(ROOT / "tests"))


def _load(path: Path, name: str):
    import importlib.util
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _time(fn, *args, repeats: int) -> float:
    """Median seconds of fn(*args) over repeats (a warm-up call first)."""
    fn(*args).block_until_ready()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn(*args).block_until_ready()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _repeats(batch: int) -> int:
    return 200 if batch == 1 else (30 if batch <= 1000 else 5)


def jax_run(robot_name: str, batches, progress) -> dict:
    import jax
    import jax.numpy as jnp
    jax.config.update("jax_enable_x64", True)
    from adam.jax import KinDynComputations
    from dh_to_urdf import urdf_string
    from kindyngen.readers.yaml_description import load_robot

    robot = load_robot(ROOT / "robots" / f"{robot_name}.yaml")
    ours = _load(GENERATED / robot_name / "jax" / f"{robot_name}_jax.py", f"bench_jax_{robot_name}")
    joints = [f"joint{i + 1}" for i in range(robot.n)]
    with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as f:
        f.write(urdf_string(robot))
    kd = KinDynComputations(f.name, joints, gravity=jnp.array(list(map(float, robot.gravity)) + [0.0, 0.0, 0.0]))
    base, n = jnp.eye(4), robot.n

    def adam_M(q):
        return kd.mass_matrix(base, q)[6:, 6:]

    def adam_tau(q, qd, qdd):
        M = kd.mass_matrix(base, q)
        h = kd.bias_force(base, q, jnp.zeros(6), qd)
        return (M @ jnp.concatenate([jnp.zeros(6), qdd]) + h)[6:]

    pairs = {"M": (ours.M, adam_M), "tau": (ours.tau, adam_tau)}
    rng = np.random.default_rng(0)
    out = {"robot": robot_name, "functions": {}}
    for name, (mine, peer) in pairs.items():
        row = {"batches": {}}
        q, qd, qdd = (jnp.asarray(rng.uniform(-1.5, 1.5, size=(8, n))) for _ in range(3))
        args = (q,) if name == "M" else (q, qd, qdd)
        row["max_abs_difference"] = float(jnp.max(jnp.abs(jax.vmap(mine)(*args) - jax.vmap(peer)(*args))))
        for batch in batches:
            q, qd, qdd = (jnp.asarray(rng.uniform(-1.5, 1.5, size=(batch, n))) for _ in range(3))
            args = (q,) if name == "M" else (q, qd, qdd)
            if batch == 1:
                args = tuple(a[0] for a in args)
            entry = {}
            for label, fn in (("kindyngen", mine), ("adam", peer)):
                jitted = jax.jit(fn if batch == 1 else jax.vmap(fn))
                start = time.perf_counter()
                jitted(*args).block_until_ready()
                entry[f"{label}_compile_s"] = time.perf_counter() - start
                entry[f"{label}_s"] = _time(jitted, *args, repeats=_repeats(batch))
            entry["speedup"] = entry["adam_s"] / entry["kindyngen_s"]
            row["batches"][str(batch)] = entry
            progress(f"jax {robot_name} {name} batch {batch}: ours {entry['kindyngen_s'] * 1e6:.1f} us, "
                     f"adam {entry['adam_s'] * 1e6:.1f} us ({entry['speedup']:.1f}x)")
        out["functions"][name] = row
    return out


OCTAVE_SCRIPT = """
addpath('{dir}');
robot = '{robot}'; n = {n}; batches = [{batches}]; funcs = {{{funcs}}};
fid = fopen('{out}', 'w');
rand('seed', 1);
for b = batches
  q = rand(n, b) * 2 - 1; qd = rand(n, b) * 2 - 1; qdd = rand(n, b) * 2 - 1;
  for f = funcs
    name = f{{1}};
    if strcmp(name, 'M'), args = {{q}}; else, args = {{q, qd, qdd}}; end
    mfile = str2func([robot '_' name]);
    for kind = {{'m', 'mex'}}
      if strcmp(kind{{1}}, 'm'), call = @() mfile(args{{:}}); else, call = @() feval([robot '_mex'], name, args{{:}}); end
      call();
      reps = max(3, min(200, ceil(2e4 / b)));
      t = zeros(1, reps);
      for r = 1:reps
        tic; call(); t(r) = toc;
      end
      fprintf(fid, '%s %s %d %.9g\\n', name, kind{{1}}, b, median(t));
    end
  end
end
fclose(fid);
"""


def octave_run(robot_name: str, batches, progress) -> dict | None:
    if shutil.which("octave-cli") is None or shutil.which("mkoctfile") is None:
        progress("octave or mkoctfile not installed: Octave timings left out")
        return None
    from kindyngen.readers.yaml_description import load_robot
    n = load_robot(ROOT / "robots" / f"{robot_name}.yaml").n
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        shutil.copytree(GENERATED / robot_name / "matlab", tmp / "matlab")
        shutil.copytree(GENERATED / robot_name / "c", tmp / "c")
        subprocess.run(["mkoctfile", "--mex", "-O2", "-I../c", f"{robot_name}_mex.c", f"../c/{robot_name}.c",
                        "-o", f"{robot_name}_mex"], cwd=tmp / "matlab", check=True, capture_output=True)
        script = OCTAVE_SCRIPT.format(dir=tmp / "matlab", robot=robot_name, n=n, out=tmp / "times.txt",
                                      batches=" ".join(map(str, batches)), funcs="'M', 'tau'")
        (tmp / "bench.m").write_text(script)
        subprocess.run(["octave-cli", "--no-init-file", "--quiet", "--no-window-system", str(tmp / "bench.m")],
                       check=True, capture_output=True)
        version = subprocess.run(["octave-cli", "--version"], capture_output=True, text=True).stdout.splitlines()[0]
        result = {"robot": robot_name, "octave": version, "functions": {}}
        for line in (tmp / "times.txt").read_text().splitlines():
            name, kind, batch, seconds = line.split()
            result["functions"].setdefault(name, {}).setdefault(batch, {})[kind + "_s"] = float(seconds)
            progress(f"octave {robot_name} {name} {kind} batch {batch}: {float(seconds) * 1e6:.1f} us")
    return result


def plot(results: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = results["jax"]
    fig, axes = plt.subplots(1, len(runs), figsize=(5.5 * len(runs), 4), squeeze=False)
    for ax, run in zip(axes[0], runs):
        for name, row in run["functions"].items():
            batches = [int(b) for b in row["batches"]]
            for label, style in (("kindyngen", "-o"), ("adam", "--s")):
                per_config = [row["batches"][str(b)][f"{label}_s"] / b * 1e9 for b in batches]
                ax.loglog(batches, per_config, style, label=f"{name} {label} (JAX jit)")
        octave = next((o for o in results["octave"] if o and o["robot"] == run["robot"]), None)
        if octave:
            for name, per_batch in octave["functions"].items():
                batches = sorted(int(b) for b in per_batch)
                for kind, style in (("m", ":^"), ("mex", ":v")):
                    ax.loglog(batches, [per_batch[str(b)][f"{kind}_s"] / b * 1e9 for b in batches], style,
                              label=f"{name} Octave {'.m' if kind == 'm' else 'MEX'}")
        ax.set_title(f"{run['robot']}: time per configuration")
        ax.set_xlabel("batch size")
        ax.set_ylabel("ns per configuration")
        ax.legend(fontsize=7)
    fig.suptitle(results["machine"]["cpu"], fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", default="lwr4,panda")
    p.add_argument("--batches", default="1,1000,100000")
    args = p.parse_args(argv)
    batches = [int(b) for b in args.batches.split(",")]

    def progress(text):
        print(f"jax_matlab: {text}", file=sys.stderr, flush=True)

    import os
    from importlib.metadata import version
    import jax
    results = {"machine": {"cpu": cpu_model(), "cores": os.cpu_count(), "jax": jax.__version__,
                           "adam": version("adam-robotics"), "load_average_start": os.getloadavg()},
               "jax": [], "octave": []}
    for robot_name in args.robots.split(","):
        results["jax"].append(jax_run(robot_name, batches, progress))
        results["octave"].append(octave_run(robot_name, batches, progress))
    results["machine"]["load_average_end"] = os.getloadavg()

    def both(folder):          # the JSON and its figure, both or neither
        (folder / "jax_matlab.json").write_text(strict_json(results, indent=1) + "\n")
        plot(results, folder / "jax_matlab.png")
    replace_files(RESULTS, both)
    progress(f"wrote {RESULTS / 'jax_matlab.json'} and jax_matlab.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
