"""Killed and interrupted runs over an existing output (issue 42): `generate` and `discover` are
started over the output of an earlier, different run and stopped by SIGKILL, SIGINT or SIGTERM
at seeded random moments, and exactly in the swap (the process stops itself there through the
test hook KINDYNGEN_PAUSE_AT of kindyngen.output_folder); afterwards the folder is byte for byte
the earlier output or the new complete one, never a mix. SIGINT and SIGTERM end with one line,
exit 130 / 143 and no staging folder left; what SIGKILL leaves is tidied by the next run.

No timing is asserted: the random moments are drawn from the length of one complete run, and
the time limits only stop a hung run. Linux only (it reads /proc/<pid> to know when a run has
started and when it has stopped itself)."""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.cli.test_reused_out import arm3, snapshot
from tests.harness import ROOT

pytestmark = pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="reads /proc/<pid>")
HANG = 600          # seconds: only to stop a hung run, never a verdict
ENDING = {signal.SIGINT: (130, "interrupted"), signal.SIGTERM: (143, "terminated")}
# kindyngen.output_folder's test hooks and its staging folders' names (spelled out: the test runs
# as it is against a KinDynGen without them, and fails there)
PAUSE_AT, NO_EXCHANGE, STAGING = "KINDYNGEN_PAUSE_AT", "KINDYNGEN_NO_RENAME_EXCHANGE", "kdg-staging"


def _start(argv, cwd, session=False, **environment):
    """``python -m kindyngen ARGV`` from this checkout, with SIGINT's default action restored
    (a test run from a background shell job would otherwise pass on an ignored SIGINT);
    ``session``: in a process group of its own, as a command started from a terminal."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
           **environment}
    return subprocess.Popen([sys.executable, "-m", "kindyngen", *argv], cwd=cwd, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=session,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _status(pid):
    try:
        return Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return ""


def _until(condition, process, what):
    """Poll until ``condition()``; False if the process ended first."""
    deadline = time.monotonic() + HANG
    while not condition():
        if process.poll() is not None:
            return False
        if time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"hung waiting for {what}")
        time.sleep(0.01)
    return True


def _signal_mask(pid, field):
    """Whose bits of /proc/<pid>/status's ``field`` (SigCgt: caught, SigBlk: blocked) are set."""
    lines = [line for line in _status(pid).splitlines() if line.startswith(field + ":")]
    mask = int(lines[0].split()[1], 16) if lines else 0
    return {s for s in (signal.SIGINT, signal.SIGTERM) if mask >> (s - 1) & 1}


def _handles_sigterm(pid):
    """KinDynGen's first line has run: it catches SIGTERM (kindyngen.cli.interrupts)."""
    return signal.SIGTERM in _signal_mask(pid, "SigCgt")


def _stopped(pid):
    return any(line.split()[1:2] == ["T"] for line in _status(pid).splitlines() if line.startswith("State:"))


def _finish(process):
    try:
        out, err = process.communicate(timeout=HANG)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail("a run did not end")
    return process.returncode, err


def _staging_of(out, pid):
    return [p for p in out.iterdir() if STAGING in p.name and f".{pid}." in p.name]


def _signal_after(process, signum, delay, out=None):
    """Send ``signum`` ``delay`` seconds after the run's first line, or (``out``) after its
    staging folder appeared there; (exit code, stderr)."""
    started = _until(lambda: _handles_sigterm(process.pid), process, "the start")
    if started and out is not None:
        started = _until(lambda: _staging_of(out, process.pid), process, "the staging folder")
    if started:
        time.sleep(delay)
        if process.poll() is None:
            os.kill(process.pid, signum)
    return _finish(process)


def _signal_at(process, signum):
    """Send ``signum`` where the run has stopped itself (KINDYNGEN_PAUSE_AT)."""
    assert _until(lambda: _stopped(process.pid), process, "the pause"), _finish(process)
    os.kill(process.pid, signum)
    if signum != signal.SIGKILL:
        os.kill(process.pid, signal.SIGCONT)
    return _finish(process)


