"""Generic damped least-squares IK (``ik_dls``, kindyngen/ik/damped_least_squares.py): the generated code in
every language, on reachable targets (FK of random in-limit configurations, independent
numpy DH product), from random and from nearby starts; unreachable and invalid input;
agreement between C, Python and CasADi; its functions.json entry and header.

Run with ``-s`` to see the measured success rates."""
import json
import shutil
import subprocess
import sys
from functools import lru_cache

import numpy as np
import pytest

from kindyngen.runtime.evaluate import EvaluationError, load_generated
from kindyngen.ik.damped_least_squares import CONSTANTS
from tests.harness import GENERATED, ROOT, evaluate, robot
from tests.reference import fk_numpy, random_configurations

ROBOTS = ("panda", "lwr4")
LANGS = ("c", "python", "casadi")
COUNT = 500
NEAR = 0.3   # rad: "near" starts are within this of the configuration that produced the target
# Floors below the measured rates (printed; see the report of issue 5): from random starts
# about 99 % for both arms, from near starts 99.8-100 %; the failures are targets at or
# next to a singularity (e.g. the LWR's elbow stretched, q4 ~ 0), where the error falls
# too slowly to reach 1e-10 within the iteration limit.
FLOOR_RANDOM = 0.95
FLOOR_NEAR = 0.99


@lru_cache(maxsize=None)
def targets(name: str):
    model = robot(name)
    q_star = random_configurations(model, COUNT, seed=2024)
    T = np.array([fk_numpy(model, q) for q in q_star])
    rng = np.random.default_rng(5)
    starts = {"random": random_configurations(model, COUNT, seed=77),
              "near": np.clip(q_star + rng.uniform(-NEAR, NEAR, q_star.shape), model.lower, model.upper)}
    return q_star, T, starts


@lru_cache(maxsize=None)
def solve(name: str, lang: str, start: str):
    _, T, starts = targets(name)
    out = evaluate(name, lang, "ik_dls", T=T, q0=starts[start])
    return out["q"], out["status"]


def pose_error(model, q, T):
    return np.abs(fk_numpy(model, q) - T).max()


@pytest.mark.parametrize("start", ["random", "near"])
@pytest.mark.parametrize("lang", LANGS)
@pytest.mark.parametrize("name", ROBOTS)
def test_success_rate_and_converged_solutions_are_exact(name, lang, start):
    model = robot(name)
    _, T, _ = targets(name)
    q, status = solve(name, lang, start)
    assert q.shape == (COUNT, model.n) and status.shape == (COUNT, 1) and status.dtype.kind == "i"
    status = status[:, 0]
    rate = np.mean(status == 0)
    print(f"\nik_dls {name} {lang} from {start} starts: {100 * rate:.1f} % converged "
          f"({np.sum(status == 0)}/{COUNT}), status counts {np.bincount(status, minlength=4).tolist()}")
    assert set(status.tolist()) <= {0, 2}          # reachable, valid targets: converged or not
    assert rate >= (FLOOR_RANDOM if start == "random" else FLOOR_NEAR)
    for k in np.flatnonzero(status == 0):
        assert pose_error(model, q[k], T[k]) < 1e-9, k
    assert np.all(q >= model.lower) and np.all(q <= model.upper)
    assert np.all(np.isfinite(q))


@pytest.mark.parametrize("name", ROBOTS)
def test_languages_agree(name):
    """Same algorithm and operation order: same status everywhere; the converged poses agree
    (q itself may differ along the self-motion of the redundant arm after many iterations)."""
    model = robot(name)
    for start in ("random", "near"):
        q_c, s_c = solve(name, "c", start)
        for lang in ("python", "casadi"):
            q_l, s_l = solve(name, lang, start)
            np.testing.assert_array_equal(s_l, s_c, err_msg=f"{name} {lang} {start}")
            for k in np.flatnonzero(s_c[:, 0] == 0):
                assert np.abs(fk_numpy(model, q_l[k]) - fk_numpy(model, q_c[k])).max() < 2e-9
            close = np.abs(q_l - q_c).max(axis=1) < 1e-9
            assert close.mean() > 0.9, (lang, start, close.mean())


@pytest.mark.parametrize("lang", LANGS)
@pytest.mark.parametrize("name", ROBOTS)
def test_start_at_the_solution_returns_it(name, lang):
    q_star, T, _ = targets(name)
    out = evaluate(name, lang, "ik_dls", T=T[:20], q0=q_star[:20])
    assert np.all(out["status"] == 0)
    np.testing.assert_allclose(out["q"], q_star[:20], atol=1e-9)


