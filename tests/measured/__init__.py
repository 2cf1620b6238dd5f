"""Tests of kindyngen.measured: logs, identification, excitation and discovery."""
