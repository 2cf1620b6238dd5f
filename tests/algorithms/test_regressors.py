"""Regressors on base parameters (issue 4): ranks, the paper's pi_g, generated Y_g / Y_m / Y
against Pinocchio, the base-parameter map against Pinocchio's own full regressor, and the
paper's coefficient collection.

Reference values come from Pinocchio (crba, computeGeneralizedGravity, rnea,
computeJointTorqueRegressor) on the model of tests/reference.py, and from the paper's text."""
import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
import sympy

from tests.harness import GENERATED, evaluate, robot
from tests.reference import pinocchio_model, random_configurations
from kindyngen.algorithms.paper_parameters import barycentric_in_paper, paper_in_barycentric, paper_symbols
from kindyngen.algorithms.regressors import base_parameters, base_params_document, regressor

ROBOTS = ("lwr4", "lwr4_hartl", "panda")
KINDS = ("Y_g", "Y_m", "Y")


def lower_stack(M):
    n = M.shape[0]
    return np.array([M[i, j] for i in range(n) for j in range(i + 1)])


def pin_full_regressors(rob, Q, QD, QDD):
    """Pinocchio's full regressors (10 n columns, its parameter order) stacked over samples:
    gravity (qd = qdd = 0), inertia stack (gravity off, column j of M from qdd = e_j), torque."""
    model, data, _ = pinocchio_model(rob)
    zero = np.zeros(rob.n)
    Yg = np.array([pin.computeJointTorqueRegressor(model, data, q, zero, zero).copy() for q in Q])
    Yt = np.array([pin.computeJointTorqueRegressor(model, data, q, qd, qdd).copy() for q, qd, qdd in zip(Q, QD, QDD)])
    model.gravity = pin.Motion.Zero()
    data = model.createData()
    Ym = []
    for q in Q:
        cols = [pin.computeJointTorqueRegressor(model, data, q, zero, np.eye(rob.n)[j]).copy() for j in range(rob.n)]
        Ym.append(np.array([cols[j][i] for i in range(rob.n) for j in range(i + 1)]))  # M_ij, j <= i
    return Yg, np.array(Ym), Yt


def samples(rob, count, seed):
    rng = np.random.default_rng(seed)
    return random_configurations(rob, count, seed), rng.normal(size=(count, rob.n)), rng.normal(size=(count, rob.n))


# ----------------------------------------------------------------------------- ranks

@pytest.mark.parametrize("kind, expected", [("Y_g", 12), ("Y_m", 39), ("Y", 43)])
def test_lwr4_ranks(kind, expected):
    b = base_parameters(robot("lwr4"), kind)
    assert b.rank == expected
    assert len(b.base) == expected and len(b.names) == expected
    f = regressor(robot("lwr4"), kind)
    assert f.outputs[0].name == "Y"
    assert f.outputs[0].shape[1] == expected


@pytest.mark.parametrize("name", ROBOTS)
def test_ranks_agree_with_pinocchio_full_regressor(name):
    """Independent ranks: SVD of Pinocchio's stacked full regressors."""
    rob = robot(name)
    Q, QD, QDD = samples(rob, 30, 7)
    Yg, Ym, Yt = pin_full_regressors(rob, Q, QD, QDD)
    for kind, A in (("Y_g", Yg), ("Y_m", Ym), ("Y", Yt)):
        A = A.reshape(-1, A.shape[-1])
        sv = np.linalg.svd(A, compute_uv=False)
        assert base_parameters(rob, kind).rank == int(np.sum(sv > 1e-9 * sv[0])), (name, kind)


def test_tilted_gravity_gives_rank_45():
    rob = replace(robot("lwr4"), gravity=(0.9, -1.3, -9.7), name="lwr4_tilted")
    b = base_parameters(rob, "Y")
    assert b.rank == 45
    Q, QD, QDD = samples(rob, 30, 8)
    _, _, Yt = pin_full_regressors(rob, Q, QD, QDD)
    sv = np.linalg.svd(Yt.reshape(-1, 70), compute_uv=False)
    assert int(np.sum(sv > 1e-9 * sv[0])) == 45
    assert base_parameters(rob, "Y_g").zero_rows == ()


