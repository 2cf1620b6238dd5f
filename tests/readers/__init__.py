"""Tests of kindyngen.readers: robot descriptions in and out."""
