"""The command line, ``kindyngen --help`` (also ``python -m kindyngen``)."""