def test_first_gravity_row_is_zero_on_a_level_base():
    assert base_parameters(robot("lwr4"), "Y_g").zero_rows == (0,)
    Q = random_configurations(robot("lwr4"), 10, 3)
    Y = evaluate("lwr4", "python", "Y_g", q=Q)["Y"]
    assert np.all(Y[:, 0, :] == 0.0)
    assert np.abs(Y[:, 1:, :]).max() > 1.0


# ----------------------------------------------------------------------------- pi_g, eq. 28

m = {i: sympy.Symbol(f"m{i}") for i in range(1, 8)}
c = {(i, a): sympy.Symbol(f"c{i}{a}") for i in range(1, 8) for a in "xyz"}
d1, d2 = sympy.symbols("d1 d2")

# the paper's eq. 28, written from the paper (d1 = 0.40 m, d2 = 0.39 m)
EQ28 = (
    c[7, "y"] * m[7],
    c[7, "x"] * m[7],
    c[6, "x"] * m[6],
    c[6, "z"] * m[6] + c[7, "z"] * m[7],
    c[5, "z"] * m[5] - c[6, "y"] * m[6],
    c[5, "x"] * m[5],
    c[5, "y"] * m[5] + c[4, "z"] * m[4] + d2 * (m[5] + m[6] + m[7]),
    c[4, "x"] * m[4],
    c[4, "y"] * m[4] + c[3, "z"] * m[3],
    c[2, "x"] * m[2],
    c[3, "x"] * m[3],
    c[2, "z"] * m[2] - c[3, "y"] * m[3] + d1 * (m[3] + m[4] + m[5] + m[6] + m[7]),
)


def same_up_to_sign(a, b):
    return sympy.expand(a - b) == 0 or sympy.expand(a + b) == 0


def match_entries(found, expected):
    """Pair every expected expression with a distinct found one (up to sign)."""
    left = list(found)
    for e in expected:
        hit = [k for k, f in enumerate(left) if same_up_to_sign(f, e)]
        assert hit, f"eq. 28 entry {e} not found among {left}"
        left.pop(hit[0])
    assert not left


def test_paper_collection_of_g_is_eq28():
    from tests.algorithms.paper_coefficients import collect_gravity
    col = collect_gravity(robot("lwr4"))
    assert col.rows == ("g2", "g3", "g4", "g5", "g6", "g7")      # g1 vanishes and is dropped
    assert len(col.coefficients) == 12
    rename = {sympy.Symbol("d3"): d1, sympy.Symbol("d5"): d2}  # DH rows 3 and 5 carry the paper's d1, d2
    match_entries([k.xreplace(rename) for k in col.coefficients], EQ28)
    assert col.numeric_rank() == 12


def test_base_parameters_of_gravity_are_eq28():
    """Our pi_g (barycentric base parameters of Y_g, mapped to the paper's parameters) is
    eq. 28 entry by entry, up to sign, at the LWR's d1, d2."""
    from kindyngen.algorithms.paper_parameters import base_expressions_in_paper
    found = base_expressions_in_paper(robot("lwr4"), "Y_g")
    lengths = {d1: sympy.Rational(2, 5), d2: sympy.Rational(39, 100)}
    match_entries(found, [sympy.expand(e.xreplace(lengths)) for e in EQ28])