@pytest.mark.parametrize("lang", LANGS)
@pytest.mark.parametrize("name", ROBOTS)
def test_rotation_error_near_pi(name, lang):
    """Start with the last joint turned by almost pi (and exactly pi where the limits allow):
    the first rotation error is near pi, where the log map takes the axis from the symmetric
    part of R* R^T."""
    model = robot(name)
    q_star, T, _ = targets(name)
    last = model.n - 1
    pick = np.flatnonzero(q_star[:, last] < model.upper[last] - np.pi)[:10]
    q0 = q_star[pick].copy()
    q0[:, last] += np.pi - np.tile([0.0, 1e-7, 1e-3, 0.3, 1e-10], 2)[:len(pick)]
    assert len(pick) >= 5 and np.all(q0[:, last] <= model.upper[last])
    out = evaluate(name, lang, "ik_dls", T=T[pick], q0=q0)
    assert np.all(out["status"] == 0), out["status"].ravel()
    for k, j in enumerate(pick):
        assert pose_error(model, out["q"][k], T[j]) < 1e-9


@pytest.mark.parametrize("lang", LANGS)
@pytest.mark.parametrize("name", ROBOTS)
def test_unreachable_targets_give_status_2_and_the_best_iterate(name, lang):
    model = robot(name)
    _, T, starts = targets(name)
    far = T[:10].copy()
    far[:, 0, 3] += 2.0                              # 2 m beyond a reachable position
    out = evaluate(name, lang, "ik_dls", T=far, q0=starts["random"][:10])
    assert np.all(out["status"] == 2)
    q = out["q"]
    assert np.all(np.isfinite(q)) and np.all(q >= model.lower) and np.all(q <= model.upper)
    # the best iterate is at least as close as the start
    for k in range(10):
        start_distance = np.linalg.norm(fk_numpy(model, np.clip(starts["random"][k], model.lower, model.upper))[:3, 3]
                                        - far[k, :3, 3])
        assert np.linalg.norm(fk_numpy(model, q[k])[:3, 3] - far[k, :3, 3]) <= start_distance + 1e-12


@pytest.mark.parametrize("lang", LANGS)
@pytest.mark.parametrize("name", ROBOTS)
def test_invalid_input_gives_status_3_and_clamped_start(name, lang):
    model = robot(name)
    q_star, T, _ = targets(name)
    n = model.n
    q0 = np.linspace(-4.0, 4.0, n)                   # partly outside the limits
    clamped = np.clip(q0, model.lower, model.upper)
    nan_T, inf_T, skewed, reflected, scaled = (T[0].copy() for _ in range(5))
    nan_T[1, 2] = np.nan
    inf_T[0, 3] = np.inf
    skewed[0, 1] += 1e-5                             # rotation not orthonormal to 1e-6
    reflected[:3, 0] *= -1.0                         # orthonormal, but det = -1
    scaled[:3, :3] *= 1.0 + 2e-6
    cases = [(nan_T, q0, clamped), (inf_T, q0, clamped), (skewed, q0, clamped), (reflected, q0, clamped),
             (scaled, q0, clamped)]
    nan_q0 = q0.copy()
    nan_q0[[0, n - 1]] = [np.nan, -np.inf]
    expected = clamped.copy()
    expected[[0, n - 1]] = 0.0
    cases.append((T[0], nan_q0, expected))
    out = evaluate(name, lang, "ik_dls", T=np.array([c[0] for c in cases]), q0=np.array([c[1] for c in cases]))
    assert out["status"].ravel().tolist() == [3] * len(cases)
    np.testing.assert_array_equal(out["q"], np.array([c[2] for c in cases]))
    # a rotation orthonormal to 1e-7 is accepted (and the IK converges to its nearest rotation)
    nearly = T[0].copy()
    nearly[:3, :3] *= 1.0 + 1e-7
    assert evaluate(name, lang, "ik_dls", T=nearly[None], q0=q_star[:1])["status"][0, 0] in (0, 2)


def test_python_broadcasts_and_returns_batch_shapes():
    module = load_generated(GENERATED / "panda", "python")._impl.module
    q_star, T, starts = targets("panda")
    q, status = module.ik_dls(T[0], starts["near"][:3])      # one target, three starts
    assert q.shape == (3, 7) and status.shape == (3, 1) and status.dtype == np.int64
    q1, status1 = module.ik_dls(T[0], starts["near"][0])
    assert q1.shape == (7,) and status1.shape == (1,)
    np.testing.assert_array_equal(q1, q[0])
    with pytest.raises(ValueError, match="q0"):
        module.ik_dls(T[0], np.zeros(6))


def test_deterministic():
    _, T, starts = targets("panda")
    first = evaluate("panda", "c", "ik_dls", T=T[:50], q0=starts["random"][:50])
    again = evaluate("panda", "c", "ik_dls", T=T[:50], q0=starts["random"][:50])
    np.testing.assert_array_equal(first["q"], again["q"])
    np.testing.assert_array_equal(first["status"], again["status"])


