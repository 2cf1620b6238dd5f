"""Numeric rows of the torque regressor along measured or planned motion: the pipeline's
derived base regressor ``Y(q, qd, qdd)`` (:func:`kindyngen.algorithms.regressors.regressor`), evaluated
in batches, and the map from the full barycentric parameters to the base ones.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> rows = TorqueRegressor(load_robot("robots/lwr4.yaml"))            # doctest: +SKIP
>>> rows(np.zeros((5, 7)), np.zeros((5, 7)), np.zeros((5, 7))).shape   # doctest: +SKIP
(5, 7, 43)
"""
from __future__ import annotations

import hashlib
import os
import pickle
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import symengine as se

from ..model.inertial_parameters import parameter_vector
from ..algorithms.regressors import base_parameters, regressor
from ..model.robot_model import Link, RobotDescriptionError, RobotModel
from .effect_columns import law_torques


def rigid_body_model(model: RobotModel) -> RobotModel:
    """``model`` without its joint effects (friction, offset, armature, ripple) and without
    how its joints are measured; the payload stays (it is part of the last link's parameters)."""
    joints = tuple(replace(j, friction=None, armature=None, ripple=None, stiffness=None, encoder_offset=None,
                           torque_gain=None) for j in model.joints)
    return replace(model, joints=joints, coulomb_smoothing=None)


def refuse_mimic_joints(model: RobotModel) -> None:
    """Logs, limits and effect columns of the measured side are per joint, and a mimic joint is
    no coordinate: a robot with mimic joints is refused in one line naming the first, and so is
    a tree closed by loops (its dependent joints are none either)."""
    if model.loops:
        raise RobotDescriptionError(model.source, "loops", "identify, discover and excite take robots without closed "
                                    "loops (the regressor Y of a parallelogram linkage is generated in its independent "
                                    "joints: fit it by least squares, docs/tutorials/closed_loops.md)")
    for joint in model.joints:
        if joint.mimic is not None:
            raise RobotDescriptionError(model.source, f"joint '{joint.name}' mimic",
                                        "identify, discover and excite take robots without mimic joints (the "
                                        "generated functions of this one take its independent joints)")


_UNIT_LINK = Link(mass=1, com=(0, 0, 0), inertia=(1, 1, 1, 0, 0, 0))


def geometry_of(model: RobotModel) -> RobotModel:
    """What a regressor depends on: the rigid-body model with its inertial values, payload,
    name, source, notes and bundles replaced by fixed ones (the regressor is linear in the inertial
    parameters and its base parameters are decided without their values,
    :mod:`kindyngen.algorithms.regressors`).  Two models with the same geometry, joints and
    gravity share one regressor."""
    rigid = rigid_body_model(model)
    return replace(rigid, name="robot", source="<memory>", links=(_UNIT_LINK,) * model.n, payload=None, notes=(),
                   bundles=(),
                   root=_UNIT_LINK if model.floating_base else rigid.root)