def test_paper_collections_reproduce_g_and_the_inertia_stack():
    """Y(q) pi from the paper's collection equals Pinocchio's g and M stack (validates the
    expansion and collection), and spans our base regressor."""
    from tests.algorithms.paper_coefficients import collect_gravity, collect_inertia
    rob = robot("lwr4")
    model, data, _ = pinocchio_model(rob)
    values = {}
    for i, link in enumerate(rob.links, start=1):
        values[sympy.Symbol(f"m{i}")] = link.mass
        for a, v in zip("xyz", link.com):
            values[sympy.Symbol(f"c{i}{a}")] = v
        for k, v in zip(("xx", "yy", "zz", "xy", "xz", "yz"), link.inertia):
            values[sympy.Symbol(f"I{i}{k}")] = v
    Q = random_configurations(rob, 6, 11)
    g_col, m_col = collect_gravity(rob), collect_inertia(rob)
    Yg, Ym = g_col.numeric(Q), m_col.numeric(Q)
    pg, pm = g_col.value(values), m_col.value(values)
    for k, q in enumerate(Q):
        np.testing.assert_allclose(Yg[k] @ pg, pin.computeGeneralizedGravity(model, data, q)[1:], atol=1e-10)
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        np.testing.assert_allclose(Ym[k] @ pm, lower_stack(M), atol=1e-10)
    # every base column is a combination of the paper's columns
    Q = random_configurations(rob, 40, 12)
    A = m_col.numeric(Q).reshape(-1, len(m_col.coefficients))
    B = evaluate("lwr4", "python", "Y_m", q=Q)["Y"].reshape(-1, 39)
    X = np.linalg.lstsq(A, B, rcond=None)[0]
    assert np.abs(A @ X - B).max() < 1e-9


def test_eq27_m76_as_in_the_paper():
    """M_76 = c7y c7z m7 cos q7 - I7xz sin q7 - I7yz cos q7 + c7x c7z m7 sin q7 (paper, Sect. VI)."""
    from tests.algorithms.paper_coefficients import paper_dynamics
    _, M = paper_dynamics(robot("lwr4"))
    C7, S7, m7, c7x, c7y, c7z, I7xz, I7yz = sympy.symbols("C7 S7 m7 c7x c7y c7z I7xz I7yz")
    paper = c7y * c7z * m7 * C7 - I7xz * S7 - I7yz * C7 + c7x * c7z * m7 * S7
    ours = sympy.sympify(str(M[6][5]))
    assert sympy.expand(ours - paper) == 0 or sympy.expand(ours + paper) == 0


# ----------------------------------------------------------------------------- generated code

@pytest.mark.parametrize("name", ROBOTS)
def test_generated_regressors_times_base_values_equal_pinocchio(name):
    rob = robot(name)
    document = json.loads((GENERATED / name / "base_params.json").read_text())
    model, data, _ = pinocchio_model(rob)
    Q, QD, QDD = samples(rob, 12, 5)
    Yg = evaluate(name, "python", "Y_g", q=Q)["Y"]
    Ym = evaluate(name, "python", "Y_m", q=Q)["Y"]
    Yt = evaluate(name, "python", "Y", q=Q, qd=QD, qdd=QDD)["Y"]
    n = rob.n
    assert Yg.shape == (12, n, len(document["Y_g"]["names"]))
    assert Ym.shape == (12, n * (n + 1) // 2, len(document["Y_m"]["names"]))
    assert Yt.shape == (12, n, len(document["Y"]["names"]))
    for k in range(12):
        g = pin.computeGeneralizedGravity(model, data, Q[k])
        M = pin.crba(model, data, Q[k])
        M = np.triu(M) + np.triu(M, 1).T
        tau = pin.rnea(model, data, Q[k], QD[k], QDD[k])
        np.testing.assert_allclose(Yg[k] @ document["Y_g"]["values"], g, atol=1e-10, rtol=0)
        np.testing.assert_allclose(Ym[k] @ document["Y_m"]["values"], lower_stack(M), atol=1e-10, rtol=0)
        np.testing.assert_allclose(Yt[k] @ document["Y"]["values"], tau, atol=1e-10, rtol=0)


@pytest.mark.parametrize("name", ["lwr4", "panda"])
@pytest.mark.parametrize("lang", ["c", "casadi"])
def test_generated_languages_agree(name, lang):
    rob = robot(name)
    Q, QD, QDD = samples(rob, 4, 6)
    for fn, inputs in (("Y_g", {"q": Q}), ("Y_m", {"q": Q}), ("Y", {"q": Q, "qd": QD, "qdd": QDD})):
        np.testing.assert_allclose(evaluate(name, lang, fn, **inputs)["Y"],
                                   evaluate(name, "python", fn, **inputs)["Y"], atol=1e-12, rtol=1e-12)


def random_links(rob, seed):
    """Random physical links (mass, CoM, inertia about the CoM)."""
    from kindyngen.model.robot_model import Link
    rng = np.random.default_rng(seed)
    links = []
    for _ in rob.links:
        A = rng.normal(size=(3, 3)) * 0.1
        Ic = A @ A.T + 0.01 * np.eye(3)
        links.append(Link(mass=float(rng.uniform(0.5, 3.0)), com=tuple(rng.uniform(-0.1, 0.1, 3)),
                          inertia=(Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2])))
    return tuple(links)