@pytest.mark.parametrize("name", ("lwr4", "lwr4_hartl", "panda"))
def test_manifest_entry_and_header(name):
    manifest = json.loads((GENERATED / name / "functions.json").read_text())
    functions = {f["name"]: f for f in manifest["functions"]}
    entry = functions["ik_dls"]
    assert entry["kind"] == "iterative" and entry["c_symbol"] == f"{name}_ik_dls"
    assert [(p["name"], p["shape"], p["dtype"]) for p in entry["inputs"]] == [("T", [4, 4], "double"),
                                                                             ("q0", [manifest["n"]], "double")]
    assert [(p["name"], p["shape"], p["dtype"]) for p in entry["outputs"]] == [("q", [manifest["n"]], "double"),
                                                                              ("status", [1], "int")]
    assert "before" not in entry["opcount"] and "after" not in entry["opcount"]
    per = entry["opcount"]["per_iteration"]
    assert per["fk_hom"] == functions["fk_hom"]["opcount"]["after"]
    assert per["jacobian"] == functions["jacobian"]["opcount"]["after"]
    assert entry["opcount"]["max_iterations"] == CONSTANTS["MAX_ITERATIONS"][0] == 200
    header = (GENERATED / name / "c" / f"{name}.h").read_text()
    declaration = f"void {name}_ik_dls(const double *T, const double *q0, double *q, int *status);"
    assert declaration in header
    comment = header[header.index("* ik_dls:"):header.index(declaration)]
    fk = per["fk_hom"]
    assert "Cost per iteration: one fk_hom + one jacobian + a 6x6 solve" in comment
    assert f"fk_hom ({fk['add']} add, {fk['mul']} mul, {fk['call']} call)" in comment
    for word in ("MAX_ITERATIONS = 200", "TOL_POSITION = 1e-10", "TOL_ROTATION = 1e-10", "[rad]",
                 "0: converged", "1: converged but outside", "2: not converged", "3: invalid input"):
        assert word in comment, word
    source = (GENERATED / name / "c" / f"{name}.c").read_text()
    body = source[source.index(f"void {name}_ik_dls("):]
    assert f"{name}_fk_hom(qn, F);" in body and f"{name}_jacobian(q, J);" in body


def test_eval_command_and_language_guard(tmp_path):
    _, T, starts = targets("panda")
    payload = json.dumps({"T": T[0].tolist(), "q0": starts["near"][0].tolist()})
    results = {}
    for lang in LANGS:
        done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(GENERATED / "panda"), "ik_dls",
                               "--lang", lang], input=payload, capture_output=True, text=True, cwd=ROOT, check=True)
        results[lang] = json.loads(done.stdout)
    assert all(r["status"] == [0] for r in results.values()), results
    # a function the manifest lists for some languages only is a clear error in the others
    copy = tmp_path / "panda"
    shutil.copytree(GENERATED / "panda", copy)
    manifest = json.loads((copy / "functions.json").read_text())
    next(f for f in manifest["functions"] if f["name"] == "ik_dls")["languages"] = ["c", "python"]
    (copy / "functions.json").write_text(json.dumps(manifest))
    with pytest.raises(EvaluationError, match="ik_dls is not generated for casadi"):
        load_generated(copy, "casadi").call("ik_dls", {"T": T[0], "q0": starts["near"][0]})
    (copy / "casadi" / "ik_dls.casadi").unlink()
    done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(copy), "ik_dls", "--lang", "casadi"],
                          input=payload, capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and "not generated for casadi" in done.stderr


@pytest.fixture(scope="module")
def symbolic_lengths_lwr(tmp_path_factory):
    root = tmp_path_factory.mktemp("ik_dls_lengths")
    text = (ROOT / "robots" / "lwr4.yaml").read_text()
    text = text.replace("d: 0.40,", "d: l1,").replace("d: 0.39,", "d: l2,").replace("name: lwr4", "name: lwr4_len")
    (root / "lwr4_len.yaml").write_text(text)
    subprocess.run([sys.executable, "-m", "kindyngen", "generate", str(root / "lwr4_len.yaml"), "--out", str(root),
                    "--quiet", "--lang", "c,python"], check=True, cwd=ROOT)
    return root / "lwr4_len"


@pytest.mark.parametrize("lang", ["c", "python"])
def test_symbolic_lengths_are_passed_through(symbolic_lengths_lwr, lang):
    """A robot with symbolic DH lengths: ik_dls takes `lengths` last, like every function,
    and hands it to fk_hom and jacobian; at the numeric values it equals the numeric robot."""
    _, T, starts = targets("lwr4")
    lib = load_generated(symbolic_lengths_lwr, lang)
    assert [p["name"] for p in lib.functions["ik_dls"]["inputs"]] == ["T", "q0", "lengths"]
    got = lib.call("ik_dls", {"T": T[:30], "q0": starts["random"][:30], "lengths": np.tile([0.40, 0.39], (30, 1))})
    want = evaluate("lwr4", lang, "ik_dls", T=T[:30], q0=starts["random"][:30])
    np.testing.assert_array_equal(got["status"], want["status"])
    # the two robots' jacobians round differently (symbolic lengths stay in the code), and over
    # many iterations q may drift along the redundant arm's self-motion (as between languages,
    # test_languages_agree): the converged poses must agree, q for most targets to 1e-9
    model = robot("lwr4")
    for k in np.flatnonzero(want["status"].ravel() == 0):
        assert np.abs(fk_numpy(model, got["q"][k]) - T[k]).max() < 2e-9, k
    close = np.abs(got["q"] - want["q"]).max(axis=1) < 1e-9
    assert close.mean() > 0.9, close.mean()
