"""Issue 42: a robot file from the internet is data, never code.

Hostile names (quote and comment terminators of every target, trigraphs, Markdown and HTML,
non-ASCII letters) in the robot's name, the description's file name, joint, link and frame
names go through every target: ``kindyngen generate``, the C (gcc and clang, strict C99, the
MEX gateway too), the CMake project, the python_c extension, the Python, JAX and CasADi modules,
the .casadi files, ``kindyngen eval`` in every language (Octave runs the .m function) and the
reports. An injection that worked would create the file SENTINEL in the working folder, stop a
compiler or CMake, or break a module; none does, and every language computes the same pose.
Names holding control characters are refused when read (one error line, exit 2); a model built
in memory with them (past the readers) is escaped all the same. Names of standard headers,
modules and keywords get identifiers that shadow nothing."""
from __future__ import annotations

import dataclasses
import html.parser
import importlib.util
import io
import json
import keyword
import shutil
import subprocess
import sys
from pathlib import Path
from xml.sax.saxutils import quoteattr

import markdown as markdown_lib
import numpy as np
import pytest
import yaml

from kindyngen.cli.main import main
from kindyngen.codegen.pipeline import build_programs, generate
from kindyngen.codegen.render import casadi_builders
from kindyngen.model.user_text import RESERVED, one_line
from kindyngen.readers.yaml_description import load_robot
from tests.harness import ROOT

SENTINEL = "PWNED"           # relative: every step runs in the shared folder of the generated robots
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
FUNCTIONS = "fk_hom,jacobian"   # frames text in both; an arm's also brings ik_dls (its own templates)

# one-line break-outs, accepted by the readers: a Python docstring ("""; code; """ keeps the
# rest of the module valid), a C comment (a failing static assertion), Markdown/HTML
PY = f'p"""; open("{SENTINEL}", "w"); """'
C = 'c*/ _Static_assert(0, "injected"); /*'
REST = "q'\\ ??/ ??= %} #} #[[ --> <script>alert(1)</script> | `x` *y* _z_ [l](u) ~~s~~ &amp; Ünïcødé 机器人"
# line breaks and controls, refused by the readers: models built in memory carry them
LINES = (f'm */\n#error injected\n/*\nmessage(FATAL_ERROR injected)\nfclose(fopen(\'{SENTINEL}\', \'w\'));\n'
         f'"""\nopen("{SENTINEL}", "w")\n"""\n')
CONTROLS = "n\x00 \r \x1b[2J \x85 \u2028 \u2029 \u202e \u2066 \ud800 \t end"

TWO_LINK = yaml.safe_load((ROOT / "examples" / "two_link.yaml").read_text())


def _tree(names):
    """A two-branch YAML tree whose joints (and so its frames of interest) are ``names``."""
    link = {"mass": 1, "com": [0, 0, 0.2], "inertia": [0.01, 0.01, 0.001, 0, 0, 0]}
    return {"name": "tree \"q\"", "dh": "none", "gravity": [0, 0, -9.81], "links": [link, link],
            "joints": [{"name": names[0], "origin": {"xyz": [0, 0.1, 0]}, "axis": [1, 0, 0], "lower": -1, "upper": 1},
                       {"name": names[1], "origin": {"xyz": [0, -0.1, 0]}, "axis": [0, 1, 0], "lower": -1, "upper": 1}]}


def _urdf(robot, base, tip):
    inertial = ('<inertial><mass value="1"/><origin xyz="0.5 0 0"/>'
                '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>')
    return (f'<robot name={quoteattr(robot)}><link name={quoteattr(base)}/>'
            f'<link name="upper">{inertial}</link><link name={quoteattr(tip)}>{inertial}</link>'
            f'<joint name={quoteattr(PY)} type="revolute"><parent link={quoteattr(base)}/><child link="upper"/>'
            f'<axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>'
            f'<joint name="elbow" type="revolute"><parent link="upper"/><child link={quoteattr(tip)}/>'
            f'<origin xyz="1 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>'
            f'</robot>')


def _generate(argv):
    code = main(["generate", *argv, "--out", "out", "--functions", FUNCTIONS, "--quiet"])
    assert code == 0
    assert not Path(SENTINEL).exists(), "generating ran text of the description"


def _arm(root):
    path = root / f"{PY}.yaml"          # the file's name breaks out of a docstring too (no "/" in a name)
    path.write_text(yaml.safe_dump({**TWO_LINK, "name": f"{PY} {C} {REST}"}), encoding="utf-8")
    _generate([str(path)])
    return load_robot(path)


