"""kindyngen.output_folder: a reused output folder is replaced whole (never two runs mixed), a
failed or interrupted run leaves the earlier output byte for byte, the user's files are carried
over, and what killed runs leave beside it is tidied or recovered by the next run (checked on
the files themselves; the kills themselves: tests/cli/test_kill_runs.py)."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys

import pytest

from kindyngen import output_folder
from kindyngen.output_folder import (OutputFolderError, check_writable, replace_file, replace_files,
                                     replace_folder, replace_outputs, signals_held, tidy_leftovers)

KNOWN = ("report.md", "model.yaml", "fit.json")


def _files(folder):
    """Every file under ``folder`` by relative path, with its bytes (links by their target)."""
    found = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).as_posix()
        if path.is_symlink():
            found[rel] = ("link", os.readlink(path))
        elif path.is_file():
            found[rel] = path.read_bytes()
        elif path.is_dir() and not any(path.iterdir()):
            found[rel] = "empty folder"
    return found


def _beside(out):
    return sorted(p.name for p in out.parent.iterdir())


def _run(folder, **files):
    def write(staging):
        for name, text in files.items():
            (staging / name.replace("_", ".")).write_text(text)
    return replace_outputs(folder, write, KNOWN)


@pytest.fixture(params=["exchange", "fallback"])
def swap(request, monkeypatch):
    """Every test twice: with renameat2's exchange, and with the fallback (rename aside)."""
    if request.param == "fallback":
        monkeypatch.setenv(output_folder.NO_EXCHANGE_VARIABLE, "1")
    elif output_folder._renameat2() is None:
        pytest.skip("no renameat2 here")
    return request.param


def _dead_pid():
    """The id of a process that has ended (reaped)."""
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(done.stdout)


def _leftover(out, kind, pid, host=None):
    host = host or output_folder._host()
    return out.parent / f".{out.name}.{kind}.{host}.{pid}.0123abcd"


def test_second_run_replaces_its_files_and_drops_what_it_no_longer_writes(tmp_path, swap):
    out = tmp_path / "run"
    assert _run(out, report_md="one", model_yaml="m1", fit_json="{}") == ("fit.json", "model.yaml", "report.md")
    (out / "notes.txt").write_text("the user's")
    assert _run(out, report_md="two", fit_json="{1}") == ("fit.json", "report.md")
    assert _files(out) == {"report.md": b"two", "fit.json": b"{1}", "notes.txt": b"the user's"}
    assert _beside(out) == ["run"]           # no staging folder left


def test_the_previous_manifest_decides_what_is_the_users(tmp_path, swap):
    """Files the previous run's manifest lists and the new run does not write are dropped; all
    else of the previous folder (nested files, empty folders, links) is carried over."""
    out = tmp_path / "gen"
    listed = {"functions.json", "c/a.c", "matlab/f.m", "matlab/g.m"}

    def write(names):
        def into(folder):
            for name in names:
                (folder / name).parent.mkdir(parents=True, exist_ok=True)
                (folder / name).write_text(f"new {name}")
        return into
    replace_folder(out, write(sorted(listed)), lambda folder: None)
    (out / "c" / "build").mkdir()
    (out / "c" / "build" / "a.o").write_bytes(b"\x7fELF")
    (out / "scratch").mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "latest").symlink_to("c/a.c")
    replace_folder(out, write(["functions.json", "c/a.c", "matlab/f.m"]), lambda folder: listed)
    assert _files(out) == {"functions.json": b"new functions.json", "c/a.c": b"new c/a.c", "matlab/f.m": b"new matlab/f.m",
                           "c/build/a.o": b"\x7fELF", "scratch": "empty folder", "notes.txt": b"mine",
                           "latest": ("link", "c/a.c")}
    assert _beside(out) == ["gen"]


def test_without_a_previous_manifest_nothing_is_dropped(tmp_path, swap):
    out = tmp_path / "gen"
    out.mkdir()
    (out / "old.m").write_text("from an older version")
    (out / "a.c").write_text("old")
    replace_folder(out, lambda folder: (folder / "a.c").write_text("new"), lambda folder: None)
    assert _files(out) == {"a.c": b"new", "old.m": b"from an older version"}


