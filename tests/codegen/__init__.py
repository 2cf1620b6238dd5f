"""Tests of kindyngen.codegen: symbolic functions to source text."""