def _tree_case(root):
    path = root / "tree.yaml"
    path.write_text(yaml.safe_dump(_tree([f"{PY} {REST}", C])), encoding="utf-8")
    _generate([str(path), "--tree"])
    return load_robot(path, tree=True)


def _urdf_case(root):
    path = root / "arm.urdf"
    path.write_text(_urdf(f"{C} {REST}", PY, f"{C} tip"), encoding="utf-8")
    _generate([str(path)])
    return load_robot(path)


def _in_memory(root, name):
    """The two-link arm renamed past the readers, generated through the pipeline."""
    model = dataclasses.replace(load_robot(ROOT / "examples" / "two_link.yaml"), name=name, source=name + ".yaml")
    generate(model, Path("out"), only=set(FUNCTIONS.split(",")), progress=False)
    assert not Path(SENTINEL).exists(), "generating ran text of the model"
    return model


CASES = {"arm": _arm, "tree": _tree_case, "urdf": _urdf_case,
         "lines": lambda root: _in_memory(root, LINES), "controls": lambda root: _in_memory(root, CONTROLS)}


@pytest.fixture(scope="module")
def robots(tmp_path_factory):
    """Every case generated into one folder (the working folder of every test here)."""
    root = tmp_path_factory.mktemp("hostile")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.setenv("KINDYNGEN_CACHE", str(root / "cache"))
        models = {case: make(root) for case, make in CASES.items()}
    return root, {case: (model, root / "out" / model.identifier) for case, model in models.items()}


@pytest.fixture
def case(request, robots, monkeypatch):
    root, generated = robots
    monkeypatch.chdir(root)
    monkeypatch.setenv("KINDYNGEN_CACHE", str(root / "cache"))
    yield generated[request.param]
    assert not (root / SENTINEL).exists(), "an injection ran"


each_case = pytest.mark.parametrize("case", list(CASES), indirect=True)


def _run(cmd, **kwargs):
    done = subprocess.run(cmd, capture_output=True, text=True, **kwargs)
    assert done.returncode == 0, f"{' '.join(map(str, cmd))}\n{done.stdout}\n{done.stderr}"
    return done


@each_case
def test_generated_folders_are_named_by_identifier(case):
    model, folder = case
    assert folder.name == model.identifier and folder.name.isascii() and folder.name not in RESERVED
    document = json.loads((folder / "functions.json").read_text())
    assert document["name"] == model.name and document["robot"] == model.identifier


@each_case
@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_c_and_mex_gateway_compile_strictly(case, compiler, tmp_path):
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} not installed")
    model, folder = case
    _run([compiler, *STRICT, "-c", str(folder / "c" / f"{model.identifier}.c"), "-o", str(tmp_path / "x.o")])
    mkoctfile = shutil.which("mkoctfile")
    if mkoctfile:        # mex.h: Octave's (system headers: their own warnings are not the gateway's)
        flags = [f"-isystem{flag[2:]}" for flag in _run([mkoctfile, "-p", "INCFLAGS"]).stdout.split()]
        _run([compiler, *STRICT, "-fsyntax-only", *flags, "-I", str(folder / "c"),
              str(folder / "matlab" / f"{model.identifier}_mex.c")])


