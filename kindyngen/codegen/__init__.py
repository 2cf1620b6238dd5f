"""Symbolic functions to source text: the catalog of functions, CSE, operation counts, printers, the C trig kernel and the jinja2 templates."""
