"""Tests of kindyngen.algorithms: symbolic derivations on the model (kinematics, dynamics, derivatives, regressors), one algorithm family per module."""
