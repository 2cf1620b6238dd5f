"""The handbook's complete robot-description example (docs/reference/description.md, moved
there from the README) is a working description: it loads, it
generates, and its kinematics, gravity torques and inertia matrix equal the textbook formulas
of a planar two-link arm (derived by hand here, sharing nothing with the generator)."""
from __future__ import annotations

import re

import numpy as np
import yaml

from tests.harness import ROOT
from kindyngen.runtime.evaluate import load_generated
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import parse_robot

L1, L2, C1, C2 = 0.5, 0.4, 0.25, 0.2        # link lengths, CoM distances from each joint
M1, M2, I1, I2 = 1.2, 0.8, 0.025, 0.0107    # masses, inertias about z through the CoM
G0 = 9.81


def _example() -> dict:
    text = (ROOT / "docs" / "reference" / "description.md").read_text()
    section = text[text.index("## Robot description (YAML)"):]
    block = re.search(r"```yaml\n(.*?)```", section, re.S).group(1)
    return yaml.safe_load(block)


def test_readme_example_matches_hand_derived_planar_arm(tmp_path):
    model = parse_robot(_example(), "docs/reference/description.md")
    assert model.name == "planar2" and model.n == 2
    out = generate(model, tmp_path, languages=("python",), progress=False)
    lib = load_generated(out, "python")
    rng = np.random.default_rng(3)
    for q in rng.uniform(-2.5, 2.5, size=(20, 2)):
        q1, q2 = q
        c1, s1, c12, s12 = np.cos(q1), np.sin(q1), np.cos(q1 + q2), np.sin(q1 + q2)
        T = lib.call("fk_hom", {"q": q})["T"]
        expected = np.array([[c12, -s12, 0, L1 * c1 + L2 * c12], [s12, c12, 0, L1 * s1 + L2 * s12],
                             [0, 0, 1, 0], [0, 0, 0, 1]])
        np.testing.assert_allclose(T, expected, atol=1e-12)
        # potential energy U = G0 (M1 C1 s1 + M2 (L1 s1 + C2 s12)); g = dU/dq
        g = lib.call("g", {"q": q})["g"]
        np.testing.assert_allclose(g, [G0 * (M1 * C1 * c1 + M2 * (L1 * c1 + C2 * c12)), G0 * M2 * C2 * c12],
                                   atol=1e-12)
        c2 = np.cos(q2)
        m11 = I1 + M1 * C1 ** 2 + I2 + M2 * (L1 ** 2 + C2 ** 2 + 2 * L1 * C2 * c2)
        m12 = I2 + M2 * (C2 ** 2 + L1 * C2 * c2)
        m22 = I2 + M2 * C2 ** 2
        np.testing.assert_allclose(lib.call("M", {"q": q})["M"], [[m11, m12], [m12, m22]], atol=1e-12)