@lru_cache(maxsize=1)
def _code_version() -> str:
    """A digest of the sources the regressors are derived by (a changed derivation is a new
    cache entry, never a stale one)."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for folder in ("algorithms", "model"):
        for path in sorted((root / folder).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    digest.update(Path(__file__).read_bytes())
    return digest.hexdigest()


def _cache_dir() -> Path:
    """Where built regressors are kept between runs: beside the compiled generated code
    (:func:`kindyngen.runtime.python_c.cache_root`, ``$KINDYNGEN_CACHE``)."""
    from ..runtime.python_c import cache_root
    return cache_root() / "regressors"


@lru_cache(maxsize=16)
def _built(geometry: RobotModel, kind: str) -> dict:
    """The regressor ``kind`` of ``geometry`` (:func:`geometry_of`) compiled for numpy: from the
    cache on disk when it holds one for the same geometry and the same derivation code
    (the key is a SHA-256 of both), else derived (1-3 s for an arm) and stored there."""
    key = hashlib.sha256(f"{kind}\0{geometry!r}\0{_code_version()}".encode()).hexdigest()[:32]
    path = _cache_dir() / f"{kind}-{geometry.n}-{key}.pickle"
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ValueError):
        pass
    function = regressor(geometry, kind)
    if function is None:
        raise ValueError("no regressor for a robot with symbolic DH lengths")
    base = base_parameters(geometry, kind)
    args = [s for syms in function.input_symbols for s in syms]
    built = dict(names=base.names, full_names=base.full_names, base_map=base.map_matrix(),
                 shape=function.outputs[0].shape, ports=tuple((p.name, p.size) for p in function.inputs),
                 fn=se.Lambdify(args, list(function.inlined_outputs()[0]), cse=True))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        with open(tmp, "wb") as f:
            pickle.dump(built, f)
        os.replace(tmp, path)           # whole or not at all, also with runs in parallel
    except OSError:
        pass                            # a read-only cache: derive again next time
    return built


class BaseRegressor:
    """A base regressor of ``model``'s rigid bodies (``kind`` "Y_g", "Y_m" or "Y", see
    :mod:`kindyngen.algorithms.regressors`) evaluated in batches: ``R(*inputs)`` -> (N, rows, columns).

    ``names``: the base parameters (columns); ``full_names``: the 10 n barycentric parameters;
    ``base``: the :class:`kindyngen.algorithms.base_parameters.BaseParameters`; ``base_map``: the matrix P
    (columns x 10 n) with ``base values = P @ full values``, so ``Y @ P`` is the regressor on
    the full parameters (as linear as the dynamics itself)."""

    def __init__(self, model: RobotModel, kind: str):
        refuse_mimic_joints(model)
        # rigid bodies only: the effects an identification fits are chosen by the caller
        # (kindyngen.measured.effect_columns), whatever the description declares
        model = rigid_body_model(model)
        built = _built(geometry_of(model), kind)
        self.model, self.n, self.kind = model, model.n, kind
        self.names, self.full_names, self.base_map = built["names"], built["full_names"], built["base_map"]
        self.shape, self._ports, self._fn = built["shape"], built["ports"], built["fn"]

    @property
    def base(self):
        """The :class:`kindyngen.algorithms.base_parameters.BaseParameters` (derived on first use)."""
        return base_parameters(geometry_of(self.model), self.kind)

    def __call__(self, *inputs) -> np.ndarray:
        """The regressor at N samples of its inputs (each (N, size) or one sample)."""
        x = np.concatenate([np.atleast_2d(np.asarray(a, float)) for a in inputs], axis=1)
        if len(inputs) != len(self._ports) or x.shape[1] != sum(size for _, size in self._ports):
            raise ValueError(f"{self.kind} expects " + ", ".join(f"{name} ({size} columns)" for name, size in self._ports))
        return np.asarray(self._fn(x), float).reshape(x.shape[0], *self.shape)


class TorqueRegressor(BaseRegressor):
    """``tau = Y(q, qd, qdd) @ base values`` for one robot (rigid bodies only): (N, n, columns)."""

    def __init__(self, model: RobotModel):
        super().__init__(model, "Y")


@lru_cache(maxsize=32)
def torque_regressor(model: RobotModel) -> TorqueRegressor:
    """:class:`TorqueRegressor` of ``model`` (its compiled regressor shared by every model of the
    same geometry and kept on disk between runs, :func:`_built`)."""
    return TorqueRegressor(model)


@lru_cache(maxsize=64)
def full_values(model: RobotModel) -> np.ndarray:
    """``parameter_vector(model)`` (exact, payload merged into the last link) as floats, once per model."""
    values = parameter_vector(model)
    values.setflags(write=False)
    return values


def description_torques(model: RobotModel, q, qd, qdd, effects: bool = True) -> np.ndarray:
    """What the robot description itself predicts along motion, (N, n) in N m: the rigid bodies
    with its parameters (payload included) and, with ``effects``, its declared joint effects
    (:func:`kindyngen.measured.effect_columns.law_torques`)."""
    R = torque_regressor(model)
    tau = R(q, qd, qdd) @ (R.base_map @ full_values(model))
    if effects and model.effects:
        tau = law_torques(model, q, qd, qdd, tau)
    return tau

