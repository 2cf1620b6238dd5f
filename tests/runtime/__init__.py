"""Tests of kindyngen.runtime: generated code run from python."""
