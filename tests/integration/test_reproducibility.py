"""generated/ is a function of robots/ alone, not of the processor: every robots/*.yaml,
generated afresh under several OpenBLAS kernels and with numpy's SIMD dispatch limited, gives
byte for byte the committed tree.

The kernels are forced with OPENBLAS_CORETYPE in subprocesses; each run first reports (through
threadpoolctl) which kernel numpy and scipy really use, so a run whose setting was ignored
cannot pass for a different kernel.  A kernel this processor cannot execute (SkylakeX needs
AVX-512) is left out, and at least three different kernels must have run."""
from __future__ import annotations

import json
import os
import subprocess
import sys


from tests.harness import GENERATED, HANG_GUARD_S, ROOT

KERNELS = ("Haswell", "SkylakeX", "Sandybridge", "Prescott")
MIN_KERNELS = 3
PROBE = ("import json, numpy, scipy.linalg, threadpoolctl; "
         "numpy.linalg.qr(numpy.ones((40, 40))); scipy.linalg.qr(numpy.ones((40, 40))); "
         "print(json.dumps(sorted({i.get('architecture', '?') for i in threadpoolctl.threadpool_info() "
         "if i.get('internal_api') == 'openblas'})))")


def _robots():
    return sorted((ROOT / "robots").glob("*.yaml"))


def _dispatched_simd() -> str:
    """numpy's dispatched SIMD targets this processor has (all of them get disabled)."""
    from numpy._core import _multiarray_umath as umath
    return " ".join(f for f in umath.__cpu_dispatch__ if umath.__cpu_features__.get(f))


def _environments() -> dict[str, dict]:
    base = dict(os.environ)
    envs = {"default": base}
    for kernel in KERNELS:
        envs[kernel] = {**base, "OPENBLAS_CORETYPE": kernel}
    envs["Prescott, numpy SIMD off"] = {**base, "OPENBLAS_CORETYPE": "Prescott",
                                        "NPY_DISABLE_CPU_FEATURES": _dispatched_simd()}
    return envs


def _probe(env: dict) -> list[str] | None:
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True,
                          timeout=HANG_GUARD_S)
    return json.loads(done.stdout) if done.returncode == 0 else None


def _tree(root):
    """{relative path: bytes} of the generated files; bytecode is left out: a test (or a
    worker running beside this one) that imports a committed Python module writes
    __pycache__ there unless PYTHONDONTWRITEBYTECODE is set, and it is no generated output."""
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and "__pycache__" not in p.parts}


def test_committed_tree_has_one_folder_per_description():
    from kindyngen.readers.yaml_description import load_robot
    expected = {load_robot(path).identifier for path in _robots()}
    assert {p.name for p in GENERATED.iterdir() if p.is_dir()} == expected


def test_generation_is_identical_under_every_blas_kernel(tmp_path):
    runs = {}
    for label, env in _environments().items():
        kernels = _probe(env)
        if kernels is None:
            print(f"{label}: cannot run on this processor, left out")
            continue
        if "OPENBLAS_CORETYPE" in env:   # numpy and scipy must both run the one forced kernel
            assert len(kernels) == 1, f"{label}: numpy and scipy run different kernels {kernels}"
        runs[label] = (env, kernels)
    # OpenBLAS names a kernel by its own table (Prescott runs as 'Katmai'): count what really ran
    ran = {kernels[0] for env, kernels in runs.values() if "OPENBLAS_CORETYPE" in env}
    if "default" in runs and len(runs["default"][1]) == 1 and runs["default"][1][0] in ran:
        # the processor's own kernel is one of the forced ones: the same generation twice
        print(f"default: runs the forced kernel {runs['default'][1][0]}, left out")
        del runs["default"]
    assert len(ran) >= MIN_KERNELS, f"only the kernels {sorted(ran)} could run; need {MIN_KERNELS}"
    assert "Prescott, numpy SIMD off" in runs

    robots = [str(p) for p in _robots()]
    pending = list(runs.items())
    active = []
    while pending or active:   # two generations at a time (CI has two cores)
        while pending and len(active) < 2:
            label, (env, _) = pending.pop(0)
            out = tmp_path / label.replace(" ", "_").replace(",", "")
            proc = subprocess.Popen([sys.executable, "-m", "kindyngen", "generate", *robots, "--out", str(out),
                                     "--quiet"], env=env, cwd=ROOT, stderr=subprocess.PIPE, text=True)
            active.append((label, out, proc))
        label, out, proc = active.pop(0)
        _, err = proc.communicate(timeout=HANG_GUARD_S)
        assert proc.returncode == 0, f"{label}: generation failed: {err}"
        committed = _tree(GENERATED)
        fresh = _tree(out)
        assert sorted(fresh) == sorted(committed), f"{label}: file lists differ from generated/"
        differing = [str(rel) for rel in fresh if fresh[rel] != committed[rel]]
        assert not differing, (f"{label} (OpenBLAS {runs[label][1]}): {len(differing)} files differ from the "
                               f"committed generated/, e.g. {differing[:5]}; run `make generate` if the change is wanted")
        print(f"{label} (OpenBLAS {runs[label][1]}): {len(fresh)} files identical")
