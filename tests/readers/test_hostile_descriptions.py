"""A robot description from the internet is data, never code (issue 42): whatever a YAML or URDF
file holds, `generate`, `count` and `describe` end in bounded time with one ``error:`` line and
exit code 2 (or read it, with a ``note:`` where a value may be meant), never a traceback, a run
without end or a silently wrong model. The rules are those of docs/reference/description.md,
"Limits and refused inputs"."""
from __future__ import annotations

import pytest

from kindyngen.cli.main import main
from kindyngen.readers.constant_expressions import MAX_CHARACTERS, MAX_NESTING
from kindyngen.readers.input_bounds import MAX_URDF_BYTES, MAX_YAML_BYTES
from kindyngen.readers.yaml_loading import MAX_DEPTH, MAX_NODES

# two joints by modified DH (so that `describe` takes it too); each test edits the text
ARM = """name: planar2
dh: modified
gravity: [0, -9.81, 0]
joints:
  - {name: j1, a: 0, alpha: 0, d: 0, offset: 0, lower: -pi, upper: pi}
  - {name: j2, a: 0.5, alpha: 0, d: 0, lower: -2.5, upper: 2.5}
links:
  - {mass: 1.2, com: [0.25, 0, 0], inertia: [0.0004, 0.025, 0.025, 0, 0, 0]}
  - {mass: 0.8, com: [0.2, 0, 0], inertia: [0.0002, 0.0107, 0.0107, 0, 0, 0]}
"""

# the same by origin and axis, as a URDF
URDF = """<?xml version="1.0"?>
<robot name="planar2">
  <link name="base"/>
  <link name="l1"><inertial><mass value="1.2"/><origin xyz="0.25 0 0" rpy="0 0 0"/>
    <inertia ixx="0.0004" ixy="0" ixz="0" iyy="0.025" iyz="0" izz="0.025"/></inertial></link>
  <link name="l2"><inertial><mass value="0.8"/><origin xyz="0.2 0 0"/>
    <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0107" iyz="0" izz="0.0107"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.5 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
</robot>
"""


