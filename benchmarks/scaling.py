"""How generation time and operation count grow with the number of joints, per derivation
route, on synthetic chains of n = 2 ... 12 revolute joints.

A route is a builder registered in kindyngen.codegen.catalog.BUILDERS whose name is a family (M, c,
tau, and g) or starts with the family and an underscore (M_lagrange, c_christoffel, tau_rnea, ...);
fk_hom and jacobian are timed as a baseline. Routes that do not exist are simply absent.
Each route runs in a forked worker so that one that blows up can be stopped: a route stops
growing n once the next size is predicted to exceed the budget, and the parent kills a
worker that goes silent for three budgets.
"""
from __future__ import annotations

import multiprocessing
import queue
import time

FAMILIES = ("M", "c", "tau", "g")
BASELINE = ("fk_hom", "jacobian")


def synthetic_chain(n: int):
    """An n-joint arm in the style of the LWR: alternating twists of +-pi/2, some link
    lengths and offsets non-zero, masses decreasing towards the tip, full inertia tensors."""
    from kindyngen.readers.yaml_description import parse_robot
    joints, links = [], []
    for i in range(n):
        joints.append({"a": 0.05 if i % 3 == 1 else 0, "alpha": 0 if i == n - 1 else ("pi/2" if i % 2 == 0 else "-pi/2"),
                       "d": 0.3 if i % 2 == 0 else 0, "offset": 0, "lower": -2.9, "upper": 2.9})
        m = 3.0 * 0.85 ** i
        s = m / 3.0
        links.append({"mass": m, "com": [0.001 * (i + 1), -0.02 + 0.004 * i, 0.05 - 0.01 * (i % 3)],
                      "inertia": [0.02 * s, 0.018 * s, 0.01 * s, 0.0003 * s, -0.0002 * s, 0.0004 * s]})
    return parse_robot({"name": f"chain{n}", "dh": "standard", "gravity": [0, 0, -9.81],
                        "joints": joints, "links": links}, source=f"<synthetic chain n={n}>")


def routes() -> dict:
    """{route name: family} for what the catalogue offers now."""
    from kindyngen.codegen.catalog import BUILDERS
    found = {}
    for name, _ in BUILDERS:
        family = name.split("_", 1)[0] if "_" in name else name
        if family in FAMILIES or name in BASELINE:
            found[name] = name if name in BASELINE else family
    return found


def measure(route: str, n: int) -> dict | None:
    from kindyngen.codegen.catalog import derive_all
    from kindyngen.codegen.optimize import optimize
    model = synthetic_chain(n)
    start = time.perf_counter()
    functions = derive_all(model, "numeric", only={route})
    derived = time.perf_counter()
    if not functions:
        return None
    program = optimize(functions[0])
    done = time.perf_counter()
    return {"n": n, "derive_s": derived - start, "optimize_s": done - derived, "total_s": done - start,
            "before": program.before.to_json(), "after": program.after.to_json()}


def _worker(route, sizes, budget_s, out):
    previous = None
    try:
        measure(route, sizes[0])  # warm-up: first-call costs (imports, caches) are not generation time
    except Exception:
        pass  # reported by the real attempt below
    for n in sizes:
        try:
            row = measure(route, n)
        except Exception as exc:  # a route that fails at some n: report it, stop the route
            out.put(("error", n, f"{type(exc).__name__}: {exc}"))
            break
        if row is None:
            break
        out.put(("row", n, row))
        growth = max(2.0, row["total_s"] / previous) if previous else 4.0
        if n != sizes[-1] and row["total_s"] * growth > budget_s:
            out.put(("stopped", n, f"next size predicted to take over {budget_s:.0f} s"))
            break
        previous = max(row["total_s"], 1e-3)
    out.put(("done", None, None))


def study(sizes, budget_s: float, log=print) -> dict:
    """{"budget_s", "routes": {route: {"family", "rows": [...], "stopped": str|None}}}."""
    sizes = list(sizes)
    result = {"budget_s": budget_s, "sizes": sizes, "routes": {}}
    context = multiprocessing.get_context("fork")
    for route, family in routes().items():
        out = context.Queue()
        worker = context.Process(target=_worker, args=(route, sizes, budget_s, out), daemon=True)
        worker.start()
        entry = {"family": family, "rows": [], "stopped": None}
        while True:
            try:
                kind, n, payload = out.get(timeout=3 * budget_s)
            except queue.Empty:
                worker.kill()
                entry["stopped"] = f"killed: no result within {3 * budget_s:.0f} s"
                break
            if kind == "done":
                break
            if kind == "row":
                entry["rows"].append(payload)
                log(f"scaling: {route} n={n}: {payload['total_s']:.2f} s, after CSE {payload['after']}")
            else:
                entry["stopped"] = f"n={n}: {payload}"
        worker.join(timeout=5)
        result["routes"][route] = entry
    return result
