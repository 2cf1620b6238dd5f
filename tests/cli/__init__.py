"""Tests of kindyngen.cli.main: the command line, ``kindyngen --help`` (also ``python -m kindyngen``)."""