class Runs:
    """An output folder ``<out>/<name>`` that one command (``argv`` with ``--out`` added: ``<out>``
    for generate, whose robot folder is ``<name>``, else ``<out>/<name>``) replaces;
    ``previous``: what an earlier, different run wrote there, ``new``: what this one writes when
    it finishes; ``seconds``: how long that took from its first line, ``writing``: from its
    staging folder's appearance."""

    def __init__(self, root: Path, name: str, previous_argv, argv):
        self.root, self.name, self.argv = root, name, argv
        self.out_is_parent = argv[0] == "generate"
        self.previous = self._complete(root / "previous", previous_argv)
        process = self.start(root / "new")
        assert _until(lambda: _handles_sigterm(process.pid), process, "the start")
        start, staged = time.monotonic(), None
        while process.poll() is None:
            if staged is None and (root / "new").is_dir() and _staging_of(root / "new", process.pid):
                staged = time.monotonic()
            time.sleep(0.01)
        self.seconds, self.writing = time.monotonic() - start, time.monotonic() - (staged or start)
        code, err = _finish(process)
        assert code == 0, err
        self.new = snapshot(root / "new" / name)
        assert self.previous != self.new

    def _out(self, out):
        return str(out if self.out_is_parent else out / self.name)

    def _complete(self, out, argv):
        code, err = _finish(_start([*argv, "--out", self._out(out)], self.root))
        assert code == 0, err
        return snapshot(out / self.name)

    def fresh(self, label):
        """A copy of the previous output, to be replaced."""
        out = self.root / label
        shutil.copytree(self.root / "previous", out, symlinks=True)
        return out

    def start(self, out, **environment):
        return _start([*self.argv, "--out", self._out(out)], self.root, **environment)

    def reset(self, out):
        """The previous output back in place (what killed runs left beside it stays)."""
        shutil.rmtree(out / self.name)
        shutil.copytree(self.root / "previous" / self.name, out / self.name, symlinks=True)

    def check(self, out, pid, code, err, signum, expect=None):
        """Either output whole (``expect``: which one), and the signal's exit."""
        found = snapshot(out / self.name)
        assert found in (self.previous, self.new), "a mix: " + "; ".join(
            f"{len([r for r in set(found) | set(whole) if found.get(r) != whole.get(r)])} files differ from the {which}"
            for which, whole in (("previous", self.previous), ("new", self.new)))
        if expect is not None:
            assert found == getattr(self, expect), f"expected the {expect} output"
        if signum == signal.SIGKILL:
            assert code in (0, -signal.SIGKILL), err
            return
        assert "Traceback" not in err, err
        assert code in (0, ENDING[signum][0]), (code, err)
        if code:
            assert err.splitlines().count(ENDING[signum][1]) == 1 and err.splitlines()[-1] == ENDING[signum][1], err
        left = [p.name for p in out.iterdir() if f".{pid}." in p.name]
        assert not left, f"a staging folder was left behind: {left}"

    def tidied_by_the_next_run(self, out):
        code, err = _finish(self.start(out))
        assert code == 0, err
        assert snapshot(out / self.name) == self.new
        assert sorted(p.name for p in out.iterdir()) == [self.name]


def _random_kills(runs: Runs, seed: int, signals):
    """Each signal at a random moment: of the whole run, and (every other one) of its writing."""
    rng = np.random.default_rng(seed)
    out = runs.fresh("random")
    for k, signum in enumerate(signals):
        writing = k % 2 == 1
        delay = float(rng.uniform(0, runs.writing if writing else runs.seconds))
        process = runs.start(out)
        code, err = _signal_after(process, signum, delay, out if writing else None)
        runs.check(out, process.pid, code, err, signum)
        if snapshot(out / runs.name) == runs.new:
            runs.reset(out)
    runs.tidied_by_the_next_run(out)


IN_THE_SWAP = (("staged", signal.SIGKILL, "previous"), ("staged", signal.SIGINT, "previous"),
               ("swapped", signal.SIGKILL, "new"), ("swapped", signal.SIGINT, "new"))


def _kills_in_the_swap(runs: Runs, cases=IN_THE_SWAP):
    """At the hook points: staged (before the swap), swapped (after the exchange, the old folder
    not yet removed; Ctrl-C waits for the swap to finish)."""
    for point, signum, expect in cases:
        out = runs.fresh(f"{point}-{signum.name}")
        process = runs.start(out, **{PAUSE_AT: point})
        code, err = _signal_at(process, signum)
        runs.check(out, process.pid, code, err, signum, expect)
        if signum == signal.SIGKILL:
            assert any(STAGING in p.name for p in out.iterdir())    # left for the next run
            runs.tidied_by_the_next_run(out)


@pytest.fixture(scope="module")
def generate_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("kill_generate")
    robot = arm3(root)
    return Runs(root, "arm3", ["generate", robot, "--quiet", "--functions", "fk_hom,jacobian,g", "--trig", "libm"],
                ["generate", robot, "--quiet"])


def test_generate_killed_or_interrupted_at_random_moments(generate_runs):
    _random_kills(generate_runs, 42, [signal.SIGKILL, signal.SIGINT, signal.SIGKILL, signal.SIGTERM,
                                      signal.SIGKILL, signal.SIGINT])


def test_generate_killed_or_interrupted_in_the_swap(generate_runs):
    _kills_in_the_swap(generate_runs)


def test_generate_killed_between_the_fallback_renames_is_recovered(generate_runs):
    """Without renameat2: the previous folder renamed aside, the new one not yet in. No
    folder then, but the next run (here tidy_leftovers, which it calls first) renames it back."""
    from kindyngen.output_folder import tidy_leftovers
    runs = generate_runs
    out = runs.fresh("aside")
    code, err = _signal_at(runs.start(out, **{PAUSE_AT: "aside", NO_EXCHANGE: "1"}), signal.SIGKILL)
    assert code == -signal.SIGKILL and not (out / runs.name).exists()
    assert len(tidy_leftovers(out / runs.name)) == 2      # recovered; the staging folder removed
    assert snapshot(out / runs.name) == runs.previous and sorted(p.name for p in out.iterdir()) == [runs.name]
    runs.tidied_by_the_next_run(out)


