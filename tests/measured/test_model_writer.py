"""kindyngen.measured.identified_model: an identified model written as model.yaml is read back by
the project's loader (kindyngen.readers.yaml_description, a separate reader) with exactly the identified links,
friction, offset, armature, stiffness (1 / compliance), torque gain (1 + gain error), payload
and gravity, and the geometry of the starting description; bad coefficients are refused by
name."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from tests.harness import ROOT
from kindyngen.measured.identified_model import ModelWriteError, model_yaml
from kindyngen.readers.yaml_description import load_robot, parse_robot

SOURCE = ROOT / "robots" / "lwr4.yaml"


def _links(n):
    rng = np.random.default_rng(6)
    return [{"mass": round(float(rng.uniform(0.5, 3)), 4), "com": [round(float(v), 4) for v in rng.uniform(-0.1, 0.1, 3)],
             "inertia": [0.02, 0.03, 0.025, 0.001, -0.002, 0.0005]} for _ in range(n)]


def test_written_model_reads_back_with_the_identified_values():
    links = _links(7)
    effects = {"fv1": 0.5, "fc3": 0.25, "f07": -0.125, "Ia2": 0.75, "ce4": 1e-4, "dq5": 0.001, "gt6": -0.02}
    payload = {"mass": 0.5, "com": [0.0, 0.0, 0.05], "inertia": [1e-4, 1e-4, 1e-4, 0, 0, 0]}
    text = model_yaml(SOURCE, links, effects, header="identified\nfrom two logs", name="lwr4_identified",
                      payload=payload, gravity=[0.0, 0.1, -9.81])
    assert text.startswith("# identified\n# from two logs\n")
    model, start = parse_robot(yaml.safe_load(text), "model.yaml"), load_robot(SOURCE)
    assert model.name == "lwr4_identified" and model.n == 7
    for got, want in zip(model.links, links):
        assert float(got.mass) == want["mass"] and [float(v) for v in got.com] == want["com"]
        assert [float(v) for v in got.inertia] == want["inertia"]
    assert float(model.friction(0).viscous) == 0.5 and float(model.friction(2).coulomb) == 0.25
    assert float(model.friction(6).offset) == -0.125 and float(model.armature(1)) == 0.75
    assert float(model.joints[3].stiffness) == pytest.approx(1e4, rel=1e-12)
    assert float(model.joints[4].encoder_offset) == 0.001
    assert float(model.joints[5].torque_gain) == pytest.approx(0.98, rel=1e-12)
    assert float(model.payload.mass) == 0.5 and [float(v) for v in model.gravity] == [0.0, 0.1, -9.81]
    for a, b in zip(model.joints, start.joints):          # the geometry is the starting description's
        assert (a.a, a.alpha, a.d, a.offset, a.lower, a.upper) == (b.a, b.alpha, b.d, b.offset, b.lower, b.upper)


def test_earlier_effects_are_replaced_not_merged():
    once = yaml.safe_load(model_yaml(SOURCE, None, {"fv1": 0.5, "fc1": 0.2}))
    data = yaml.safe_load(model_yaml(SOURCE, None, {"fc2": 0.1}))
    assert once["joints"][0]["friction"] == {"viscous": 0.5, "coulomb": 0.2}
    assert "friction" not in data["joints"][0] and data["joints"][1]["friction"] == {"coulomb": 0.1}
    assert data["links"] == yaml.safe_load(SOURCE.read_text())["links"]       # None keeps the links


@pytest.mark.parametrize("links, effects, message", [
    (None, {"xx1": 1.0}, "unknown effect coefficient 'xx1'"),
    (None, {"fv8": 1.0}, "unknown effect coefficient 'fv8'"),
    (None, {"fv1": float("nan")}, "effect coefficient fv1 is nan"),
    (None, {"ce2": 0.0}, "compliance ce2 = 0 is not positive"),
    (_links(6), {}, "6 identified links for 7 joints"),
])
def test_bad_values_are_refused_by_name(links, effects, message):
    with pytest.raises(ModelWriteError, match=message):
        model_yaml(SOURCE, links, effects)


def test_a_compliance_too_small_for_a_description_leaves_the_joint_rigid():
    """discover's points are written through measurement_model.model_at: a fitted compliance of
    1.7e-21 rad/(N m) (a UR10 trial of the known-truth benchmark) would be a stiffness of 5.9e20
    N m/rad, beyond what the loader takes (1e12): the joint is written rigid, the other
    compliance as 1 / ce."""
    from kindyngen.measured.measurement_model import model_at
    nominal = load_robot(SOURCE)
    model = model_at(nominal, SOURCE, {"ce3": 1.7e-21, "ce4": 2e-4, "fv1": 0.5})
    assert model.joints[2].stiffness is None
    assert float(model.joints[3].stiffness) == pytest.approx(5e3, rel=1e-12)
    assert float(model.friction(0).viscous) == 0.5
