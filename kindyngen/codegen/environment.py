"""The jinja2 environments that render the templates (``kindyngen/codegen/templates/``), one per
kind of output file, each printing the user's text through that file's escaper.

The renderers mark every string that comes from the user (the robot's name, the description's
file name, and the texts algorithms compose from joint, link and frame names: summaries,
conventions, port descriptions) as :class:`UserText`. A template prints it like any string;
the environment's ``finalize`` passes it through the escaper of the file being written
(:mod:`kindyngen.model.user_text`: a C comment, a Python docstring, a MATLAB comment, a CMake
comment), and ``wordwrap`` wraps the text as written, then escapes each line. Everything else
(code, numbers, the templates' own text) is printed unchanged. So the escaping is decided once,
by the file, not at each place a name is used.

>>> from kindyngen.model.user_text import c_comment
>>> env = environment(c_comment)
>>> env.from_string("/* robot {{ name }} */").render(name=UserText("x*/ int evil; /*"))
'/* robot x* / int evil; / * */'
>>> env.from_string("{{ name }}").render(name="a*/b")          # not user text: printed as is
'a*/b'
"""
from __future__ import annotations

from pathlib import Path

import jinja2
from jinja2.filters import do_wordwrap

TEMPLATES = Path(__file__).resolve().parent / "templates"


class UserText(str):
    """A string from the user's files (or composed from one): data, escaped wherever a template
    prints it."""


def blank(text: str) -> str:
    """The escaper of a module rendered only to be run (the CasADi builders the pipeline saves
    as .casadi files): no user text at all."""
    return ""


def environment(escape) -> jinja2.Environment:
    """The templates' environment for one kind of file: every UserText printed through
    ``escape`` (one of :mod:`kindyngen.model.user_text`'s escapers, or :func:`blank`)."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), keep_trailing_newline=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined,
                             finalize=lambda value: escape(value) if isinstance(value, UserText) else value)

    @jinja2.pass_environment
    def wordwrap(env, s, width=79, break_long_words=True, wrapstring=None, break_on_hyphens=True):
        wrapped = do_wordwrap(env, s, width, break_long_words, wrapstring, break_on_hyphens)
        if not isinstance(s, UserText):
            return wrapped
        separator = env.newline_sequence if wrapstring is None else wrapstring
        return separator.join(escape(line) for line in wrapped.split(separator))

    env.filters["wordwrap"] = wordwrap
    return env
