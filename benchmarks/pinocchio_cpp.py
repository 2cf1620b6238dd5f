"""Pinocchio C++ timings ("pinocchio_cpp"): build pinocchio_bench.cpp header-only against
the pin wheel's headers, write the robot as numbers, run it, parse its lines.

Header-only because linking the wheel's precompiled libpinocchio_default together with
-march=native crashes (Eigen alignment differs between the two builds).
"""
from __future__ import annotations

import subprocess
import sysconfig
from pathlib import Path

import numpy as np

from .build import Built, build, target

SOURCE = Path(__file__).resolve().parent / "pinocchio_bench.cpp"
HEADER = SOURCE.with_name("pinocchio_model.hpp")  # the model reader, shared with the SX tracer
TIMING = SOURCE.with_name("bench_timing.hpp")       # the timing loop, shared with the tree bench
ARGS = SOURCE.with_name("program_args.hpp")         # the command-line check of every benchmark program
# Pinocchio's joint variant needs Boost's MPL/Fusion limits raised.
BOOST_FLAGS = ["-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
               "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12"]
FLAGS = ["-std=c++17", "-O3", "-march=native", "-DNDEBUG", *BOOST_FLAGS]
# Generated function name -> the algorithm in pinocchio_bench.cpp that computes the same.
ALGORITHM = {"fk_hom": "fk", "fk_dq": "fk", "jacobian": "jacobian", "tau": "tau", "M": "M",
             "g": "g", "c": "c", "S": "S", "fd": "fd", "Y": "Y",
             "Minv": "Minv", "tau_derivatives": "tau_derivatives", "fd_derivatives": "fd_derivatives"}
# Timed even when generated/ has no such function (yet): the peers' figures stand on their own.
ALWAYS = ("Minv", "tau_derivatives", "fd_derivatives")
FAMILIES = ("M", "g", "c", "tau")  # M_lagrange, c_christoffel, ...: other routes, same quantity


def algorithm_for(function_name: str) -> str | None:
    if function_name in ALGORITHM:
        return ALGORITHM[function_name]
    family = function_name.split("_", 1)[0]
    return ALGORITHM[family] if family in FAMILIES else None


NOTES = {
    "fk_dq": "forwardKinematics + updateFramePlacement (SE3 pose; no dual-quaternion form)",
    "fk_hom": "forwardKinematics + updateFramePlacement",
    "jacobian": "computeFrameJacobian, LOCAL_WORLD_ALIGNED",
    "M": "crba (upper triangle only)",
    "g": "computeGeneralizedGravity",
    "tau": "rnea",
    "fd": "aba",
    "Minv": "computeMinverse (upper triangle only)",
    "c": "nonLinearEffects (c + g: no Coriolis-only call)",
    "S": "computeCoriolisMatrix",
    "Y": "computeJointTorqueRegressor (all 10n columns)",
    "tau_derivatives": "computeRNEADerivatives (dtau/dq, dtau/dqd; dtau/dqdd = M comes along)",
    "fd_derivatives": "computeABADerivatives (dqdd/dq, dqdd/dqd, Minv)",
}


def note_for(function_name: str) -> str:
    """What Pinocchio runs as the counterpart of a generated function."""
    return (NOTES.get(function_name) or NOTES.get(function_name.split("_", 1)[0])
            or algorithm_for(function_name) or "")


def include_dirs() -> list[Path]:
    """The wheel's headers (cmeel prefix) and an Eigen 3 that goes with them."""
    site = Path(sysconfig.get_paths()["purelib"])
    prefix = site / "cmeel.prefix" / "include"
    dirs = [prefix]
    for eigen in (prefix / "eigen3", site / "casadi" / "include" / "eigen3", Path("/usr/include/eigen3")):
        if (eigen / "Eigen" / "Core").exists():
            dirs.append(eigen)
            break
    return dirs