def test_a_users_file_where_the_new_run_writes_one_gives_way_with_a_note(tmp_path, capsys):
    out = tmp_path / "gen"
    replace_folder(out, lambda folder: (folder / "a.c").write_text("1"), lambda folder: None)
    (out / "b.c").write_text("the user's")
    replace_folder(out, lambda folder: (folder / "b.c").write_text("2"), lambda folder: {"a.c"})
    assert _files(out) == {"b.c": b"2"}
    assert "b.c: the generated file of that name replaces it" in capsys.readouterr().err


@pytest.mark.parametrize("failure", [RuntimeError("solver failed"), KeyboardInterrupt()])
def test_a_failed_or_interrupted_run_leaves_the_earlier_results_whole(tmp_path, swap, failure):
    out = tmp_path / "run"
    _run(out, report_md="one", model_yaml="m1")

    def half_then_fail(staging):
        (staging / "report.md").write_text("half")
        raise failure
    with pytest.raises(type(failure)):
        replace_outputs(out, half_then_fail, KNOWN)
    assert _files(out) == {"report.md": b"one", "model.yaml": b"m1"}
    assert _beside(out) == ["run"]


def test_out_that_is_a_file_is_refused_untouched(tmp_path):
    blocker = tmp_path / "run"
    blocker.write_text("a file")
    with pytest.raises(NotADirectoryError):
        _run(blocker, report_md="x")
    assert blocker.read_text() == "a file" and _beside(blocker) == ["run"]


def test_missing_parents_are_created(tmp_path):
    out = tmp_path / "a" / "b" / "run"
    _run(out, fit_json="{}")
    assert _files(out) == {"fit.json": b"{}"}


def test_the_folders_mode_stays_and_a_link_to_it_stays_a_link(tmp_path, swap):
    target = tmp_path / "real"
    _run(target, fit_json="1")
    target.chmod(0o750)
    link = tmp_path / "out"
    link.symlink_to("real")
    _run(link, fit_json="2")
    assert link.is_symlink() and _files(target) == {"fit.json": b"2"}
    assert target.stat().st_mode & 0o777 == 0o750


def test_stale_staging_folders_of_gone_processes_are_removed_others_kept(tmp_path):
    out = tmp_path / "run"
    _run(out, fit_json="1")
    dead, alive = _dead_pid(), os.getppid()
    stale = _leftover(out, output_folder.STAGING, dead)
    running = _leftover(out, output_folder.STAGING, alive)
    elsewhere = _leftover(out, output_folder.STAGING, dead, host="another-host")
    other_target = tmp_path / f".runs.{output_folder.STAGING}.{output_folder._host()}.{dead}.0123abcd"
    not_ours = tmp_path / ".run.partial"
    for folder in (stale, running, elsewhere, other_target, not_ours):
        folder.mkdir()
        (folder / "x").write_text("half")
    (tmp_path / f".run.{output_folder.STAGING}.{output_folder._host()}.{dead}.feedbeef").write_text("replace_file's")
    _run(out, fit_json="2")
    assert _beside(out) == sorted(p.name for p in (out, running, elsewhere, other_target, not_ours))
    assert _files(out) == {"fit.json": b"2"}


def test_a_folder_renamed_aside_by_a_killed_fallback_swap_is_recovered(tmp_path):
    """The fallback's window: the previous output renamed aside, the new one not yet in. The
    next run into the same place renames it back (then replaces it as usual)."""
    out = tmp_path / "run"
    aside = _leftover(out, output_folder.PREVIOUS, _dead_pid())
    aside.mkdir()
    (aside / "fit.json").write_text("previous")
    (aside / "notes.txt").write_text("the user's")
    assert tidy_leftovers(out) == [f"recovered {out} from an interrupted run's {aside.name}"]
    assert _files(out) == {"fit.json": b"previous", "notes.txt": b"the user's"} and _beside(out) == ["run"]
    # the swap had happened (out in place): the aside folder is just removed
    aside.mkdir()
    (aside / "fit.json").write_text("older")
    _run(out, fit_json="new")
    assert _files(out) == {"fit.json": b"new", "notes.txt": b"the user's"} and _beside(out) == ["run"]