@pytest.mark.parametrize("name", ["lwr4", "panda"])
def test_base_map_against_pinocchio_full_regressor(name):
    """Y_full(q, qd, qdd) @ p_full (Pinocchio, joint-frame parameters) equals
    Y_base @ base(p_full) (ours, DH-frame barycentric parameters), for random parameters."""
    rob = robot(name)
    Q, QD, QDD = samples(rob, 8, 9)
    Ybase = {kind: None for kind in KINDS}
    Ybase["Y_g"] = evaluate(name, "python", "Y_g", q=Q)["Y"]
    Ybase["Y_m"] = evaluate(name, "python", "Y_m", q=Q)["Y"]
    Ybase["Y"] = evaluate(name, "python", "Y", q=Q, qd=QD, qdd=QDD)["Y"]
    Yg, Ym, Yt = pin_full_regressors(rob, Q, QD, QDD)
    full = {"Y_g": Yg, "Y_m": Ym, "Y": Yt}
    for seed in range(3):
        links = random_links(rob, seed)
        pin_model, _, _ = pinocchio_model(replace(rob, links=links))
        p_joint = np.concatenate([pin_model.inertias[i + 1].toDynamicParameters() for i in range(rob.n)])
        p_dh = np.concatenate([pin.Inertia(l.mass, np.array(l.com), l.inertia_matrix()).toDynamicParameters()
                               for l in links])
        for kind in KINDS:
            beta = base_parameters(rob, kind).values(p_dh)
            np.testing.assert_allclose(np.einsum("skp,p->sk", Ybase[kind], beta),
                                       np.einsum("skp,p->sk", full[kind], p_joint), atol=1e-10, rtol=0,
                                       err_msg=f"{name} {kind}")


@pytest.mark.parametrize("name", ROBOTS)
def test_base_params_json_is_consistent(name):
    """The committed file equals a fresh derivation, the expressions parse and give the values,
    and the names match the regressor's columns."""
    rob = robot(name)
    text = (GENERATED / name / "base_params.json").read_text()
    assert text == json.dumps(base_params_document(rob), indent=1) + "\n"
    document = json.loads(text)
    assert set(document) == set(KINDS)
    values = {}
    for i, link in enumerate(rob.links, start=1):
        p = pin.Inertia(float(link.mass), np.array(link.com, float), link.inertia_matrix()).toDynamicParameters()
        for key, v in zip(("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"), p):
            values[sympy.Symbol(f"{key}{i}")] = v
    for kind in KINDS:
        entry = document[kind]
        assert len(entry["names"]) == len(entry["expressions"]) == len(entry["values"])
        assert len(set(entry["names"])) == len(entry["names"])
        for expr, value in zip(entry["expressions"], entry["values"]):
            assert float(sympy.sympify(expr).xreplace(values)) == pytest.approx(value, abs=1e-12)
        manifest = json.loads((GENERATED / name / "functions.json").read_text())
        spec = next(f for f in manifest["functions"] if f["name"] == kind)
        assert spec["outputs"][0]["name"] == "Y"
        assert spec["outputs"][0]["shape"][1] == len(entry["names"])


def test_grouping_relations_are_exact_rationals_for_the_shipped_robots():
    for name in ROBOTS:
        for kind in KINDS:
            b = base_parameters(robot(name), kind)
            assert b.exact, (name, kind)
            assert all(isinstance(t, sympy.Rational) for row in b.T for t in row)
            assert b.max_residual < 1e-12


