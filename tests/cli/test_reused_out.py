"""A reused --out (issue 42): regenerating a subset leaves exactly that subset's files (what
functions.json's "files" lists) plus the user's; a run that fails in its derivation, its writing
or by Ctrl-C leaves the previous output byte for byte; an unwritable --out is refused before any
work. The kills themselves: tests/cli/test_kill_runs.py."""
from __future__ import annotations

import errno
import json

import pytest

from kindyngen.cli.main import main
from kindyngen.codegen import pipeline
from kindyngen.codegen.render import RENDERERS

ARM3 = """name: arm3
dh: standard
gravity: [0, 0, -9.81]
joints:
  - {a: 0,    alpha: pi/2, d: 0.3, offset: 0, lower: -2.9, upper: 2.9}
  - {a: 0.4,  alpha: 0,    d: 0,   offset: 0, lower: -2.0, upper: 2.0}
  - {a: 0.3,  alpha: 0,    d: 0,   offset: 0, lower: -2.5, upper: 2.5}
links:
  - {mass: 3.0, com: [0.001, -0.05, 0.02], inertia: [0.02, 0.01, 0.018, 0.0004, -0.0002, 0.0011]}
  - {mass: 2.0, com: [-0.2, 0.003, 0.01], inertia: [0.02, 0.03, 0.03, 0.0003, 0.0005, -0.0012]}
  - {mass: 1.0, com: [-0.15, 0.002, 0.004], inertia: [0.006, 0.01, 0.01, 0.0002, -0.0004, 0.001]}
"""


def arm3(folder, com3="[-0.15, 0.002, 0.004]"):
    """A small three-joint arm (quick to derive), optionally with another centre of mass of link 3."""
    path = folder / "arm3.yaml"
    path.write_text(ARM3.replace("[-0.15, 0.002, 0.004]", com3))
    return str(path)


def snapshot(folder):
    """Every file under ``folder`` with its bytes, by relative path; empty folders marked."""
    found = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).as_posix()
        if path.is_file():
            found[rel] = path.read_bytes()
        elif path.is_dir() and not any(path.iterdir()):
            found[rel] = "empty folder"
    return found


def _generate(robot, out, capsys, *options):
    code = main(["generate", robot, "--out", str(out), "--quiet", *options])
    err = capsys.readouterr().err
    return code, err


def _add_user_files(folder):
    (folder / "notes.txt").write_text("my notes\n")
    (folder / "c" / "build").mkdir(parents=True, exist_ok=True)
    (folder / "c" / "build" / "arm3.o").write_bytes(b"\x7fELF object")
    (folder / "scratch").mkdir()
    return {"notes.txt": b"my notes\n", "c/build/arm3.o": b"\x7fELF object", "scratch": "empty folder"}


def test_a_subset_regenerated_leaves_exactly_its_files_and_the_users(tmp_path, capsys):
    robot = arm3(tmp_path)
    out = tmp_path / "out"
    assert _generate(robot, out, capsys) == (0, "")
    everything = snapshot(out / "arm3")
    assert {"matlab/arm3_M.m", "casadi/M.casadi", "casadi/tau.casadi"} <= set(everything)
    mine = _add_user_files(out / "arm3")
    for options in (["--functions", "fk_hom,g"], ["--functions", "fk_hom,g", "--lang", "python,matlab"]):
        assert _generate(robot, out, capsys, *options) == (0, "")
        fresh = tmp_path / f"fresh{len(options)}"
        assert _generate(robot, fresh, capsys, *options) == (0, "")
        subset = snapshot(fresh / "arm3")
        assert snapshot(out / "arm3") == {**subset, **mine}
        # the manifest is the subset's files, exactly
        assert json.loads(subset["functions.json"])["files"] == sorted(subset)
        assert "casadi/M.casadi" not in subset and "matlab/arm3_M.m" not in subset
    assert sorted(p.name for p in out.iterdir()) == ["arm3"]          # no staging folder left


def test_a_folder_from_before_the_manifest_keeps_every_file(tmp_path, capsys):
    """functions.json without "files" (an older KinDynGen): nothing is known to be the
    generator's, so nothing the new run does not write is removed."""
    robot = arm3(tmp_path)
    out = tmp_path / "out"
    assert _generate(robot, out, capsys) == (0, "")
    document = json.loads((out / "arm3" / "functions.json").read_text())
    del document["files"]
    (out / "arm3" / "functions.json").write_text(json.dumps(document))
    before = snapshot(out / "arm3")
    assert _generate(robot, out, capsys, "--functions", "fk_hom") == (0, "")
    after = snapshot(out / "arm3")
    assert set(after) == set(before) and after["matlab/arm3_M.m"] == before["matlab/arm3_M.m"]


