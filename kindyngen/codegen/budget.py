"""How much work a run is, and what happens when it exceeds its bounds."""
from __future__ import annotations


class GenerationMemoryError(Exception):
    """Deriving or optimising a function needed more memory than the run's limit
    (:func:`kindyngen.codegen.pipeline.build_programs`; the command line: one ``error:`` line)."""