def test_lwr4_classical_groupings():
    """Textbook groupings (Khalil): for a revolute joint the next link's mass moves by the DH
    offset d: here mz4R = mz4 + my5 + d2 (m5 + m6 + m7), d2 = 0.39."""
    b = base_parameters(robot("lwr4"), "Y")
    exprs = dict(zip(b.names, b.expressions()))
    sym = sympy.Symbol
    assert sympy.expand(exprs["mz4R"] - (sym("mz4") + sym("my5") + sympy.Rational(39, 100) *
                                          (sym("m5") + sym("m6") + sym("m7")))) == 0
    assert sympy.expand(exprs["Ixx7R"] - (sym("Ixx7") - sym("Iyy7"))) == 0


def test_paper_parameter_maps_round_trip():
    n = 2
    rng = np.random.default_rng(0)
    paper = paper_symbols(n)
    vals = dict(zip(paper, rng.uniform(0.1, 1.0, size=10 * n)))
    bary = [float(e.xreplace(vals)) for e in barycentric_in_paper(n)]
    # against Pinocchio's own parallel-axis shift
    for i in range(n):
        mm, cx, cy, cz, ixx, iyy, izz, ixy, ixz, iyz = (vals[s] for s in paper[10 * i:10 * i + 10])
        I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        np.testing.assert_allclose(bary[10 * i:10 * i + 10],
                                   pin.Inertia(mm, np.array([cx, cy, cz]), I).toDynamicParameters(), atol=1e-14)
    from kindyngen.algorithms.paper_parameters import barycentric_symbols
    back = [float(e.xreplace(dict(zip(barycentric_symbols(n), bary)))) for e in paper_in_barycentric(n)]
    np.testing.assert_allclose(back, [vals[s] for s in paper], atol=1e-12)


def test_regressors_are_the_same_in_both_parameter_modes():
    from kindyngen.codegen.catalog import derive_all
    numeric = derive_all(robot("lwr4"), "numeric", only=set(KINDS))
    symbolic = derive_all(robot("lwr4"), "symbolic", only=set(KINDS))
    assert [f.name for f in numeric] == list(KINDS)
    for a, b in zip(numeric, symbolic):
        assert a.inputs == b.inputs and a.output_exprs == b.output_exprs


def test_fully_reduced_paper_collection_reaches_the_base_parameter_count():
    """With S_i^2 -> 1 - C_i^2 and numeric DH lengths the paper's collection of the inertia
    stack has exactly as many columns as the inertia stack has base parameters (39, checked
    independently against Pinocchio above), and eq. 27 removes exactly two (barycentric
    Ixz7 = Iyz7 = 0 is what M_76 = 0 means)."""
    from tests.algorithms.paper_coefficients import collect_inertia
    rob = robot("lwr4")
    full = collect_inertia(rob, reduce_squares=True, numeric_lengths=True)
    assert len(full.coefficients) == full.numeric_rank() == 39
    with27 = collect_inertia(rob, reduce_squares=True, numeric_lengths=True, use_eq27=True)
    assert len(with27.coefficients) == with27.numeric_rank() == 37


def test_paper_column_count_table_backs_the_readme():
    """The README quotes this table to explain why the paper's 108 -> 74 is not reproduced:
    92 columns -> rank 64 (merging coefficients equal up to a number, no sin^2 -> 1 - cos^2,
    symbolic lengths), 90 -> 62 with eq. 27, 43 with sin^2 -> 1 - cos^2; numeric lengths with
    the reduction give exactly the base rank, 39 (37 with eq. 27)."""
    from tests.algorithms.paper_coefficients import inertia_column_counts
    table = {(r["lengths"], r["merge"], r["reduce_squares"], r["eq27"]): (r["columns"], r["rank"])
             for r in inertia_column_counts(robot("lwr4"), merges=("factor",))}  # the rule quoted
    assert all(rank <= columns for columns, rank in table.values())
    assert table[("symbolic", "factor", False, False)] == (92, 64)
    assert table[("symbolic", "factor", False, True)] == (90, 62)
    assert table[("symbolic", "factor", True, False)] == (43, 43)
    assert table[("numeric", "factor", True, False)] == (39, 39)
    assert table[("numeric", "factor", True, True)] == (37, 37)