def _arm3_log(path, robot, seed, seconds):
    """A log of the small arm: Pinocchio's rnea plus viscous friction and noise."""
    import pinocchio as pin
    from kindyngen.readers.yaml_description import load_robot
    from tests.reference import pinocchio_model
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 0.01)
    amp, w, phase = rng.uniform(0.2, 0.6, (3, 3)), 2 * np.pi * rng.uniform(0.1, 0.5, (3, 3)), rng.uniform(0, 6.3, (3, 3))
    arg = w[None] * t[:, None, None] + phase[None]
    q, qd = np.sum(amp * np.sin(arg), 2), np.sum(amp * w * np.cos(arg), 2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), 2)
    model, data, _ = pinocchio_model(load_robot(robot))
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    tau += np.array([0.5, 0.4, 0.3]) * qd + rng.normal(scale=0.02, size=q.shape)
    header = ["t"] + [f"{k}{i}" for k in ("q", "qd", "qdd", "tau") for i in (1, 2, 3)]
    np.savetxt(path, np.column_stack([t, q, qd, qdd, tau]), delimiter=",", header=",".join(header),
               comments="", fmt="%.17g")
    return path.name


@pytest.fixture(scope="module")
def discover_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("kill_discover")
    robot = arm3(root)
    argv = ["discover", "--robot", robot, "--data", _arm3_log(root / "log.csv", robot, 7, 12), "--cutoff", "none",
            "--quiet", "--candidates", "viscous_friction,coulomb_friction"]
    return Runs(root, "found", [*argv, "--holdout", "0.4"], argv)


def test_discover_killed_or_interrupted_at_random_moments(discover_runs):
    _random_kills(discover_runs, 7, [signal.SIGKILL, signal.SIGINT, signal.SIGTERM, signal.SIGKILL])


def test_discover_killed_or_interrupted_in_the_swap(discover_runs):
    _kills_in_the_swap(discover_runs, [IN_THE_SWAP[0], IN_THE_SWAP[3]])   # the same swap as generate's


def _workers(pid):
    """The pool's worker processes among ``pid``'s children (multiprocessing's spawn)."""
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return []
    found = []
    for child in children:
        with contextlib.suppress(OSError):
            if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                found.append(child)
    return found


def test_ctrl_c_in_the_terminal_during_identify_with_workers(tmp_path):
    """Ctrl-C reaches the whole process group, the worker processes of --workers too: one
    `interrupted` line all the same, no traceback from any worker, no output folder."""
    robot = arm3(tmp_path)
    logs = [_arm3_log(tmp_path / f"run{k}.csv", robot, k, 60) for k in range(3)]
    process = _start(["identify", "--robot", robot, *[a for log in logs for a in ("--data", log)], "--split", "0.7",
                      "--workers", "2", "--out", "fit"], tmp_path, session=True)
    def workers_past_their_start():         # Python's SIGINT handler installed, or SIGINT blocked
        found = _workers(process.pid)
        return len(found) == 2 and all(signal.SIGINT in _signal_mask(w, "SigCgt") | _signal_mask(w, "SigBlk")
                                       for w in found)
    if not _until(workers_past_their_start, process, "the workers"):
        pytest.skip(f"the run ended before its workers were seen (exit {_finish(process)[0]})")
    os.killpg(process.pid, signal.SIGINT)
    code, err = _finish(process)
    assert code == 130 and err.splitlines()[-1] == "interrupted", err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == []


SWALLOWED = """
import gc, os, signal, sys
from kindyngen.cli.interrupts import ending_on_signals

class Finalised:
    def __del__(self):                       # the signal's handler runs inside a finaliser,
        os.kill(os.getpid(), signal.{sig})  # where Python can only print what it raises
        sum(range(1000))

def run():
    Finalised()
    gc.collect()
    sum(range({work}))
    print("finished", file=sys.stderr)
    return 0

sys.exit(ending_on_signals(run))
"""


@pytest.mark.parametrize("sig, word, code", [("SIGTERM", "terminated", 143), ("SIGINT", "interrupted", 130)])
@pytest.mark.parametrize("work", [10, 10 ** 8])
def test_a_signal_landing_in_a_finaliser_still_ends_the_command(sig, word, code, work):
    """A SIGTERM or Ctrl-C whose exception is raised inside a garbage-collector callback (a
    discover run printed "Exception ignored in ... Terminated" with a traceback and went on) is
    sent again and ends the command with one line and its exit code, whether the command's end
    comes first (work 10) or the resent signal does (work 1e8)."""
    done = subprocess.run([sys.executable, "-c", SWALLOWED.format(sig=sig, work=work)], capture_output=True,
                          text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=600)
    assert done.returncode == code, done.stderr
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr
    assert done.stderr.splitlines()[-1] == word