def test_sigint_during_the_swap_is_delivered_after_it():
    events = []
    with pytest.raises(KeyboardInterrupt):
        with signals_held():
            os.kill(os.getpid(), signal.SIGINT)
            events.append("the swap finished")
        events.append("not reached")
    assert events == ["the swap finished"]


def test_check_writable_probes_without_leaving_anything(tmp_path):
    check_writable(tmp_path / "new" / "deeper")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "a_file").write_text("")
    with pytest.raises(OutputFolderError, match="is not a folder"):
        check_writable(tmp_path / "a_file" / "out")
    if os.path.isdir("/proc/self"):           # even root cannot create files in /proc
        with pytest.raises(OutputFolderError, match="cannot create files in /proc"):
            check_writable("/proc/out")


def test_replace_file_writes_whole_or_not_at_all(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text("old")
    path.chmod(0o640)
    replace_file(path, "new")
    assert path.read_text() == "new" and path.stat().st_mode & 0o777 == 0o640
    assert _beside(path) == ["robot.yaml"]


def test_host_names_fit_the_leftover_pattern(monkeypatch):
    monkeypatch.setattr(socket, "gethostname", lambda: "node.cluster.example")
    name = output_folder._leftover_name("lwr4", output_folder.STAGING)
    m = output_folder._leftover_pattern("lwr4").match(name)
    assert m and m["host"] == "node_cluster_example" and int(m["pid"]) == os.getpid()


def test_several_files_into_a_shared_folder_all_or_none(tmp_path):
    (tmp_path / "other.json").write_text("another run's")
    (tmp_path / "run.json").write_text("old")

    def half_then_fail(staging):
        (staging / "run.json").write_text("new")
        raise RuntimeError("plot failed")
    with pytest.raises(RuntimeError):
        replace_files(tmp_path, half_then_fail)
    assert _files(tmp_path) == {"other.json": b"another run's", "run.json": b"old"}
    assert replace_files(tmp_path, lambda d: [(d / n).write_text("new") for n in ("run.json", "run.png")]) == \
        ["run.json", "run.png"]
    assert _files(tmp_path) == {"other.json": b"another run's", "run.json": b"new", "run.png": b"new"}


def test_a_run_killed_while_moving_its_files_in_is_finished_by_the_next(tmp_path):
    """A staging folder with the mark: its files were complete, some already moved in; the next
    run moves the rest. One without the mark was killed while writing: removed."""
    (tmp_path / "run.json").write_text("new")                    # moved in before the kill
    (tmp_path / "run.png").write_text("old")
    moving = _leftover(tmp_path / tmp_path.name, output_folder.FILES, _dead_pid())
    moving.mkdir()
    (moving / output_folder.MOVING_MARK).write_text("")
    (moving / "run.png").write_text("new")
    writing = _leftover(tmp_path / tmp_path.name, output_folder.FILES, _dead_pid())
    writing = writing.with_name(writing.name.replace("0123abcd", "89abcdef"))
    writing.mkdir()
    (writing / "half.json").write_text("{")
    replace_files(tmp_path, lambda d: (d / "other.json").write_text("1"))
    assert _files(tmp_path) == {"run.json": b"new", "run.png": b"new", "other.json": b"1"}


def test_a_users_file_that_cannot_be_carried_over_stops_the_run(tmp_path, monkeypatch):
    """Rather no new output than the user's file removed with the old folder (here neither a
    hard link nor a copy can be made, as for a file this user may not read)."""
    out = tmp_path / "run"
    _run(out, fit_json="1")
    (out / "notes.txt").write_text("mine")

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(os, "link", refused)
    monkeypatch.setattr(output_folder.shutil, "copy2", refused)
    with pytest.raises(OutputFolderError, match="cannot carry this file over"):
        _run(out, fit_json="2")
    assert _files(out) == {"fit.json": b"1", "notes.txt": b"mine"} and _beside(out) == ["run"]
