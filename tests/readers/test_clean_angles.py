"""Angles written as floats cost what the exact angles cost: the LWR table with alpha written
1.5707963267948966 (or 6.1e-17 for 0) derives the very expressions of the pi/2 table;
URDF-style 1.5708 is snapped with a note naming the field, and --keep-angles keeps it."""
from __future__ import annotations

import copy

import pytest
import sympy
import yaml

from tests.harness import ROOT
from kindyngen.cli.main import main
from kindyngen.codegen.pipeline import build_programs
from kindyngen.readers.yaml_description import parse_robot

LWR = yaml.safe_load((ROOT / "robots" / "lwr4.yaml").read_text())


def _with_alphas(text_of):
    data = copy.deepcopy(LWR)
    for row in data["joints"]:
        row["alpha"] = text_of(sympy.sympify(str(row["alpha"])))
    data["name"] = "lwr4"          # same identifier: same generated text
    return data


def _counts(model):
    return {p.function.name: p.after for p in build_programs(model, only={"fk_hom", "jacobian", "M", "tau"},
                                                             progress=False)}


def test_doubles_of_right_angles_are_the_right_angles():
    exact = parse_robot(LWR, "lwr4.yaml")
    floats = parse_robot(_with_alphas(lambda a: float(a) if a != 0 else 6.1e-17), "floats.yaml")
    assert [j.dh.alpha for j in floats.joints] == [j.dh.alpha for j in exact.joints]
    assert floats.notes == ()                       # within 1e-12: read as exact, nothing to say
    assert _counts(floats) == _counts(exact)


def test_near_right_angles_are_snapped_with_a_note_or_kept():
    near = _with_alphas(lambda a: round(float(a), 4))            # 1.5708, -1.5708, 0.0
    snapped = parse_robot(near, "near.yaml")
    assert [j.dh.alpha for j in snapped.joints] == [j.dh.alpha for j in parse_robot(LWR, "x").joints]
    assert len(snapped.notes) == 6 and "near.yaml: joints[0].alpha: 1.5708 read as pi/2" in snapped.notes[0]
    kept = parse_robot(near, "near.yaml", snap_angles=False)
    assert kept.notes == () and kept.joints[0].dh.alpha == sympy.Rational("1.5708")
    exact, as_written = _counts(snapped)["fk_hom"], _counts(kept)["fk_hom"]
    assert as_written.add + as_written.mul > 2 * (exact.add + exact.mul)   # what snapping saves


def test_cli_prints_the_note_and_keeps_angles_on_request(tmp_path, capsys):
    path = tmp_path / "near.yaml"
    path.write_text(yaml.safe_dump(_with_alphas(lambda a: round(float(a), 6))))    # 1.570796
    assert main(["count", str(path), "--only", "fk_hom", "--format", "json"]) == 0
    err = capsys.readouterr().err
    assert f"note: {path}: joints[1].alpha: -1.570796 read as -pi/2" in err
    assert main(["count", str(path), "--only", "fk_hom", "--format", "json", "--keep-angles"]) == 0
    assert "note:" not in capsys.readouterr().err


@pytest.mark.parametrize("value, expected", [(0.3, sympy.Rational(3, 10)), (-3.14159265358979, -sympy.pi),
                                             (0.5235987755982988, sympy.pi / 6), (0.7853981633974483, sympy.pi / 4)])
def test_other_angles(value, expected):
    data = copy.deepcopy(LWR)
    data["joints"][6]["alpha"] = value
    assert parse_robot(data, "x.yaml").joints[6].dh.alpha == expected
