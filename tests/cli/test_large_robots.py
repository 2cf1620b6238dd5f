"""A robot too large for some functions (kindyngen/codegen/budget.py, docs/reference/cli.md
'Large robots'): before anything is derived the run says its estimate and leaves out what is
above the limits (or refuses it, asked for by name, with one ``error:`` line and exit 2); what
it derives it derives in bounded memory, with a progress line as each function starts; a
derivation that needs more memory than the run may use stops with one ``error:`` line naming
it, never a kill.

Each run is a subprocess under a hard address-space limit (RLIMIT_AS, ADDRESS_GB): the bound
is enforced, not only observed (a run that needs more fails), and the peak resident memory it
reports is read back: ``VmHWM`` of /proc/self/status, the peak of its own address space (Linux
carries ``ru_maxrss`` over an exec, so that one can report the forking test worker's size:
3.09 GB once in a full suite, above the 3 GB the run itself may use). No time is asserted;
HANG_GUARD_S only stops a hang."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from benchmarks.generation_cost import write_chain
from kindyngen.codegen.budget import estimate
from kindyngen.codegen.catalog import applicable_names
from kindyngen.readers.yaml_description import load_robot
from tests.harness import HANG_GUARD_S, ROOT

JOINTS = 40
ADDRESS_GB = 3.0          # the child's hard RLIMIT_AS

RUNNER = ("import resource, sys\n"
          "limit = int(float(sys.argv[1]) * 2 ** 30)\n"
          "resource.setrlimit(resource.RLIMIT_AS, (limit, limit))\n"
          "from kindyngen.cli.main import main\n"
          "code = main(sys.argv[2:])\n"
          "peak = [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM:')]\n"
          "print(f'peak_kb {peak[0] if peak else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}', file=sys.stderr)\n"
          "sys.exit(code)\n")


def _bounded(argv, address_gb=ADDRESS_GB):
    """(exit code, stdout, stderr without the peak line, peak RSS in MB) of the command line."""
    done = subprocess.run([sys.executable, "-c", RUNNER, str(address_gb), *argv], capture_output=True, text=True,
                          cwd=ROOT, timeout=HANG_GUARD_S)
    lines = done.stderr.splitlines()
    peak = [int(line.split()[1]) / 1024 for line in lines if line.startswith("peak_kb ")]
    return done.returncode, done.stdout, "\n".join(l for l in lines if not l.startswith("peak_kb ")), \
        (peak[0] if peak else None)


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    return write_chain(JOINTS, tmp_path_factory.mktemp("chain"))


def _above_the_limits(chain) -> set:
    """The functions of the chain whose measured cost (budget.COSTS, tested against the
    benchmark's results in tests/codegen/test_budget.py) is above a limit at its size."""
    return {n for n in applicable_names(load_robot(chain)) if not estimate(n, JOINTS).within_limit}


def _started(lines) -> list[tuple]:
    """(k, N, name) of each progress line that says a function starts."""
    found = [re.search(r" (\d+)/(\d+) (\w+): deriving", line) for line in lines]
    return [m.groups() for m in found if m]


def test_a_long_chain_is_generated_in_bounded_memory_with_what_is_left_out_said_first(chain, tmp_path):
    above = _above_the_limits(chain)
    assert {"fd_derivatives", "S", "c_christoffel"} <= above and "fk_hom" not in above   # the cost table's say
    code, out, err, peak = _bounded(["generate", str(chain), "--lang", "c", "--out", str(tmp_path)])
    assert code == 0, err[-3000:]
    # the enforced bound is ADDRESS_GB (a run needing more fails); the run's own peak RSS is
    # below it (550 MB, 2026-12-07)
    assert peak is not None and peak < ADDRESS_GB * 1024, peak
    lines = err.splitlines()
    # before anything is derived: the estimate, then what is left out (each one line)
    first_progress = next(k for k, line in enumerate(lines) if re.search(r" 1/\d+ fk_hom: deriving", line))
    notes = lines[:first_progress]
    estimated = [n for n in notes if n.startswith(f"note: chain{JOINTS}: {JOINTS} degrees of freedom; estimated")]
    left = [n for n in notes if n.startswith(f"note: chain{JOINTS}: left out above the limits")]
    assert len(estimated) == 1 and len(left) == 1, notes
    assert "--allow-large" in left[0]
    named = set(re.findall(r"[;:] (\w+)(?: \d|: did not finish)", left[0].split("per function", 1)[1]))
    assert named == above, named
    written = [f["name"] for f in json.loads((tmp_path / f"chain{JOINTS}" / "functions.json").read_text())["functions"]]
    assert set(written) == set(applicable_names(load_robot(chain))) - above | {"ik_dls"}, written
    # a regressor left out is not analysed either (deciding its base parameters costs as much)
    base = json.loads((tmp_path / f"chain{JOINTS}" / "base_params.json").read_text())
    for kind in ("Y", "Y_g", "Y_m"):
        assert ("left out" in base[kind].get("unavailable", "")) == (kind in above), (kind, base[kind])
    assert base["Y"]["names"]
    # a line as each function starts, in order, numbered against what is derived
    started = _started(lines)
    derived = [name for name in written if name != "ik_dls"]        # ik_dls iterates fk_hom and jacobian
    assert [name for _, _, name in started] == derived
    assert [int(k) for k, _, _ in started] == list(range(1, len(derived) + 1))
    assert {int(total) for _, total, _ in started} == {len(derived)}


def test_a_long_chain_is_counted_with_its_estimate_said_first(chain):
    asked = ["fk_hom", "M", "tau_derivatives"]
    code, out, err, peak = _bounded(["count", str(chain), "--only", *asked, "--format", "json"])
    assert code == 0, err[-3000:]
    lines = err.splitlines()
    assert lines[0].startswith(f"note: chain{JOINTS}: {JOINTS} degrees of freedom; estimated"), lines
    for name in asked:        # each with its estimate: a duration and a memory
        assert re.search(rf"[:;] {name} \d+(\.\d)? (s|min|h), \d+(\.\d)? (MB|GB)", lines[0]), (name, lines[0])
    assert not any("left out" in line for line in lines)
    assert [name for _, _, name in _started(lines)] == asked
    assert list(json.loads(out)[f"chain{JOINTS}"]) == asked


def test_a_function_above_its_limit_asked_for_by_name_is_refused_before_deriving(chain, tmp_path):
    code, out, err, _ = _bounded(["generate", str(chain), "--functions", "fk_hom,fd_derivatives", "--lang", "c",
                                  "--out", str(tmp_path / "out")])
    assert code == 2 and out == "", err[-3000:]
    error = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(error) == 1 and err.splitlines()[-1] == error[0], err
    assert "fd_derivatives" in error[0] and "fk_hom" not in error[0] and "--allow-large" in error[0], error
    assert re.search(r"fd_derivatives(: did not finish at \d+| \d+(\.\d)? (s|min|h), )", error[0]), error
    assert not re.search(r": deriving", err) and not (tmp_path / "out").exists()


@pytest.mark.parametrize("gigabytes, said", [("0.002", "2 MB"), ("0.01", "10 MB")])
def test_running_out_of_the_memory_limit_is_an_error_naming_the_function(gigabytes, said):
    # lwr4's fd_derivatives needs 10-20 MB more; at 2 MB the first C++ exception symengine
    # throws is the std::bad_alloc itself, which once ended the process in glibc (exit 127)
    code, out, err, _ = _bounded(["count", str(ROOT / "robots" / "lwr4.yaml"), "--only", "fd_derivatives",
                                  "--quiet", "--max-memory", gigabytes])
    assert code == 2 and out == "", err[-3000:]
    assert err.count("\n") == 0 and err.startswith("error: lwr4: fd_derivatives ("), err
    assert f"needed more than the memory limit of {said}" in err, err
