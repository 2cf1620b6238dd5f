"""Write a URDF of a KinDynGen DH robot description, and check it with Pinocchio.

    .venv/bin/python examples/dh_to_urdf.py robots/lwr4.yaml [--out lwr4.urdf]   # write + self-test
    .venv/bin/python examples/dh_to_urdf.py --all                              # lwr4, panda, two_link

The URDF (for URDF-based peers such as adam-robotics and urdf2casadi):
  base_link  fixed root, = DH frame 0
  link{i}    one link per joint: its frame is the joint frame of joint i after the rotation
             Rz(q_i) (the body frame of tests/reference.py and examples/handwritten_dynamics.py);
             DH frame i is a constant transform of it (standard: Tz(d) Tx(a) Rx(alpha);
             modified: Tz(d)). Inertial: origin at the CoM, the inertia about the CoM rotated
             into the link frame (rpy = 0, so no reader has to apply the inertial rpy).
  joint{i}   revolute about z, origin = parent link frame -> joint frame at q = 0 (standard:
             ... Rz(offset); modified: ... Rx(alpha) Tx(a) Rz(offset)), with the position limits
             and (optional) effort and velocity limits.
  flange     massless link on a fixed joint at DH frame n.
Gravity is not part of URDF: pass robot.gravity to the consumer.

Self-test (run by __main__ for every URDF written): Pinocchio's model from the URDF
(pin.buildModelFromUrdf) against tests/reference.py's pinocchio_model(robot) at random states:
rnea, aba, and the flange pose agree to 1e-10.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for _p in (str(ROOT), str(ROOT / "tests")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

from kindyngen.readers.yaml_description import load_robot  # noqa: E402


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _hom(R=np.eye(3), p=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _rpy(R):
    """URDF roll-pitch-yaw (R = Rz(y) Ry(p) Rx(r))."""
    p = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    if abs(np.cos(p)) < 1e-12:   # gimbal lock: put everything into yaw
        return np.array([0.0, p, np.arctan2(-R[0, 1], R[1, 1])])
    return np.array([np.arctan2(R[2, 1], R[2, 2]), p, np.arctan2(R[1, 0], R[0, 0])])


def _f(x):
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def _origin(T):
    xyz = " ".join(_f(v) for v in T[:3, 3])
    rpy = " ".join(_f(v) for v in _rpy(T[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def dh_frames(robot):
    """Per joint i: (P_i, B_i) with P_i = parent body frame -> joint frame at q = 0 and
    B_i = body frame i -> DH frame i (4x4 numpy), as in tests/reference.py."""
    out, previous = [], np.eye(4)
    for j in robot.joints:
        a, alpha, d, off = (float(getattr(j, k)) for k in ("a", "alpha", "d", "offset"))
        if robot.convention == "standard":
            P = previous @ _hom(_rz(off))
            B = _hom(_rx(alpha), [a, 0, d])
        else:
            P = previous @ _hom(_rx(alpha), [a, 0, 0]) @ _hom(_rz(off))
            B = _hom(np.eye(3), [0, 0, d])
        out.append((P, B))
        previous = B
    return out


def urdf_string(robot, effort=None, velocity=None) -> str:
    """The URDF text of a KinDynGen RobotModel (revolute joints only)."""
    n = robot.n
    effort = np.full(n, 1000.0) if effort is None else np.asarray(effort, float)
    velocity = np.full(n, 100.0) if velocity is None else np.asarray(velocity, float)
    lines = ['<?xml version="1.0"?>',
             f'<!-- written by examples/dh_to_urdf.py from the KinDynGen description "{escape(robot.name)}" '
             f'({robot.convention} DH); gravity {list(map(float, robot.gravity))} is not part of URDF -->',
             f'<robot name="{escape(robot.name)}">',
             '  <link name="base_link"/>']
    frames = dh_frames(robot)
    for i, ((P, B), link) in enumerate(zip(frames, robot.links)):
        R, p = B[:3, :3], B[:3, 3]
        com = R @ np.array(link.com, float) + p
        Ib = R @ link.inertia_matrix() @ R.T
        Ib = 0.5 * (Ib + Ib.T)
        parent = "base_link" if i == 0 else f"link{i}"
        lo, hi = float(robot.joints[i].lower), float(robot.joints[i].upper)
        lines += [
            f'  <joint name="joint{i + 1}" type="revolute">',
            f'    <parent link="{parent}"/>', f'    <child link="link{i + 1}"/>',
            f'    {_origin(P)}', '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{_f(lo)}" upper="{_f(hi)}" effort="{_f(effort[i])}" velocity="{_f(velocity[i])}"/>',
            '  </joint>',
            f'  <link name="link{i + 1}">', '    <inertial>',
            f'      <origin xyz="{" ".join(_f(v) for v in com)}" rpy="0 0 0"/>',
            f'      <mass value="{_f(link.mass)}"/>',
            f'      <inertia ixx="{_f(Ib[0, 0])}" ixy="{_f(Ib[0, 1])}" ixz="{_f(Ib[0, 2])}" '
            f'iyy="{_f(Ib[1, 1])}" iyz="{_f(Ib[1, 2])}" izz="{_f(Ib[2, 2])}"/>',
            '    </inertial>', '  </link>']
    lines += ['  <joint name="flange_joint" type="fixed">', f'    <parent link="link{n}"/>',
              '    <child link="flange"/>', f'    {_origin(frames[-1][1])}', '  </joint>',
              '  <link name="flange"/>', '</robot>', '']
    return "\n".join(lines)


def write_urdf(robot, path, effort=None, velocity=None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(urdf_string(robot, effort, velocity))
    return path


def check_against_reference(robot, urdf_path, count: int = 20, seed: int = 1, tol: float = 1e-10) -> dict:
    """Pinocchio on the URDF vs tests/reference.py's pinocchio_model: max |difference| of rnea,
    aba and the flange pose at `count` random states. Raises AssertionError above tol."""
    import pinocchio as pin
    from reference import pinocchio_model
    ref, rdata, rflange = pinocchio_model(robot)
    model = pin.buildModelFromUrdf(str(urdf_path))
    model.gravity = pin.Motion(np.array(robot.gravity, float), np.zeros(3))
    data = model.createData()
    flange = model.getFrameId("flange")
    assert model.nq == robot.n, (model.nq, robot.n)
    rng = np.random.default_rng(seed)
    err = {"rnea": 0.0, "aba": 0.0, "fk": 0.0}
    for _ in range(count):
        q = rng.uniform(robot.lower, robot.upper)
        qd, qdd, tau = (rng.uniform(-2, 2, robot.n) for _ in range(3))
        err["rnea"] = max(err["rnea"], np.abs(pin.rnea(model, data, q, qd, qdd) - pin.rnea(ref, rdata, q, qd, qdd)).max())
        err["aba"] = max(err["aba"], np.abs(pin.aba(model, data, q, qd, tau) - pin.aba(ref, rdata, q, qd, tau)).max())
        pin.framesForwardKinematics(model, data, q)
        pin.framesForwardKinematics(ref, rdata, q)
        err["fk"] = max(err["fk"], np.abs(data.oMf[flange].homogeneous - rdata.oMf[rflange].homogeneous).max())
    err = {k: float(v) for k, v in err.items()}
    bad = {k: v for k, v in err.items() if not v <= tol}
    assert not bad, f"{robot.name}: URDF differs from tests/reference.py: {bad}"
    return err


ROBOTS = {"lwr4": ROOT / "robots" / "lwr4.yaml", "panda": ROOT / "robots" / "panda.yaml",
          "two_link": ROOT / "examples" / "two_link.yaml"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("yaml", nargs="*", help="robot descriptions (default with --all: lwr4, panda, two_link)")
    ap.add_argument("--all", action="store_true")
    ap.add_argument("--out", help="URDF path (one robot) or folder (default examples/results/urdf)")
    args = ap.parse_args(argv)
    paths = [Path(p) for p in args.yaml] or (list(ROBOTS.values()) if args.all else [])
    if not paths:
        ap.error("give a robot description or --all")
    for yp in paths:
        robot = load_robot(yp)
        if args.out and len(paths) == 1 and args.out.endswith(".urdf"):
            out = Path(args.out)
        else:
            out = Path(args.out or Path(__file__).resolve().parent / "results" / "urdf") / f"{robot.name}.urdf"
        write_urdf(robot, out)
        err = check_against_reference(robot, out)
        print(f"{robot.name}: wrote {out}; Pinocchio(URDF) vs reference: "
              + ", ".join(f"{k} {v:.1e}" for k, v in err.items()))


if __name__ == "__main__":
    main()