def _build_args() -> tuple:
    return ("pinocchio_bench", "g++", [SOURCE], FLAGS + [f"-I{d}" for d in include_dirs()], (), (HEADER, TIMING, ARGS))


def build_binary() -> Built:
    return build(*_build_args())


def binary_cached() -> bool:
    """Whether build_binary() would return at once (its slow cold build is done)."""
    return target(*_build_args()).exists()


# --- the robot as numbers: the same construction as tests/reference.py ----------------------
def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _compose(a, b):
    (Ra, pa), (Rb, pb) = a, b
    return Ra @ Rb, Ra @ pb + pa


def model_text(robot) -> str:
    """Joint placements and joint-frame inertias of a DH arm (revolute-z joints).

    Standard DH: joint i sits at the previous link's static part Tz(d) Tx(a) Rx(alpha) and
    link i is that static part after the joint; modified DH: the static part Rx(alpha) Tx(a)
    comes before the joint and Tz(d) after."""
    ident = (np.eye(3), np.zeros(3))
    lines = [str(robot.n), " ".join(repr(float(g)) for g in robot.gravity)]
    placement = ident
    for joint, link in zip(robot.joints, robot.links):
        a, alpha, d, off = (float(getattr(joint, k)) for k in ("a", "alpha", "d", "offset"))
        if robot.convention == "standard":
            joint_placement = _compose(placement, (_rz(off), np.zeros(3)))
            body_to_link = (_rx(alpha), np.array([a, 0.0, d]))
        else:
            joint_placement = _compose(_compose(placement, (_rx(alpha), np.array([a, 0.0, 0.0]))),
                                       (_rz(off), np.zeros(3)))
            body_to_link = (np.eye(3), np.array([0.0, 0.0, d]))
        R, p = body_to_link
        com = R @ np.array(link.com, float) + p
        inertia = R @ link.inertia_matrix() @ R.T
        values = [*joint_placement[0].ravel(), *joint_placement[1], link.mass, *com,
                  inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1], inertia[1, 2], inertia[2, 2]]
        lines.append(" ".join(repr(float(v)) for v in values))
        placement = body_to_link
    lines.append(" ".join(repr(float(v)) for v in [*placement[0].ravel(), *placement[1]]))
    return "\n".join(lines) + "\n"


def prepare(robot, inputs: dict, workdir: Path) -> tuple[Path, Path, int]:
    """Write the model and the inputs (q, qd, qdd, tau) for the binary."""
    workdir.mkdir(parents=True, exist_ok=True)
    model_file = workdir / f"{robot.identifier}_pinocchio_model.txt"
    model_file.write_text(model_text(robot))
    arrays = [np.ascontiguousarray(inputs[k], dtype=np.float64) for k in ("q", "qd", "qdd", "tau")]
    input_file = workdir / f"{robot.identifier}_pinocchio_inputs.bin"
    np.concatenate([a.ravel() for a in arrays]).tofile(input_file)
    return model_file, input_file, arrays[0].shape[0]


def measure(binary: Path, prepared: tuple, repeats: int, target_ns: float) -> tuple[dict, dict]:
    """Run once: ({algorithm: [ns per call per repetition]}, {algorithm: [flat row-major
    result for input 0, one per output]}), where "fk" holds the top three rows of the flange
    pose and "c" is nonLinearEffects - gravity."""
    model_file, input_file, K = prepared
    out = subprocess.run([str(binary), str(model_file), str(input_file), str(K), str(repeats), str(target_ns)],
                         capture_output=True, text=True, check=True)
    times, checks = {}, {}
    # "time NAME t1 .. tR" / "check NAME v1 .. vm" / "check NAME.OUTPUT v1 .. vm" (outputs in order)
    for line in out.stdout.splitlines():
        kind, name, *values = line.split()
        if kind == "time":
            times[name] = [float(v) for v in values]
        else:
            checks.setdefault(name.split(".", 1)[0], []).append(np.array([float(v) for v in values]))
    return times, checks
