"""A YAML description file as plain data (dicts, lists, numbers, strings), read within bounds.

PyYAML's safe loader builds no objects but plain data, yet it trusts the document's shape:
its composer recurses once per nesting level (100,000 nested ``[`` end in a RecursionError),
aliases share nodes so that a 1 kB "billion laughs" document stands for a billion items (any
walk over it, an error message's repr included, never ends), a repeated key silently keeps
the last value, and an integer of 5,000 digits ends in int()'s ValueError. Here the file is refused,
as a :class:`kindyngen.model.robot_model.RobotDescriptionError` naming the file, the line and
the reason, when it

* is larger than :data:`kindyngen.readers.input_bounds.MAX_YAML_BYTES`;
* nests deeper than :data:`MAX_DEPTH` (counted while composing, before the recursion grows);
* stands for more than :data:`MAX_NODES` nodes once its aliases are expanded, or refers to
  itself (an anchor used inside its own value);
* repeats a key in a mapping (both lines named; merge keys ``<<`` may be overridden as YAML
  intends);
* writes an integer with more than :data:`MAX_INTEGER_DIGITS` characters.

Example:

>>> load_yaml_text("a: 1\\nb: [2, 3]\\n", "f.yaml")
{'a': 1, 'b': [2, 3]}
>>> load_yaml_text("a: 1\\nb: 2\\na: 3\\n", "f.yaml")
Traceback (most recent call last):
...
kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field '<yaml>': key 'a' repeated at line 3, column 1 (first at line 1, column 1): a description gives each key once
"""
from __future__ import annotations

from pathlib import Path

import yaml

from ..model.robot_model import RobotDescriptionError
from .input_bounds import MAX_YAML_BYTES, read_bounded, shown

MAX_DEPTH = 20               # a description nests 5 deep (top, joints, a joint, origin, xyz)
MAX_NODES = 1_000_000        # with aliases expanded; about the most a 1 MiB file holds without (a value per byte)
MAX_INTEGER_DIGITS = 4000    # characters of an integer scalar: below int()'s 4300 digits, and
                             # longer than any double (309 digits), refused by its field
_MERGE = "tag:yaml.org,2002:merge"


class _BoundError(yaml.YAMLError):
    """A document beyond a bound (not malformed YAML): the reason and where."""

    def __init__(self, reason: str, mark=None):
        super().__init__(reason)
        self.reason, self.mark = reason, mark


class _DescriptionLoader(yaml.SafeLoader):
    """PyYAML's safe loader, bounded (see the module text)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _BoundError(f"nested deeper than {MAX_DEPTH} levels (a description needs about 5)",
                                  self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_document(self, node):
        _check_expansion(node)
        return super().construct_document(node)

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            first = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE:
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    earlier = first.setdefault(key, key_node)
                except TypeError:           # an unhashable key: the base constructor refuses it
                    continue
                if earlier is not key_node:
                    mark = key_node.start_mark
                    before = earlier.start_mark
                    raise _BoundError(f"key {shown(key)} repeated at line {mark.line + 1}, column {mark.column + 1} "
                                      f"(first at line {before.line + 1}, column {before.column + 1}): a "
                                      f"description gives each key once", mark)
        return super().construct_mapping(node, deep)

    def construct_yaml_int(self, node):
        if len(node.value) > MAX_INTEGER_DIGITS:
            raise _BoundError(f"an integer of {len(node.value)} characters, more than {MAX_INTEGER_DIGITS}",
                              node.start_mark)
        return super().construct_yaml_int(node)


_DescriptionLoader.add_constructor("tag:yaml.org,2002:int", _DescriptionLoader.construct_yaml_int)


def _children(node) -> list:
    if isinstance(node, yaml.SequenceNode):
        return node.value
    if isinstance(node, yaml.MappingNode):
        return [child for pair in node.value for child in pair]
    return []


def _check_expansion(root) -> None:
    """Refuse a node graph that refers to itself or that stands for more than :data:`MAX_NODES`
    nodes with its aliases expanded (each shared node counted once per use), without recursion."""
    sizes, path, stack = {}, set(), [(root, False)]
    while stack:
        node, done = stack.pop()
        if done:
            path.discard(id(node))
            sizes[id(node)] = 1 + sum(sizes[id(child)] for child in _children(node))
            if sizes[id(node)] > MAX_NODES:
                raise _BoundError(f"more than {MAX_NODES} values once its aliases are expanded", node.start_mark)
            continue
        if id(node) in sizes:
            continue
        path.add(id(node))
        stack.append((node, True))
        for child in _children(node):
            if id(child) in path:
                raise _BoundError("an alias refers to a value that contains it (a recursive document)",
                                  child.start_mark)
            if id(child) not in sizes:
                stack.append((child, False))


def load_yaml_text(text: str, source: str):
    """Parse a description's text (see the module text)."""
    try:
        return yaml.load(text, Loader=_DescriptionLoader)
    except _BoundError as exc:
        where = f" at line {exc.mark.line + 1}, column {exc.mark.column + 1}" if exc.mark else ""
        reason = exc.reason if exc.reason.startswith("key ") else f"{exc.reason}{where}"
        raise RobotDescriptionError(source, "<yaml>", reason) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise RobotDescriptionError(source, "<yaml>", f"malformed YAML{where}: {problem}") from exc


def load_yaml(path: Path):
    """A description file's data: read at most :data:`MAX_YAML_BYTES`, as UTF-8 text without
    NUL bytes, parsed by :func:`load_yaml_text`."""
    source = str(path)
    data = read_bounded(path, MAX_YAML_BYTES, "a YAML description")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RobotDescriptionError(source, "<file>", f"not a text file (byte {exc.start}: {exc.reason}): a robot "
                                                      f"description is YAML or URDF text") from None
    if "\0" in text:
        raise RobotDescriptionError(source, "<file>", "contains NUL bytes: a binary file, not a YAML description")
    return load_yaml_text(text, source)