@each_case
def test_cmake_configures_and_builds(case, tmp_path):
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    model, folder = case
    build = tmp_path / "build"
    _run(["cmake", "-S", str(folder / "c"), "-B", str(build), f"-DCMAKE_C_FLAGS={' '.join(STRICT[1:])}"])
    _run(["cmake", "--build", str(build)])


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(f"hostile_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _words(text: str) -> str:
    """``text`` with every run of whitespace one space (docstrings wrap long texts)."""
    return " ".join(text.split())


@each_case
def test_python_jax_and_casadi_modules_import_with_the_names_as_written(case):
    """The docstrings hold the robot's name, and fk_hom's its frames' (a tree) or links' (a
    URDF chain) names, unchanged: escaped as string literals, not mangled."""
    model, folder = case
    ident = model.identifier
    pytest.importorskip("jax")
    names = ([f.name for f in model.frames_of_interest] if model.is_tree
             else [model.base_name, model.flange_name] if model.base_name else [])
    for path in (folder / "python" / f"{ident}.py", folder / "jax" / f"{ident}_jax.py",
                 folder / "casadi" / f"{ident}_casadi.py"):
        module = _module(path)
        assert model.name in module.__doc__, path
        functions = getattr(module, "FUNCTIONS", None) or module.BUILDERS
        assert "fk_hom" in functions and "jacobian" in functions
        for name in names:
            assert _words(name) in _words(module.fk_hom.__doc__), (path, name)


@each_case
def test_python_c_extension_builds_and_documents_the_name(case):
    from kindyngen.runtime import python_c
    model, folder = case
    try:
        extension = python_c.load(folder)
    except python_c.BuildError as exc:
        if "no C compiler" in str(exc):
            pytest.skip(str(exc))
        raise
    # a C string: controls written visibly (a docstring ends at NUL); wrapped: whitespace may differ
    assert _words(one_line(model.name)) in _words(extension.__doc__)
    q = np.full(model.nq, 0.3)
    np.testing.assert_allclose(extension.fk_hom(q), _module(folder / "python" / f"{model.identifier}.py").fk_hom(q),
                               atol=1e-14)


def _eval(folder, lang, q, monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", io.StringIO(json.dumps({"q": q})))
    code = main(["eval", str(folder), "fk_hom", "--lang", lang])
    out, err = capsys.readouterr()
    assert code == 0, err
    return np.array(json.loads(out)["T"])


@each_case
def test_eval_in_every_language_gives_the_same_pose(case, monkeypatch, capsys):
    model, folder = case
    pytest.importorskip("jax")
    q = [0.3, -0.7]
    langs = ["python", "c", "casadi", "jax"] + (["matlab"] if shutil.which("octave-cli") else [])
    poses = {lang: _eval(folder, lang, q, monkeypatch, capsys) for lang in langs}
    for lang, pose in poses.items():
        np.testing.assert_allclose(pose, poses["python"], atol=1e-12, err_msg=lang)
    if "matlab" not in poses:
        pytest.skip("GNU Octave not installed: the .m function was not run")


class _Tags(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags, self.text = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)

    def handle_data(self, data):
        self.text.append(data)


@each_case
def test_opcounts_heading_renders_as_the_name_in_text(case):
    """opcounts.md rendered as MkDocs renders it: one heading, no other element, whose text is
    the name (its controls as visible escapes)."""
    model, folder = case
    heading = (folder / "opcounts.md").read_text(encoding="utf-8").splitlines()[0]
    parser = _Tags()
    parser.feed(markdown_lib.markdown(heading, extensions=["tables"]))
    assert parser.tags == ["h1"]
    assert "".join(parser.text) == f"Operation counts: {one_line(model.name)}"


@pytest.mark.parametrize("case", ["arm", "tree", "urdf"], indirect=True)
def test_the_casadi_code_run_when_generating_holds_no_user_text(case):
    model, _ = case
    source = casadi_builders(model, build_programs(model, only=set(FUNCTIONS.split(",")), progress=False))
    given = [f.name for f in model.frames] if model.is_tree else [model.base_name, model.flange_name]
    for text in [model.name, SENTINEL, "_Static_assert", "<script>"] + [name for name in given if name]:
        assert text not in source, text


# ------------------------------------------------------------------------ refused at reading

REFUSED = ["\n", "\r", "\x00", "\t", "\x1b", "\x7f", "\x85", "\u2028", "\u2029", "\u202e", "\u2066", "\u200f"]


def _refused(argv, capsys, *phrases):
    code = main(argv)
    _, err = capsys.readouterr()
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), err
    assert err.isprintable() or err[:-1].isprintable(), repr(err)      # no control character printed
    for phrase in phrases:
        assert phrase in lines[0], lines[0]


@pytest.mark.parametrize("char", REFUSED)
def test_a_robot_name_with_a_control_character_is_refused(char, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "r.yaml"
    path.write_text(yaml.safe_dump({**TWO_LINK, "name": f"x{char}import os"}), encoding="utf-8")
    _refused(["generate", str(path), "--out", "out"], capsys, "r.yaml: field 'name'", f"U+{ord(char):04X}",
             "position 2")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("where", ["joint", "tree joint", "urdf robot", "urdf link", "urdf joint"])
@pytest.mark.parametrize("char", ["\n", "\u202e"])
def test_joint_link_and_urdf_names_with_control_characters_are_refused(where, char, tmp_path, capsys):
    bad = f"a{char}b"
    if where.startswith("urdf"):
        text = _urdf(*{"urdf robot": (bad, "base", "tip"), "urdf link": ("r", bad, "tip"),
                       "urdf joint": ("r", "base", "tip")}[where])
        if where == "urdf joint":
            text = text.replace(quoteattr(PY), quoteattr(bad))
        path = tmp_path / "r.urdf"
        path.write_text(text.replace(char, f"&#{ord(char)};"), encoding="utf-8")   # XML: as a reference
        field = {"urdf robot": "<robot> name", "urdf link": "link[0] name", "urdf joint": "joint[0] name"}[where]
        argv = [str(path)]
    else:
        data = _tree(["a", "b"]) if where == "tree joint" else {**TWO_LINK, "joints": [dict(j) for j in TWO_LINK["joints"]]}
        data["joints"][1]["name"] = bad
        path = tmp_path / "r.yaml"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        field, argv = "joints[1].name", [str(path)] + (["--tree"] if where == "tree joint" else [])
    _refused(["generate", *argv, "--out", str(tmp_path / "out")], capsys, f"field '{field}'", f"U+{ord(char):04X}")


# ------------------------------------------------------------------------ identifiers

def test_identifiers_of_the_shipped_robots_are_unchanged():
    assert [load_robot(p).identifier for p in sorted((ROOT / "robots").glob("*.yaml"))] == ["lwr4", "lwr4_hartl",
                                                                                           "panda"]
    assert load_robot(ROOT / "examples" / "two_link.yaml").identifier == "two_link"


NAMES = ["math", "struct", "os", "string", "sys", "time", "signal", "test", "numpy", "Python", "mex", "stdio",
         "class", "int", "end", "function", "def", "import", "true", "con", "kdg", "", "___", "7dof", "机器人",
         'x"""', "x*/ int evil; /*", "a" * 100, "é" * 40, "Lwr4 -- Hartl!", "_private_", "?" * 5,
         "Stretch", "tool arm", "isaac", "memory", "wcsx", "to", "is 2"]


C_HEADERS = {"assert", "complex", "ctype", "errno", "fenv", "float", "inttypes", "iso646", "limits", "locale", "math",
             "setjmp", "signal", "stdalign", "stdarg", "stdatomic", "stdbool", "stddef", "stdint", "stdio", "stdlib",
             "stdnoreturn", "string", "tgmath", "threads", "time", "uchar", "wchar", "wctype"}
C_KEYWORDS = {"auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else", "enum", "extern",
              "float", "for", "goto", "if", "inline", "int", "long", "register", "restrict", "return", "short", "signed",
              "sizeof", "static", "struct", "switch", "typedef", "union", "unsigned", "void", "volatile", "while",
              "bool", "true", "false", "class", "new", "delete", "template", "this", "namespace"}


@pytest.mark.parametrize("name", NAMES)
def test_identifiers_are_ascii_bounded_and_shadow_nothing(name):
    """Checked against Python's own lists and the C standard's headers and keywords, not the
    rule's table."""
    model = dataclasses.replace(load_robot(ROOT / "examples" / "two_link.yaml"), name=name)
    ident = model.identifier
    assert ident.isascii() and ident.isidentifier() and 0 < len(ident) <= 32
    assert ident[0].isalpha() and ident == ident.lower() and "__" not in ident and not ident.endswith("_")
    assert not keyword.iskeyword(ident) and not keyword.issoftkeyword(ident)
    assert ident not in {m.lower() for m in sys.stdlib_module_names} | C_HEADERS | C_KEYWORDS
    assert ident not in {"numpy", "casadi", "jax", "python", "mex", "end", "function", "con", "kdg"}
    # C99 7.26.2 / 7.26.11: is, to, str, mem, wcs and a lowercase letter begin names the C library
    # may take for external linkage, such as the symbol <identifier>_fk_hom
    assert not any(ident.startswith(p) and ident[len(p)].islower() for p in ("is", "to", "str", "mem", "wcs")
                   if len(ident) > len(p))


def test_reserved_words_cover_this_pythons_standard_library_and_keywords():
    public = {m.lower() for m in sys.stdlib_module_names if not m.startswith("_")}
    assert public <= RESERVED, sorted(public - RESERVED)
    assert {w.lower() for w in keyword.kwlist} <= RESERVED


@pytest.mark.parametrize("name", ["math", "string", "struct"])
def test_robots_named_like_the_standard_library_shadow_nothing(name, tmp_path, monkeypatch):
    """math.h beside the C, found first through the CMake target's include folder, would shadow
    <math.h>; string.py or struct.py on the path would shadow the standard modules."""
    monkeypatch.chdir(tmp_path)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({**TWO_LINK, "name": name}))
    assert main(["generate", str(path), "--out", "out", "--functions", "fk_hom", "--lang", "c,python", "--quiet"]) == 0
    ident = load_robot(path).identifier
    folder = tmp_path / "out" / ident
    if shutil.which("cmake"):
        _run(["cmake", "-S", str(folder / "c"), "-B", str(tmp_path / "build"), f"-DCMAKE_C_FLAGS={' '.join(STRICT[1:])}"])
        _run(["cmake", "--build", str(tmp_path / "build")])
    _run([sys.executable, "-c", f"import sys; sys.path.insert(0, '.'); import numpy, math, string, struct; "
                                f"string.ascii_letters, struct.pack, math.sqrt; import {ident}"],
         cwd=folder / "python")
