"""kindyngen.cli.output_dir.replace_outputs: a reused output folder never mixes two runs and a
failed run leaves the earlier results whole (checked on the files themselves)."""
from __future__ import annotations

import pytest

from kindyngen.cli.output_dir import replace_outputs

KNOWN = ("report.md", "model.yaml", "fit.json")


def _files(folder):
    return {p.name: p.read_text() for p in folder.iterdir()}


def _run(folder, **files):
    def write(staging):
        for name, text in files.items():
            (staging / name.replace("_", ".")).write_text(text)
    return replace_outputs(folder, write, KNOWN)


def test_second_run_replaces_its_files_and_drops_what_it_no_longer_writes(tmp_path):
    out = tmp_path / "run"
    assert _run(out, report_md="one", model_yaml="m1", fit_json="{}") == ("fit.json", "model.yaml", "report.md")
    (out / "notes.txt").write_text("the user's")
    assert _run(out, report_md="two", fit_json="{1}") == ("fit.json", "report.md")
    assert _files(out) == {"report.md": "two", "fit.json": "{1}", "notes.txt": "the user's"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]           # no staging folder left


def test_a_failed_run_leaves_the_earlier_results_whole(tmp_path):
    out = tmp_path / "run"
    _run(out, report_md="one", model_yaml="m1")

    def half_then_fail(staging):
        (staging / "report.md").write_text("half")
        raise RuntimeError("solver failed")
    with pytest.raises(RuntimeError, match="solver failed"):
        replace_outputs(out, half_then_fail, KNOWN)
    assert _files(out) == {"report.md": "one", "model.yaml": "m1"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_out_that_is_a_file_is_refused_untouched(tmp_path):
    blocker = tmp_path / "run"
    blocker.write_text("a file")
    with pytest.raises(NotADirectoryError):
        _run(blocker, report_md="x")
    assert blocker.read_text() == "a file" and sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_missing_parents_are_created(tmp_path):
    out = tmp_path / "a" / "b" / "run"
    _run(out, fit_json="{}")
    assert _files(out) == {"fit.json": "{}"}