def test_a_run_failing_in_its_derivation_leaves_the_previous_output(tmp_path, capsys):
    """A centre of mass of 1e200 m overflows to inf in the generated constants (issue 42: this
    had already overwritten base_params.json when the run stopped)."""
    out = tmp_path / "out"
    assert _generate(arm3(tmp_path), out, capsys) == (0, "")
    mine = _add_user_files(out / "arm3")
    before = snapshot(out / "arm3")
    try:
        code, err = _generate(arm3(tmp_path, com3="[1e200, 0, 0]"), out, capsys)
    except ValueError:              # the description is not refused by the reader: a traceback
        code = None
    assert code != 0
    assert snapshot(out / "arm3") == before and set(mine) <= set(before)
    assert sorted(p.name for p in out.iterdir()) == ["arm3"]


def test_a_full_disk_while_writing_leaves_the_previous_output(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    robot = arm3(tmp_path)
    assert _generate(robot, out, capsys, "--functions", "fk_hom,jacobian,M") == (0, "")
    before = snapshot(out / "arm3")

    def disk_full(source, directory):
        (directory / "fk_hom.casadi").write_bytes(b"half")
        raise OSError(errno.ENOSPC, "No space left on device", str(directory / "fk_hom.casadi"))
    monkeypatch.setattr(pipeline, "save_casadi_functions", disk_full)
    code, err = _generate(robot, out, capsys)
    assert code == 2 and err.startswith("error: ") and "No space left on device" in err and err.count("\n") == 1
    assert snapshot(out / "arm3") == before
    assert sorted(p.name for p in out.iterdir()) == ["arm3"]


def test_ctrl_c_while_writing_is_one_line_exit_130_and_the_previous_output(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    robot = arm3(tmp_path)
    assert _generate(robot, out, capsys, "--functions", "fk_hom") == (0, "")
    before = snapshot(out / "arm3")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setitem(RENDERERS, "matlab", interrupted)
    assert _generate(robot, out, capsys) == (130, "interrupted\n")
    assert snapshot(out / "arm3") == before
    assert sorted(p.name for p in out.iterdir()) == ["arm3"]


@pytest.mark.parametrize("command", [
    ["generate", "ROBOT"],
    ["identify", "--robot", "ROBOT", "--data", "LOG", "--split", "0.7"],
    ["discover", "--robot", "ROBOT", "--data", "LOG"],
    ["excite", "--robot", "ROBOT"],
    ["reproduce-identification", "--robot", "ROBOT"],
])
@pytest.mark.parametrize("where", ["under a file", "in /proc"])
def test_an_unwritable_out_is_refused_before_any_work(tmp_path, capsys, command, where):
    """The robot and the log do not exist: the refusal names --out, so it came first."""
    if where == "in /proc":
        if not (tmp_path / "/proc/self").is_dir():
            pytest.skip("no /proc")
        out = "/proc/kindyngen-out"         # no file can be created in /proc, not even by root
    else:
        (tmp_path / "a_file").write_text("")
        out = str(tmp_path / "a_file" / "out")
    argv = [{"ROBOT": str(tmp_path / "absent.yaml"), "LOG": str(tmp_path / "absent.csv")}.get(a, a) for a in command]
    code = main(argv + ["--out", out, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"error: --out {out}: "), err
    assert ("cannot create files in /proc" if where == "in /proc" else "a_file is not a folder") in err
    assert "absent" not in err


def test_an_out_that_is_a_file_is_refused_before_any_work(tmp_path, capsys):
    (tmp_path / "results").write_text("a file")
    code = main(["discover", "--robot", str(tmp_path / "absent.yaml"), "--data", str(tmp_path / "absent.csv"),
                 "--out", str(tmp_path / "results")])
    assert code == 2 and capsys.readouterr().err == f"error: --out {tmp_path / 'results'}: exists and is not a folder\n"


def test_two_robots_with_one_identifier_are_refused_before_any_work(tmp_path, capsys):
    """'ARM3' and 'arm3' are both arm3: the second would replace the first's folder."""
    first = arm3(tmp_path)
    (tmp_path / "other").mkdir()
    second = tmp_path / "other" / "arm3.yaml"
    second.write_text(ARM3.replace("name: arm3", "name: ARM3"))
    code = main(["generate", first, str(second), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"error: {second}: the robot's identifier arm3 is that of {first} too"), err
    assert not (tmp_path / "out" / "arm3").exists()
