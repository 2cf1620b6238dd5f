"""One behaviour for bad input on the command line: exit code 2 and exactly one line on
standard error, starting with ``error:``, that says what is wrong; never a traceback.
Outputs that are not finite are still valid JSON."""
from __future__ import annotations

import io
import json
import subprocess
import sys

import pytest
import yaml

from tests.harness import GENERATED, ROOT
from kindyngen.cli.main import main

LWR4 = str(GENERATED / "lwr4")


def _run(argv, capsys, monkeypatch, stdin=""):
    monkeypatch.setattr(sys, "stdin", io.StringIO(stdin))
    try:
        code = main(argv)
    except SystemExit as exc:   # argparse's own exits (its errors and --help)
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _refused(argv, capsys, monkeypatch, message, stdin=""):
    code, out, err = _run(argv, capsys, monkeypatch, stdin)
    assert code == 2, (code, err)
    assert out == ""
    assert err.startswith("error: ") and err.count("\n") == 1 and err.endswith("\n"), repr(err)
    assert message in err, err
    return err


@pytest.mark.parametrize("stdin, message", [
    ("{\"q\": [0, 0,", "standard input is not JSON"),
    ("not json at all", "standard input is not JSON"),
    ("[0, 0, 0, 0, 0, 0, 0]", "must be a JSON object of named inputs"),
    ("{\"q\": [0, 0, 0, null, 0, 0, 0]}", "input q[3] must be a number, got null"),
    ("{\"q\": [0, 0, true, 0, 0, 0, 0]}", "input q[2] must be a number, got true"),
    ("{\"q\": [0, \"0.1\", 0, 0, 0, 0, 0]}", "input q[1] must be a number, got \"0.1\""),
    ("{\"q\": [[0, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, NaN]]}", "input q[1][6] must be finite, got nan"),
    ("{\"q\": [Infinity, 0, 0, 0, 0, 0, 0]}", "input q[0] must be finite, got inf"),
    ("{\"q\": null}", "input q must be a number, got null"),
    ("{\"q\": [0.1, 0.2]}", "has shape [2]; expected [7]"),
    ("{}", "missing input 'q'"),
])
def test_eval_refuses_bad_standard_input(capsys, monkeypatch, stdin, message):
    _refused(["eval", LWR4, "fk_hom", "--lang", "python"], capsys, monkeypatch, message, stdin)


def test_malformed_json_exits_2_as_a_real_process():
    """The case that used to exit 1: checked on a real process, so no traceback can hide."""
    done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", LWR4, "fk_hom"], input="{\"q\": [",
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("error: standard input is not JSON") and done.stderr.count("\n") == 1


def test_eval_unknown_function_and_folder(capsys, monkeypatch, tmp_path):
    _refused(["eval", LWR4, "nope"], capsys, monkeypatch, "no function 'nope'", "{}")
    _refused(["eval", str(tmp_path), "fk_hom"], capsys, monkeypatch, "functions.json: not found", "{}")


def test_non_finite_outputs_are_valid_json(capsys, monkeypatch):
    """Velocities of 1e200 rad/s overflow the Coriolis products: +inf and -inf meet in sums
    (NaN), and each is written as a string, the way protobuf's JSON mapping spells doubles."""
    stdin = json.dumps({"q": [0.1] * 7, "qd": [1e200, -1e200] * 3 + [1e200], "qdd": [0.0] * 7})
    code, out, err = _run(["eval", LWR4, "tau", "--lang", "python"], capsys, monkeypatch, stdin)
    assert code == 0, err

    def refuse(token):
        raise AssertionError(f"bare {token} in the output: not JSON")

    tau = json.loads(out, parse_constant=refuse)["tau"]
    assert set(v for v in tau if isinstance(v, str)) <= {"NaN", "Infinity", "-Infinity"}
    assert any(isinstance(v, str) for v in tau), tau


@pytest.mark.parametrize("only, message", [
    (["nope"], "--only: unknown function(s) nope; known: fk_hom"),
    (["fk_hom", "tua"], "unknown function(s) tua"),
    ([], "--only needs at least one function name"),
])
def test_count_only_refuses_unknown_names(capsys, monkeypatch, only, message):
    _refused(["count", str(ROOT / "robots" / "lwr4.yaml"), "--only", *only], capsys, monkeypatch, message)


def test_count_only_refuses_a_function_that_does_not_apply(capsys, monkeypatch):
    """Closed-form IK exists for LWR-type arms only: asking for it on the Panda is an error,
    not an empty table."""
    _refused(["count", str(ROOT / "robots" / "panda.yaml"), "--only", "ik_hom"], capsys, monkeypatch,
             "--only: ik_hom not generated for panda")


def test_count_only_known_name_works(capsys, monkeypatch):
    code, out, err = _run(["count", str(ROOT / "robots" / "lwr4.yaml"), "--only", "fk_dq", "--format", "json"],
                          capsys, monkeypatch)
    assert code == 0 and set(json.loads(out)["lwr4"]) == {"fk_dq"}


def test_robot_description_typo_exits_2(capsys, monkeypatch, tmp_path):
    data = yaml.safe_load((ROOT / "robots" / "lwr4.yaml").read_text())
    data["joints"][2]["ofset"] = 0.5
    path = tmp_path / "typo.yaml"
    path.write_text(yaml.safe_dump(data))
    err = _refused(["generate", str(path), "--out", str(tmp_path / "out")], capsys, monkeypatch,
                   "field 'joints[2].ofset': unknown key; did you mean 'offset'?")
    assert str(path) in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, message", [
    (["generate", "robots/lwr4.yaml"], "the following arguments are required: --out"),
    (["generate", "robots/lwr4.yaml", "--out", "x", "--lang", "fortran"], "unknown language(s) fortran"),
    (["count", "robots/lwr4.yaml", "--format", "xml"], "invalid choice: 'xml'"),
    (["frobnicate"], "invalid choice: 'frobnicate'"),
    ([], "the following arguments are required: command"),
])
def test_argument_errors_are_one_line(capsys, monkeypatch, argv, message):
    _refused(argv, capsys, monkeypatch, message)


def test_missing_robot_file(capsys, monkeypatch, tmp_path):
    _refused(["count", str(tmp_path / "absent.yaml")], capsys, monkeypatch, "cannot read: No such file")


def test_unwritable_output_folder(capsys, monkeypatch, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    _refused(["generate", str(ROOT / "robots" / "lwr4.yaml"), "--out", str(blocker / "sub"), "--quiet",
              "--lang", "python"], capsys, monkeypatch, f"--out {blocker / 'sub'}: {blocker} is not a folder")


def test_eval_on_a_broken_or_partial_generated_folder(capsys, monkeypatch, tmp_path):
    (tmp_path / "functions.json").write_text("{not json")
    _refused(["eval", str(tmp_path), "fk_hom"], capsys, monkeypatch, "not a KinDynGen interface file", "{}")
    (tmp_path / "functions.json").write_text((GENERATED / "lwr4" / "functions.json").read_text())
    _refused(["eval", str(tmp_path), "fk_hom", "--lang", "casadi"], capsys, monkeypatch,
             "fk_hom.casadi: not found", json.dumps({"q": [0] * 7}))
    _refused(["eval", str(tmp_path), "fk_hom", "--lang", "python"], capsys, monkeypatch,
             "No such file or directory", json.dumps({"q": [0] * 7}))
