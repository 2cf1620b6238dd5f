"""CasADi's own C code generation ("casadi_codegen"): the saved Functions of one robot are
written to one C file by casadi.CodeGenerator and described as CFunctions for the C harness.

CasADi stores matrices column-major and only their structural non-zeros, so inputs are
handed over in that layout and outputs are rebuilt as dense row-major arrays for the wiring
check.
"""
from __future__ import annotations

from pathlib import Path

import casadi
import numpy as np

from .c_harness import CFunction


def load(robot_dir: Path, name: str):
    path = robot_dir / "casadi" / f"{name}.casadi"
    return casadi.Function.load(str(path)) if path.exists() else None


def _triplet(sparsity):
    rows, cols = sparsity.get_triplet()
    return np.asarray(rows, int), np.asarray(cols, int)


def to_casadi_layout(array: np.ndarray, sparsity) -> np.ndarray:
    """(K, *port shape) row-major -> (K, nnz) in CasADi's non-zero order."""
    K = array.shape[0]
    dense = array.reshape(K, sparsity.size1(), sparsity.size2())
    rows, cols = _triplet(sparsity)
    return np.ascontiguousarray(dense[:, rows, cols])


def from_casadi_layout(nonzeros: np.ndarray, sparsity) -> np.ndarray:
    """Non-zeros of one output -> dense row-major, flat."""
    dense = np.zeros((sparsity.size1(), sparsity.size2()))
    rows, cols = _triplet(sparsity)
    dense[rows, cols] = nonzeros
    return dense.ravel()


def generate(functions: dict, inputs: dict, workdir: Path, stem: str):
    """Write ``stem``.c for ``functions`` ({name: casadi.Function}); returns
    (C source path, prelude with the prototypes, [CFunction])."""
    workdir.mkdir(parents=True, exist_ok=True)
    opts = {"with_header": False, "casadi_real": "double", "casadi_int": "long long int"}
    generator = casadi.CodeGenerator(f"{stem}.c", opts)
    for f in functions.values():
        generator.add(f)
    generator.generate(str(workdir) + "/")
    sz_arg = max(f.sz_arg() for f in functions.values())
    sz_res = max(f.sz_res() for f in functions.values())
    sz_iw = max(f.sz_iw() for f in functions.values())
    sz_w = max(f.sz_w() for f in functions.values())
    prelude = [f"static const double *kb_arg[{max(sz_arg, 1)}];",
               f"static double *kb_res[{max(sz_res, 1)}];",
               f"static long long int kb_iw[{max(sz_iw, 1)}];",
               f"static double kb_w[{max(sz_w, 1)}];"]
    targets = []
    for name, f in functions.items():
        prelude.append(f"int {f.name()}(const double **arg, double **res, long long int *iw, double *w, int mem);")
        ins = [to_casadi_layout(inputs[name][f.name_in(i)], f.sparsity_in(i)) for i in range(f.n_in())]
        # kb_res is shared, so the output pointers are set on every call (two stores each,
        # negligible next to the call itself); inputs likewise.
        setup = [f"kb_arg[{i}] = {{in{i}}}" for i in range(f.n_in())]
        setup += [f"kb_res[{i}] = {{out{i}}}" for i in range(f.n_out())]
        call = ", ".join(setup + [f"{f.name()}(kb_arg, kb_res, kb_iw, kb_w, 0)"])
        outs = [(f.nnz_out(i), "double") for i in range(f.n_out())]
        targets.append(CFunction(name=name, call=call, inputs=ins, outputs=outs))
    return workdir / f"{stem}.c", "\n".join(prelude), targets
