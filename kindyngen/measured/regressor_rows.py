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

from dataclasses import replace
from functools import lru_cache

import numpy as np
import symengine as se

from ..model.inertial_parameters import parameter_vector
from ..algorithms.regressors import base_parameters, regressor
from ..model.robot_model import RobotModel
from .effect_columns import law_torques


def rigid_body_model(model: RobotModel) -> RobotModel:
    """``model`` without its joint effects (friction, offset, armature); the payload stays
    (it is part of the last link's parameters)."""
    joints = tuple(replace(j, friction=None, armature=None) for j in model.joints)
    return replace(model, joints=joints, coulomb_smoothing=None)


class BaseRegressor:
    """A base regressor of ``model``'s rigid bodies (``kind`` "Y_g", "Y_m" or "Y", see
    :mod:`kindyngen.algorithms.regressors`) evaluated in batches: ``R(*inputs)`` -> (N, rows, columns).

    ``names``: the base parameters (columns); ``full_names``: the 10 n barycentric parameters;
    ``base``: the :class:`kindyngen.algorithms.base_parameters.BaseParameters`; ``base_map``: the matrix P
    (columns x 10 n) with ``base values = P @ full values``, so ``Y @ P`` is the regressor on
    the full parameters (as linear as the dynamics itself)."""

    def __init__(self, model: RobotModel, kind: str):
        # rigid bodies only: the effects an identification fits are chosen by the caller
        # (kindyngen.measured.effect_columns), whatever the description declares
        model = rigid_body_model(model)
        function = regressor(model, kind)
        if function is None:
            raise ValueError(f"{model.source}: no regressor for a robot with symbolic DH lengths")
        self.model, self.n, self.kind = model, model.n, kind
        self.base = base_parameters(model, kind)
        self.names = self.base.names
        self.full_names = self.base.full_names
        self.base_map = self.base.map_matrix()
        self.shape = function.outputs[0].shape
        self._ports = function.inputs
        args = [s for syms in function.input_symbols for s in syms]
        self._fn = se.Lambdify(args, list(function.inlined_outputs()[0]), cse=True)

    def __call__(self, *inputs) -> np.ndarray:
        """The regressor at N samples of its inputs (each (N, size) or one sample)."""
        x = np.concatenate([np.atleast_2d(np.asarray(a, float)) for a in inputs], axis=1)
        if len(inputs) != len(self._ports) or x.shape[1] != sum(p.size for p in self._ports):
            raise ValueError(f"{self.kind} expects " + ", ".join(f"{p.name} ({p.size} columns)" for p in self._ports))
        return np.asarray(self._fn(x), float).reshape(x.shape[0], *self.shape)


class TorqueRegressor(BaseRegressor):
    """``tau = Y(q, qd, qdd) @ base values`` for one robot (rigid bodies only): (N, n, columns)."""

    def __init__(self, model: RobotModel):
        super().__init__(model, "Y")


@lru_cache(maxsize=8)
def torque_regressor(model: RobotModel) -> TorqueRegressor:
    """:class:`TorqueRegressor` of ``model``, built once per model (the symbolic derivation
    takes about a second and callers evaluate one model many times)."""
    return TorqueRegressor(model)


def description_torques(model: RobotModel, q, qd, qdd, effects: bool = True) -> np.ndarray:
    """What the robot description itself predicts along motion, (N, n) in N m: the rigid bodies
    with its parameters (payload included) and, with ``effects``, its declared joint effects
    (:func:`kindyngen.measured.effect_columns.law_torques`)."""
    R = torque_regressor(model)
    tau = R(q, qd, qdd) @ (R.base_map @ parameter_vector(model))
    if effects and model.effects:
        tau = law_torques(model, q, qd, qdd, tau)
    return tau

