"""Tests of kindyngen.ik: inverse kinematics."""
