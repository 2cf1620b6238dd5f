"""Tests of kindyngen.algorithms.dualquat: the dual-quaternion route."""
