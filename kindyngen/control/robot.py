"""A robot prepared for optimal control: its generated functions (fd, fd_derivatives, tau and
the flange pose fk_hom) as CasADi Functions and as C, written once per description into a
cache keyed by content, and its joint limits.

``prepare(model)`` derives the four functions of ``model`` by the pipeline that writes
``generated/`` (:func:`kindyngen.codegen.pipeline.build_programs`, ``render_c``,
``render_casadi``), into ``<cache>/control/<robot>-<key>/`` with ``key`` a hash of the model
(its exact numbers) and of the generator's own source: the same description on the same
generator is derived once, any change derives anew. Writing goes through a temporary folder
renamed into place, so a concurrent or interrupted run never leaves half a folder.

Example (the UR5 of example-robot-data would be read the same way, with ``tip="tool0"``):

>>> from kindyngen.readers.yaml_description import load_robot
>>> robot = prepare(load_robot("robots/lwr4.yaml"), progress=False)      # doctest: +SKIP
>>> robot.n, robot.fd.name()                                              # doctest: +SKIP
(7, 'fd')
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.robot_model import RobotModel

#: the generated functions the controllers call
FUNCTIONS = ("fd", "fd_derivatives", "tau", "fk_hom")
PACKAGE = Path(__file__).resolve().parents[1]
#: the folders whose source decides what the pipeline writes (and so the cache key)
GENERATOR_FOLDERS = ("algorithms", "codegen", "model", "readers", "ik")


class ControlError(ValueError):
    """A control problem that cannot be posed or solved as asked (bad limits, a goal out of
    reach, a robot the controllers do not handle): the CLI prints it as one ``error:`` line."""


@dataclass(frozen=True)
class Limits:
    """Joint limits: positions (rad or m), speeds (rad/s or m/s) and torques (N m or N), each a
    tuple of one value per joint; speeds and torques symmetric (|qd| <= qd_max, |tau| <= tau_max).

    >>> Limits((-1.0,), (1.0,), (2.0,), (3.0,)).backed_off(0.1, 0.5).qd_max
    (1.8,)
    """
    q_lo: tuple
    q_hi: tuple
    qd_max: tuple
    tau_max: tuple

    def __post_init__(self):
        n = len(self.q_lo)
        for name in ("q_hi", "qd_max", "tau_max"):
            if len(getattr(self, name)) != n:
                raise ControlError(f"limits: {name} has {len(getattr(self, name))} values for {n} joints")
        for j in range(n):
            if not self.q_lo[j] < self.q_hi[j]:
                raise ControlError(f"limits: joint {j + 1}: lower position {self.q_lo[j]} not below upper {self.q_hi[j]}")
            for name in ("qd_max", "tau_max"):
                v = getattr(self, name)[j]
                if not (np.isfinite(v) and v > 0):
                    raise ControlError(f"limits: joint {j + 1}: {name} must be a positive finite number, got {v}")

    @property
    def n(self) -> int:
        return len(self.q_lo)

    def array(self, name: str) -> np.ndarray:
        return np.array(getattr(self, name), float)

    def backed_off(self, speed: float = 0.0, position: float = 0.0, torque: float = 0.0) -> "Limits":
        """The limits a plan keeps to: speeds scaled by (1 - speed), positions moved in by
        ``position`` rad, torques scaled by (1 - torque) (stated margins for what happens between
        nodes and under disturbances, and for a feedback loop's share of the torque)."""
        return Limits(tuple(lo + position for lo in self.q_lo), tuple(hi - position for hi in self.q_hi),
                      tuple((1.0 - speed) * v for v in self.qd_max), tuple((1.0 - torque) * v for v in self.tau_max))


def urdf_limits(path, model: RobotModel) -> Limits:
    """Speed and effort limits of the model's joints from the URDF's ``<limit velocity effort>``
    (positions from the model); a joint without them is an error naming it."""
    root = ET.parse(str(path)).getroot()
    found = {}
    for joint in root.iter("joint"):
        lim = joint.find("limit")
        if lim is not None:
            found[joint.get("name")] = lim
    qd, tau = [], []
    for j, joint in enumerate(model.joints):
        lim = found.get(joint.name)
        if lim is None or lim.get("velocity") is None or lim.get("effort") is None:
            raise ControlError(f"{path}: joint '{joint.name or j + 1}': no <limit velocity=... effort=...>; "
                               "give the limits in a file (--limits)")
        qd.append(float(lim.get("velocity")))
        tau.append(float(lim.get("effort")))
    return Limits(tuple(model.lower.tolist()), tuple(model.upper.tolist()), tuple(qd), tuple(tau))


def read_limits(path, model: RobotModel) -> Limits:
    """Limits from a YAML file ``{velocity: [...], effort: [...]}`` (rad/s, N m; one per joint),
    optionally ``lower: [...]``, ``upper: [...]`` (default: the model's position limits)."""
    import yaml
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ControlError(f"{path}: cannot read limits: {exc}") from None
    if not isinstance(doc, dict):
        raise ControlError(f"{path}: expected a mapping with 'velocity' and 'effort'")
    out = {}
    for key, default in (("lower", model.lower), ("upper", model.upper), ("velocity", None), ("effort", None)):
        value = doc.get(key, None if default is None else list(default))
        if value is None:
            raise ControlError(f"{path}: field '{key}': missing (one value per joint, {model.n} joints)")
        try:
            value = tuple(float(v) for v in value)
        except (TypeError, ValueError):
            raise ControlError(f"{path}: field '{key}': expected a list of {model.n} numbers") from None
        if len(value) != model.n:
            raise ControlError(f"{path}: field '{key}': {len(value)} values for {model.n} joints")
        out[key] = value
    try:
        return Limits(out["lower"], out["upper"], out["velocity"], out["effort"])
    except ControlError as exc:
        raise ControlError(f"{path}: {exc}") from None


@functools.lru_cache(maxsize=1)
def generator_fingerprint() -> str:
    """Hash of the source that decides what the pipeline writes for a model."""
    h = hashlib.sha256()
    for folder in GENERATOR_FOLDERS:
        for path in sorted((PACKAGE / folder).rglob("*")):
            if path.is_file() and path.suffix in (".py", ".j2", ".c", ".h"):
                h.update(str(path.relative_to(PACKAGE)).encode())
                h.update(path.read_bytes())
    return h.hexdigest()


def model_key(model: RobotModel) -> str:
    """Content key of a model: its exact numbers (notes and source path left out) and the generator."""
    plain = dataclasses.replace(model, notes=(), source="")
    return hashlib.sha256((repr(plain) + "\0" + generator_fingerprint() + "\0" + ",".join(FUNCTIONS)).encode()).hexdigest()


def cache_root() -> Path:
    from ..runtime.python_c import cache_root as root
    return root() / "control"


@dataclass(frozen=True)
class ControlRobot:
    """A prepared robot: the model, the folder holding its generated C (``c/<id>.c``) and
    CasADi Functions (``casadi/<name>.casadi``), loaded on first use."""
    model: RobotModel
    folder: Path
    key: str

    @property
    def n(self) -> int:
        return self.model.n

    @property
    def name(self) -> str:
        return self.model.identifier

    @property
    def c_source(self) -> Path:
        return self.folder / "c" / f"{self.name}.c"

    def function(self, name: str):
        import casadi as ca
        return ca.Function.load(str(self.folder / "casadi" / f"{name}.casadi"))

    @functools.cached_property
    def fd(self):
        return self.function("fd")

    @functools.cached_property
    def fd_derivatives(self):
        return self.function("fd_derivatives")

    @functools.cached_property
    def tau(self):
        return self.function("tau")

    @functools.cached_property
    def fk_hom(self):
        return self.function("fk_hom")

    def flange_position(self, q) -> np.ndarray:
        return np.array(self.fk_hom(np.asarray(q, float))).reshape(4, 4)[:3, 3].copy()

    def gravity_torque(self, q) -> np.ndarray:
        z = np.zeros(self.n)
        return np.array(self.tau(np.asarray(q, float), z, z)).ravel()


def prepare(model: RobotModel, cache: Path | None = None, progress=None) -> ControlRobot:
    """The robot's generated functions, derived into the cache unless already there.
    ``progress``: a callable taking one line of text (None: silent)."""
    if not model.is_chain or model.floating_base:
        raise ControlError(f"{model.name}: the controllers handle fixed-base serial arms; this description is a "
                           "tree or has a floating base")
    key = model_key(model)
    folder = Path(cache or cache_root()) / f"{model.identifier}-{key[:16]}"
    if (folder / "done").is_file():
        return ControlRobot(model, folder, key)
    from ..codegen.pipeline import build_programs, save_casadi_functions
    from ..codegen.render import render_c, render_casadi
    if progress:
        progress(f"deriving fd, fd_derivatives, tau, fk_hom of {model.name} (once; cached in {folder})")
    programs = build_programs(model, only=set(FUNCTIONS), progress=False)
    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        (staging / "c").mkdir()
        (staging / "casadi").mkdir()
        for fname, text in render_c(model, programs, batch=False).items():
            (staging / "c" / fname).write_text(text)
        for fname, text in render_casadi(model, programs).items():
            (staging / "casadi" / fname).write_text(text)
            save_casadi_functions(text, staging / "casadi")
        (staging / "done").write_text(key + "\n")
        try:
            os.replace(staging, folder)
        except OSError:            # another process put it there first: theirs is the same
            if not (folder / "done").is_file():
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return ControlRobot(model, folder, key)
