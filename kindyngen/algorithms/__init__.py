"""Symbolic derivations on the model (kinematics, dynamics, derivatives, regressors), one algorithm family per module."""
