"""Numeric rows of the torque regressor along measured or planned motion: the pipeline's
derived base regressor ``Y(q, qd, qdd)`` (:func:`kindyngen.regressors.regressor`), evaluated
in batches, and the map from the full barycentric parameters to the base ones.

Example:

>>> from kindyngen.robot import load_robot
>>> rows = TorqueRegressor(load_robot("robots/lwr4.yaml"))            # doctest: +SKIP
>>> rows(np.zeros((5, 7)), np.zeros((5, 7)), np.zeros((5, 7))).shape   # doctest: +SKIP
(5, 7, 43)
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import symengine as se

from ..inertial_parameters import parameter_vector
from ..joint_effects import effect_parameter_values
from ..regressors import base_parameters, regressor
from ..robot import RobotModel
from .effects import coulomb_eps, effect_columns


def rigid_body_model(model: RobotModel) -> RobotModel:
    """``model`` without its joint effects (friction, offset, armature); the payload stays
    (it is part of the last link's parameters)."""
    joints = tuple(replace(j, friction=None, armature=None) for j in model.joints)
    return replace(model, joints=joints, coulomb_smoothing=None)


class TorqueRegressor:
    """``tau = Y(q, qd, qdd) @ base values`` for one robot (rigid bodies only).

    ``names``: the base parameters (columns); ``full_names``: the 10 n barycentric parameters;
    ``base_map``: the matrix P (columns x 10 n) with ``base values = P @ full values``, so
    ``Y @ P`` is the regressor on the full parameters (as linear as the dynamics itself)."""

    def __init__(self, model: RobotModel):
        # rigid bodies only: the effects an identification fits are chosen by the caller
        # (kindyngen.measured.effects), whatever the description declares
        model = rigid_body_model(model)
        function = regressor(model, "Y")
        if function is None:
            raise ValueError(f"{model.source}: no regressor for a robot with symbolic DH lengths")
        self.model = model
        self.n = model.n
        b = base_parameters(model, "Y")
        self.names = b.names
        self.full_names = b.full_names
        self.base_map = b.map_matrix()
        args = [s for syms in function.input_symbols for s in syms]
        self._columns = len(b.names)
        self._fn = se.Lambdify(args, list(function.output_exprs[0]), cse=True)

    def __call__(self, q, qd, qdd) -> np.ndarray:
        """The regressor at N samples: array (N, n, columns)."""
        x = np.concatenate([np.atleast_2d(np.asarray(a, float)) for a in (q, qd, qdd)], axis=1)
        if x.shape[1] != 3 * self.n:
            raise ValueError(f"expected q, qd, qdd with {self.n} columns each")
        out = np.asarray(self._fn(x), float)
        return out.reshape(x.shape[0], self.n, self._columns)


@lru_cache(maxsize=8)
def torque_regressor(model: RobotModel) -> TorqueRegressor:
    """:class:`TorqueRegressor` of ``model``, built once per model (the symbolic derivation
    takes about a second and callers evaluate one model many times)."""
    return TorqueRegressor(model)


def description_torques(model: RobotModel, q, qd, qdd, effects: bool = True) -> np.ndarray:
    """What the robot description itself predicts along motion, (N, n) in N m: the rigid bodies
    with its parameters (payload included) and, with ``effects``, its declared friction, offset
    and armature (the formulas of :mod:`kindyngen.measured.effects`)."""
    R = torque_regressor(model)
    tau = R(q, qd, qdd) @ (R.base_map @ parameter_vector(model))
    if effects and model.effects:
        values = np.array([float(v) for v in effect_parameter_values(model)])
        tau = tau + effect_columns(model.effects, qd, qdd, coulomb_eps(model)) @ values
    return tau