def _edit(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def _run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _argv(command: str, path, tmp_path) -> list:
    return {"generate": ["generate", str(path), "--functions", "fk_hom", "--out", str(tmp_path / "out")],
            "count": ["count", str(path), "--only", "fk_hom"],
            "describe": ["describe", str(path)]}[command]


def _refused(path, capsys, tmp_path, *phrases, command="describe", options=()):
    """One ``error:`` line naming the file and every phrase, exit code 2, nothing written."""
    code, out, err = _run(_argv(command, path, tmp_path) + list(options), capsys)
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert code == 2, err[-2000:]
    assert len(lines) == 1 and "Traceback" not in err, err[-2000:]
    assert lines[0].startswith(f"error: {path}: field "), lines[0]
    for phrase in phrases:
        assert phrase in lines[0], lines[0]
    assert len(lines[0]) < 400, lines[0]
    assert not (tmp_path / "out").exists()
    return lines[0]


def _write(tmp_path, text: str | bytes, name: str = "robot.yaml"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def _laughs(levels: int) -> str:
    """A YAML list whose aliases stand for 10**levels numbers in a few hundred bytes."""
    anchors = ["&l0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    anchors += [f"&l{k} [" + ", ".join([f"*l{k - 1}"] * 10) + "]" for k in range(1, levels + 1)]
    return "[" + ", ".join(anchors) + "]"


# ------------------------------------------------------------- YAML: unbounded work refused

@pytest.mark.parametrize("command", ["generate", "count", "describe"])
def test_tower_of_powers_is_refused_before_it_is_evaluated(tmp_path, capsys, command):
    path = _write(tmp_path, _edit(ARM, "alpha: 0, d: 0, offset: 0", "alpha: '9**9**9**9', d: 0, offset: 0"))
    _refused(path, capsys, tmp_path, "'joints[0].alpha'", "9**9**9**9", "not finite", command=command)


@pytest.mark.parametrize("expression, phrases", [
    # a finite value whose exact rational would have millions of digits
    ("1.0000001**10**5", ("exponent 100000 is beyond +-100",)),
    ("(1.0001**10)**20", ("exponent 200 is beyond +-100", "nested powers multiply")),
    ("(1e-300)**100", ("below 1e-300",)),
    ("1e308", ("beyond 1e+300",)),
    ("+".join(["1"] * 20000), (f"more than the {MAX_CHARACTERS} an expression may have",)),
    ("(" * (MAX_NESTING + 1) + "1" + ")" * (MAX_NESTING + 1), (f"brackets nested {MAX_NESTING + 1} deep",)),
    ("-" * 40 + "1", ("nested 42 operations deep",)),
    ("1/(2-2)", ("divides by zero",)),
], ids=["exponent", "nested-exponents", "underflow", "huge", "long", "brackets", "unary-chain", "zero-division"])
def test_expressions_are_bounded(tmp_path, capsys, expression, phrases):
    path = _write(tmp_path, _edit(ARM, "a: 0.5", f"a: '{expression}'"))
    _refused(path, capsys, tmp_path, "'joints[1].a'", *phrases)


def test_deep_nesting_is_refused_before_the_parser_recurses(tmp_path, capsys):
    path = _write(tmp_path, _edit(ARM, "a: 0.5", "a: " + "[" * 100_000 + "]" * 100_000))
    _refused(path, capsys, tmp_path, "'<yaml>'", f"nested deeper than {MAX_DEPTH} levels", "line 6")


def test_billion_laughs_is_refused(tmp_path, capsys):
    """Nine levels of ten aliases: a billion numbers in 0.7 kB (a repr of it never ends)."""
    path = _write(tmp_path, _edit(ARM, "com: [0.2, 0, 0]", f"com: [0.2, 0, {_laughs(8)}]"))
    _refused(path, capsys, tmp_path, "'<yaml>'", f"more than {MAX_NODES} values once its aliases are expanded")


def test_recursive_alias_is_refused(tmp_path, capsys):
    path = _write(tmp_path, _edit(ARM, "a: 0.5", "a: &r [*r]"))
    _refused(path, capsys, tmp_path, "'<yaml>'", "recursive", "line 6")


def test_aliases_that_expand_little_are_read(tmp_path, capsys):
    text = _edit(ARM, "com: [0.25, 0, 0], inertia: [0.0004", "com: &c [0.25, 0, 0], inertia: [0.0004")
    path = _write(tmp_path, _edit(text, "com: [0.2, 0, 0]", "com: *c"))
    code, out, err = _run(["describe", str(path)], capsys)
    assert code == 0, err
    assert out.count("com: [0.25, 0.0, 0.0]") == 2


def test_integer_of_thousands_of_digits_is_refused(tmp_path, capsys):
    path = _write(tmp_path, _edit(ARM, "a: 0.5", "a: " + "9" * 5000))
    _refused(path, capsys, tmp_path, "'<yaml>'", "an integer of 5000 characters", "line 6")


def test_file_above_the_size_limit_is_refused(tmp_path, capsys):
    """A description padded with comments to the limit is read; one byte more is refused."""
    padding = MAX_YAML_BYTES - len(ARM.encode())
    lines, rest = divmod(padding, 80)
    text = ARM + ("#" * 79 + "\n") * lines + "#" * (rest - 1) + "\n"
    assert len(text.encode()) == MAX_YAML_BYTES
    code, _, err = _run(["describe", str(_write(tmp_path, text))], capsys)
    assert code == 0, err
    _refused(_write(tmp_path, text + "\n"), capsys, tmp_path, "'<file>'", f"larger than {MAX_YAML_BYTES} bytes")


@pytest.mark.parametrize("name", ["robot.yaml", "robot.urdf"])
def test_hundred_megabytes_are_not_read(tmp_path, capsys, name):
    """A sparse 100 MB file (no disk written): refused after reading the limit plus one byte."""
    path = tmp_path / name
    with open(path, "wb") as stream:
        stream.truncate(100 << 20)
    limit = MAX_URDF_BYTES if name.endswith(".urdf") else MAX_YAML_BYTES
    _refused(path, capsys, tmp_path, "'<file>'", f"larger than {limit} bytes")


# ------------------------------------------------------------- YAML: implausible numbers
# (YAML 1.1 reads 1.0e+9 as a float and 1.0e9 as a string: here the numbers are floats, the
# expressions are above)

@pytest.mark.parametrize("old, new, field, phrases", [
    ("a: 0.5", "a: 1.0e+308", "joints[1].a", ("beyond +-1e+100",)),
    ("a: 0.5", "a: 2500.0", "joints[1].a", ("plausible range of a length", "millimetres?")),
    ("com: [0.2, 0, 0]", "com: [1.0e+200, 0, 0]", "links[1].com[0]", ("beyond +-1e+100",)),
    ("com: [0.2, 0, 0]", "com: [0.2, 0, 5.0e+3]", "links[1].com[2]", ("plausible range of a length",)),
    ("mass: 0.8", "mass: 1.0e+9", "links[1].mass", ("plausible range of a mass", "1e+06 kg")),
    ("mass: 0.8", "mass: 1.0e-120", "links[1].mass", ("below 1e-100",)),
    ("0.0107, 0.0107, 0", "1.0e+13, 1.0e+13, 0", "links[1].inertia[1]", ("plausible range of an inertia",)),
    ("gravity: [0, -9.81, 0]", "gravity: [0, -9.81e+4, 0]", "gravity[1]", ("plausible range of gravity",)),
    ("lower: -2.5, upper: 2.5", "lower: -2.5, upper: 2.5, friction: {viscous: 1.0e+20}",
     "joints[1].friction.viscous", ("plausible range of a coefficient",)),
], ids=["length-huge", "length-mm", "com-huge", "com", "mass", "mass-tiny", "inertia", "gravity", "friction"])
def test_implausible_numbers_are_refused_with_the_field(tmp_path, capsys, old, new, field, phrases):
    _refused(_write(tmp_path, _edit(ARM, old, new)), capsys, tmp_path, f"'{field}'", *phrases, command="count")


def test_prismatic_limits_are_lengths(tmp_path, capsys):
    text = _edit(ARM, "{name: j2, a: 0.5, alpha: 0, d: 0, lower: -2.5, upper: 2.5}",
                 "{name: j2, type: prismatic, a: 0.5, alpha: 0, d: 0, lower: 0, upper: 1500}")
    _refused(_write(tmp_path, text), capsys, tmp_path, "'joints[1].upper'", "plausible range of a length")


# ------------------------------------------------------------- YAML: degrees

@pytest.mark.parametrize("old, new, field, hint", [
    ("a: 0.5, alpha: 0", "a: 0.5, alpha: 90", "joints[1].alpha", "for 90 degrees write pi/2 (1.5708)"),
    ("offset: 0", "offset: 90", "joints[0].offset", "for 90 degrees write pi/2 (1.5708)"),
    ("offset: 0", "offset: -45.5", "joints[0].offset", "for -45.5 degrees write -91*pi/360"),
], ids=["alpha", "offset", "offset-decimal"])
def test_angles_beyond_a_turn_are_refused_as_degrees(tmp_path, capsys, old, new, field, hint):
    _refused(_write(tmp_path, _edit(ARM, old, new)), capsys, tmp_path, f"'{field}'", "beyond a full turn",
             "looks like degrees", hint)


def test_origin_rpy_and_tool_beyond_a_turn_are_refused(tmp_path, capsys):
    frames = _edit(_edit(ARM, "dh: modified", "dh: none"), "{name: j1, a: 0, alpha: 0, d: 0, offset: 0,",
                   "{name: j1, origin: {rpy: [0, 180, 0]},")
    frames = _edit(frames, "{name: j2, a: 0.5, alpha: 0, d: 0,", "{name: j2, origin: {xyz: [0.5, 0, 0]},")
    _refused(_write(tmp_path, frames), capsys, tmp_path, "'joints[0].origin.rpy[1]'", "for 180 degrees write pi")
    tool = _edit(ARM, "links:", "tool: {xyz: [0, 0, 0.1], rpy: [0, 0, 1e3]}\nlinks:")
    _refused(_write(tmp_path, tool), capsys, tmp_path, "'tool.rpy[2]'", "beyond a full turn")


def test_revolute_limits_in_degrees_are_refused_and_multi_turn_ranges_written_as_expressions(tmp_path, capsys):
    text = _edit(ARM, "lower: -2.5, upper: 2.5", "lower: -170, upper: 170")
    _refused(_write(tmp_path, text), capsys, tmp_path, "'joints[1].lower'", "beyond a full turn",
             "for -170 degrees write -17*pi/18 (-2.96706)", "written as an expression")
    multi_turn = _edit(ARM, "lower: -2.5, upper: 2.5", "lower: -4*pi, upper: '12.5'")
    code, out, err = _run(["describe", str(_write(tmp_path, multi_turn))], capsys)
    assert code == 0 and "note:" not in err, err
    assert "upper: '12.5'" in out          # written back in the form that reads again
    # a full turn written with few decimals is still a full turn
    code, _, err = _run(["describe", str(_write(tmp_path, _edit(ARM, "upper: 2.5", "upper: 6.2832")))], capsys)
    assert code == 0, err


# ------------------------------------------------------------- YAML: duplicates

def test_repeated_key_is_refused_naming_both_lines(tmp_path, capsys):
    path = _write(tmp_path, _edit(ARM, "a: 0.5, alpha: 0, d: 0,", "a: 0.5, alpha: 0, d: 0, d: 0.3,"))
    _refused(path, capsys, tmp_path, "'<yaml>'", "key 'd' repeated at line 6, column 40 (first at line 6, column 34)")
    top = _write(tmp_path, ARM + "name: other\n")
    _refused(top, capsys, tmp_path, "key 'name' repeated at line 10", "(first at line 1, column 1)")


def test_merge_keys_may_be_overridden(tmp_path, capsys):
    """``<<: *x`` then an explicit key is YAML's override, not a repetition."""
    text = _edit(ARM, "- {mass: 0.8, com: [0.2, 0, 0], inertia: [0.0002, 0.0107, 0.0107, 0, 0, 0]}",
                 "- {<<: {mass: 2.0, com: [0.2, 0, 0]}, mass: 0.8, inertia: [0.0002, 0.0107, 0.0107, 0, 0, 0]}")
    code, out, err = _run(["describe", str(_write(tmp_path, text))], capsys)
    assert code == 0, err
    assert "mass: 0.8" in out and "mass: 2.0" not in out


@pytest.mark.parametrize("tree", [False, True], ids=["arm", "tree"])
def test_repeated_joint_name_is_refused_naming_both(tmp_path, capsys, tree):
    text = _edit(ARM, "{name: j2,", "{name: j1,")
    if tree:
        text = _edit(_edit(text, "dh: modified", "dh: none"), "a: 0, alpha: 0, d: 0, offset: 0, ", "")
        text = _edit(text, "a: 0.5, alpha: 0, d: 0, ", "")
    _refused(_write(tmp_path, text), capsys, tmp_path, "'joints[1].name'", "'j1' is also the name of joints[0]",
             command="count", options=["--tree"] if tree else [])


# ------------------------------------------------------------- URDF

def test_urdf_with_a_document_type_is_refused_before_its_entities_expand(tmp_path, capsys):
    entities = "".join(f'<!ENTITY e{k} "' + f"&e{k - 1};" * 10 + '">' for k in range(1, 10))
    text = _edit(URDF, '<robot name="planar2">', f'<!DOCTYPE robot [<!ENTITY e0 "lol">{entities}]>\n'
                                                  f'<robot name="&e9;">')
    _refused(_write(tmp_path, text, "robot.urdf"), capsys, tmp_path, "'<!DOCTYPE>'", "(DTD) is refused")
    external = _edit(URDF, '<robot name="planar2">', '<!DOCTYPE robot [<!ENTITY x SYSTEM "file:///etc/hostname">]>\n'
                                                      '<robot name="planar2&x;">')
    _refused(_write(tmp_path, external, "external.urdf"), capsys, tmp_path, "'<!DOCTYPE>'")


@pytest.mark.parametrize("old, new, field, phrases", [
    ('<origin xyz="0.5 0 0" rpy="0 0 0"/>', '<origin xyz="0.5 0 0" rpy="0 0 90"/>', "joint 'j2' origin rpy[2]",
     ("beyond a full turn", "for 90 degrees write pi/2")),
    ('<origin xyz="0.25 0 0" rpy="0 0 0"/>', '<origin xyz="0.25 0 0" rpy="-360 0 0"/>',
     "link 'l1' inertial origin rpy[0]", ("for -360 degrees write -2*pi",)),
    ('<origin xyz="0.5 0 0" rpy', '<origin xyz="500e3 0 0" rpy', "joint 'j2' origin xyz[0]",
     ("plausible range of a length",)),
    ('<mass value="0.8"/>', '<mass value="1e200"/>', "link 'l2' inertial mass value", ("beyond +-1e+100",)),
    ('<mass value="0.8"/>', '<mass value="2e7"/>', "link 'l2' inertial mass value", ("plausible range of a mass",)),
    ('iyy="0.0107"', 'iyy="3e13"', "link 'l2' inertial inertia iyy", ("plausible range of an inertia",)),
], ids=["rpy-degrees", "inertial-rpy", "xyz", "mass-huge", "mass", "inertia"])
def test_urdf_implausible_numbers_are_refused(tmp_path, capsys, old, new, field, phrases):
    _refused(_write(tmp_path, _edit(URDF, old, new), "robot.urdf"), capsys, tmp_path, f"'{field}'", *phrases,
             command="count")


def test_urdf_prismatic_limits_are_lengths(tmp_path, capsys):
    text = _edit(URDF, '<joint name="j2" type="revolute">', '<joint name="j2" type="prismatic">')
    text = _edit(text, 'lower="-2.5" upper="2.5"', 'lower="0" upper="2000"')
    _refused(_write(tmp_path, text, "robot.urdf"), capsys, tmp_path, "'joint 'j2' limit upper'",
             "plausible range of a length")


def test_urdf_limits_that_may_be_degrees_are_read_with_a_note(tmp_path, capsys):
    """URDF states radians and real files hold multi-turn ranges (Solo's -10..10): read as
    written, with one note; a placeholder far beyond degrees (a rotor's 1e16) without one."""
    text = _edit(URDF, 'lower="-2.5" upper="2.5"', 'lower="-170" upper="170"')
    code, out, err = _run(["describe", str(_write(tmp_path, text, "robot.urdf"))], capsys)
    notes = [line for line in err.splitlines() if line.startswith("note:")]
    assert code == 0, err
    assert len(notes) == 1 and "'j2' -170..170" in notes[0] and "if degrees were meant" in notes[0], err
    assert "lower: '-170.0'" in out and "upper: '170.0'" in out      # the YAML written reads again
    unlimited = _edit(URDF, 'lower="-2.5" upper="2.5"', 'lower="-1e16" upper="1e16"')
    code, _, err = _run(["describe", str(_write(tmp_path, unlimited, "unlimited.urdf"))], capsys)
    assert code == 0 and "note:" not in err, err


@pytest.mark.parametrize("element, phrase", [
    ('<link name="l2">', "link 'l1'"), ('<joint name="j2" type="revolute">', "joint 'j1'")], ids=["link", "joint"])
def test_urdf_duplicate_names_name_both_elements(tmp_path, capsys, element, phrase):
    text = _edit(URDF, element, element.replace("2", "1"))
    line = _refused(_write(tmp_path, text, "robot.urdf"), capsys, tmp_path, f"'{phrase}'", "defined twice")
    assert ("number 2 and number 3" if "link" in element else "number 1 and number 2") in line


def test_urdf_above_the_size_limit_is_refused(tmp_path, capsys):
    padding = MAX_URDF_BYTES - len(URDF.encode()) - len("<!---->\n")
    text = URDF + "<!--" + "x" * padding + "-->\n"
    assert len(text.encode()) == MAX_URDF_BYTES
    code, _, err = _run(["describe", str(_write(tmp_path, text, "robot.urdf"))], capsys)
    assert code == 0, err
    _refused(_write(tmp_path, text + " ", "robot.urdf"), capsys, tmp_path, "'<file>'",
             f"larger than {MAX_URDF_BYTES} bytes")
