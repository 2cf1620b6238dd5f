"""Text from the user's files: what a name may hold, the identifier derived from it, and one
escaper per output language, so that a robot file from the internet stays data, never code.

Every string a user writes (the robot's name, joint, link and frame names, the file name of
the description, log file and column names) may reach generated code, comments, build files
and reports. Three rules keep it data:

- Reading refuses a name holding a control character (:func:`name_problem`: C0 and C1
  controls such as NUL, newline and escape, Unicode line and paragraph separators, lone
  surrogates, and the bidirectional controls of "Trojan Source"). Quotes, backslashes,
  comment terminators, non-ASCII letters and keywords are accepted.
- Wherever such text is written it passes through the escaper of that place: a C comment
  (:func:`c_comment`), a C string literal (:func:`c_string`), a Python string literal or
  docstring (:func:`python_string`), a MATLAB/Octave comment (:func:`matlab_comment`), an
  Octave double-quoted string (:func:`octave_string`), a CMake comment (:func:`cmake_comment`),
  Markdown (:func:`markdown`); JSON is written by ``json.dumps``. The code generator applies them
  where it renders (:mod:`kindyngen.codegen.environment`), not where algorithms compose texts.
  The escapers also neutralise what reading refuses (defence in depth: a model can be built in
  memory).
- File and symbol names use :func:`identifier`, never the name itself.

This module imports nothing from the package, so every stage (readers, codegen, measured
reports, the command line) may use it.
"""
from __future__ import annotations

import keyword
import re
import unicodedata

# the bidirectional formatting characters that reorder how source text is displayed
# ("Trojan Source", CVE-2021-42574): ALM, LRM, RLM, LRE..RLO, LRI..PDI
_BIDI = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def _unsafe(ch: str) -> bool:
    """A character no name may hold: a control (Cc: C0, DEL, C1), a line or paragraph
    separator, a surrogate, a bidirectional control."""
    return unicodedata.category(ch) in ("Cc", "Zl", "Zp", "Cs") or ch in _BIDI


def name_problem(text: str) -> str | None:
    """Why ``text`` cannot be a name, or None when it can (the reason names the character).

    >>> name_problem("arm \\"7\\" */ ü") is None
    True
    >>> name_problem("a\\nb")
    'holds the control character U+000A (LINE FEED) at position 2: a name is one line of printable text'
    >>> name_problem("x\\u202ey")
    'holds the control character U+202E (RIGHT-TO-LEFT OVERRIDE) at position 2: a name is one line of printable text'
    """
    for k, ch in enumerate(text):
        if _unsafe(ch):
            what = unicodedata.name(ch, "") or _CONTROL_NAMES.get(ord(ch), "a control character")
            return (f"holds the control character U+{ord(ch):04X} ({what}) at position {k + 1}: "
                    "a name is one line of printable text")
    return None


# unicodedata has no names for the C0 and C1 controls
_CONTROL_NAMES = {0: "NULL", 7: "BELL", 8: "BACKSPACE", 9: "CHARACTER TABULATION", 10: "LINE FEED",
                  11: "LINE TABULATION", 12: "FORM FEED", 13: "CARRIAGE RETURN", 27: "ESCAPE", 127: "DELETE",
                  0x85: "NEXT LINE"}


def _visible(ch: str) -> str:
    """A character as Python would escape it: ``\\x0a``, ``\\u202e``, ``\\U0001f600``."""
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


def one_line(text: str) -> str:
    """``text`` with every character :func:`name_problem` refuses written as its escape, so it
    stays one line of harmless text (terminal output, line comments).

    >>> print(one_line("a\\nb\\x1b[2J\\u2028c"))
    a\\x0ab\\x1b[2J\\u2028c
    """
    return "".join(_visible(ch) if _unsafe(ch) else ch for ch in text)


def c_comment(text: str) -> str:
    """``text`` for the inside of a C block comment: ``*/`` and ``/*`` (which -Wcomment flags)
    split by a space, trigraphs ``??x`` (replaced even in comments in strict C99) broken up,
    controls escaped (a backslash-newline never forms).

    >>> print(c_comment("x*/ int evil; /* ??/"))
    x* / int evil; / * ? ?/
    """
    return re.sub(r"\*(?=/)|/(?=\*)|\?(?=\?)", lambda m: m.group() + " ", one_line(text))


def c_string(text: str) -> str:
    r"""``text`` for the inside of a C string literal ``"..."``, the same text once compiled
    except controls, which are written as visible escapes (a docstring is a NUL-terminated C
    string): backslash and quote escaped, ``?`` before ``?`` escaped (no trigraph); other
    non-ASCII text stays UTF-8.

    >>> print(c_string('say "hi"\\ ??/ \x00 \u202e ü'))
    say \"hi\"\\ ?\?/ \\x00 \\u202e ü
    """
    text = one_line(text)
    return "".join("\\" + ch if ch in '\\"' else "?\\" if ch == "?" and text[k + 1:k + 2] == "?" else ch
                   for k, ch in enumerate(text))


def python_string(text: str) -> str:
    """``text`` for the inside of a Python ``"..."`` or ``\"\"\"...\"\"\"`` literal (not raw), the
    same string once evaluated: backslash and double quote escaped, controls as escapes.

    >>> print(python_string('x\"\"\"\\nimport os\\\\'))
    x\\"\\"\\"\\x0aimport os\\\\
    >>> eval('\"\"\"' + python_string('a\"\"\"\\x00\\\\') + '\"\"\"') == 'a\"\"\"\\x00\\\\'
    True
    """
    return "".join("\\" + ch if ch in '\\"' else _visible(ch) if _unsafe(ch) else ch for ch in text)


def matlab_comment(text: str) -> str:
    """``text`` for a MATLAB/Octave ``%`` line comment: controls escaped (a newline would end
    the comment), block-comment markers ``%{ %} #{ #}`` split.

    >>> print(matlab_comment("x\\nsystem('touch y'); %}"))
    x\\x0asystem('touch y'); % }
    """
    return re.sub(r"([%#])([{}])", r"\1 \2", one_line(text))


def octave_string(text: str) -> str:
    """``text`` for the inside of an Octave double-quoted string ``"..."`` (Octave, not MATLAB,
    reads escapes there): backslash and double quote escaped, controls as three-digit octal
    escapes of their UTF-8 bytes (Octave's hexadecimal escapes take any number of digits).

    >>> print(octave_string('/tmp/it\\'s "x"\\n1'))
    /tmp/it's \\"x\\"\\0121
    """
    return "".join("\\" + ch if ch in '\\"' else
                   "".join(f"\\{b:03o}" for b in ch.encode("utf-8", "surrogatepass")) if _unsafe(ch) else ch
                   for ch in text)


def cmake_comment(text: str) -> str:
    """``text`` for a CMake ``#`` line comment placed after other text (where ``#[[`` opens no
    bracket comment): only a line break could end it, so controls are escaped.

    >>> print(cmake_comment('x"\\nmessage(FATAL_ERROR X)'))
    x"\\x0amessage(FATAL_ERROR X)
    """
    return one_line(text)


# Markdown: characters that start inline markup (emphasis, code, links, HTML, entities, table
# cells, heading closers, GitHub strikethrough), escaped as both CommonMark and Python-Markdown
# (MkDocs) read them; "_" only where it can open or close emphasis (not inside a word, so
# lwr4_hartl stays as written); ">" only where it would begin a quote (after "<", escaped, it
# closes no tag)
_MARKDOWN = {"\\": "\\\\", "`": "\\`", "*": "\\*", "[": "\\[", "]": "\\]", "#": "\\#", "|": "\\|",
             "<": "&lt;", "&": "&amp;", "~": "&#126;"}


def markdown(text: str) -> str:
    """``text`` as literal inline Markdown (a heading, a table cell, a list item, a paragraph):
    no markup, no HTML, one line; a leading list or block marker escaped too.

    >>> print(markdown("lwr4_hartl <script> *x* | _y_ [l](u) 1 -> 2"))
    lwr4_hartl &lt;script> \\*x\\* \\| \\_y\\_ \\[l\\](u) 1 -> 2
    >>> print(markdown("- 1. item"), markdown("2) x"), markdown("> quote"))
    \\- 1. item 2\\) x \\> quote
    """
    out = []
    for k, ch in enumerate(text):
        if ch == "_":
            inside = 0 < k < len(text) - 1 and text[k - 1].isalnum() and text[k + 1].isalnum()
            out.append("_" if inside else "\\_")
        elif ch in _MARKDOWN:
            out.append(_MARKDOWN[ch])
        else:
            out.append(_visible(ch) if _unsafe(ch) else ch)
    escaped = "".join(out)
    if re.match(r"[-+>]|\d+[.)]", escaped):    # would begin a list item or a quote
        match = re.match(r"\d*", escaped)
        escaped = escaped[:match.end()] + "\\" + escaped[match.end():]
    return escaped


# ------------------------------------------------------------------------------ identifiers

MAX_IDENTIFIER = 32
"""Longest identifier: ``<identifier>_fd_derivatives_no_minv`` stays within MATLAB's 63
characters of a function name."""

_C_KEYWORDS = """auto break case char const continue default do double else enum extern float for goto if
inline int long register restrict return short signed sizeof static struct switch typedef union unsigned void
volatile while alignas alignof bool constexpr false nullptr static_assert thread_local true typeof typeof_unqual
complex imaginary noreturn asm fortran and and_eq bitand bitor catch char8_t char16_t char32_t class co_await
co_return co_yield compl concept const_cast consteval constinit decltype delete dynamic_cast explicit export
friend mutable namespace new noexcept not not_eq operator or or_eq private protected public reinterpret_cast
requires static_cast template this throw try typeid typename using virtual wchar_t xor xor_eq
assert errno offsetof setjmp va_arg va_list""".split()

# headers found before the system's when a build adds the generated folder with -I (the CMake
# target does): the C standard's (C89-C23), POSIX's and those glibc, Windows, Python and the
# MEX API include
_HEADERS = """assert complex ctype errno fenv float inttypes iso646 limits locale math setjmp signal stdalign
stdarg stdatomic stdbit stdbool stdckdint stddef stdint stdio stdlib stdnoreturn string tgmath threads time uchar
wchar wctype aio cpio dirent dlfcn fcntl fmtmsg fnmatch ftw glob grp iconv langinfo libgen monetary mqueue ndbm
netdb nl_types poll pthread pwd regex sched search semaphore spawn strings stropts syslog tar termios trace
ulimit unistd utime utmpx wordexp features alloca endian malloc memory getopt error byteswap libintl values
windows io direct process conio python pyconfig mex matrix tmwtypes mat engine oct""".split()

# module names a generated Python module must not shadow: the standard library of Python
# 3.9-3.14 (sys.stdlib_module_names without private names, plus the removed ones, and the
# test package), what the generated code and KinDynGen import
_PYTHON_MODULES = """abc aifc annotationlib antigravity argparse array ast asynchat asyncio asyncore atexit
audioop base64 bdb binascii binhex bisect builtins bz2 cprofile calendar cgi cgitb chunk cmath cmd code codecs
codeop collections colorsys compileall compression concurrent configparser contextlib contextvars copy copyreg
crypt csv ctypes curses dataclasses datetime dbm decimal difflib dis distutils doctest email encodings ensurepip
enum errno faulthandler fcntl filecmp fileinput fnmatch formatter fractions ftplib functools gc genericpath
getopt getpass gettext glob graphlib grp gzip hashlib heapq hmac html http idlelib imaplib imghdr imp importlib
inspect io ipaddress itertools json keyword lib2to3 linecache locale logging lzma mailbox mailcap marshal math
mimetypes mmap modulefinder msilib msvcrt multiprocessing netrc nis nntplib nt ntpath nturl2path numbers opcode
operator optparse os ossaudiodev parser pathlib pdb pickle pickletools pipes pkgutil platform plistlib poplib
posix posixpath pprint profile pstats pty pwd py_compile pyclbr pydoc pydoc_data pyexpat queue quopri random re
readline reprlib resource rlcompleter runpy sched secrets select selectors shelve shlex shutil signal site
smtpd smtplib sndhdr socket socketserver spwd sqlite3 sre_compile sre_constants sre_parse ssl stat statistics
string stringprep struct subprocess sunau symbol symtable sys sysconfig syslog tabnanny tarfile telnetlib
tempfile termios test textwrap this threading time timeit tkinter token tokenize tomllib trace traceback
tracemalloc tty turtle turtledemo types typing unicodedata unittest urllib uu uuid venv warnings wave weakref
webbrowser winreg winsound wsgiref xdrlib xml xmlrpc zipapp zipfile zipimport zlib zoneinfo
numpy scipy casadi jax jaxlib kindyngen""".split()

_MATLAB_WORDS = """break case catch classdef continue else elseif end enumeration events for function global
if methods otherwise parfor persistent properties return spmd switch try while do until unwind_protect
unwind_protect_cleanup end_unwind_protect end_try_catch endclassdef endenumeration endevents endfor endfunction
endif endmethods endparfor endproperties endspmd endswitch endwhile
abs all ans any atan2 acos asin atan cat ceil cell cellfun char chol class clc clear cos cosh cross det diag disp
doc dot double eig eps error eval exist exit exp expm eye false feval fieldnames find fix floor fprintf help i
imag inf input int8 int16 int32 int64 inv isa isempty isfield j keyboard kron length load log log10 log2 logical
lu max mean min mkoctfile mod nan norm numel ones path pi pinv plot qr quit rand randn rank real rem repmat
reshape round save sign sin single sinh size sort sqrt std struct sum svd tan tanh trace true uint8 uint16 uint32
uint64 var version warning which who zeros""".split()

# device names Windows refuses as file names, whatever the extension
_WINDOWS = ["con", "prn", "aux", "nul"] + [f"{d}{k}" for d in ("com", "lpt") for k in range(1, 10)]

RESERVED = frozenset(_C_KEYWORDS + _HEADERS + _PYTHON_MODULES + _MATLAB_WORDS + _WINDOWS
                     + [w.lower() for w in keyword.kwlist + keyword.softkwlist] + ["kdg"])
"""Identifiers that get the suffix ``_robot``: C, C++ and Python keywords, standard headers and
the headers system and MEX headers include, Python's standard modules and what generated code
imports, MATLAB/Octave keywords and common functions, Windows device names, and ``kdg`` (the
prefix of the generated C's own names)."""

_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
# C99 7.26.2 and 7.26.11 (future library directions, reserved for external linkage whatever is
# included, 7.1.3): function names beginning with is, to, str, mem or wcs and a lowercase letter.
# The C symbols <identifier>_fk_hom, ... have external linkage.
_C_RESERVED_PREFIX = re.compile(r"(is|to|str|mem|wcs)[a-z]")


def identifier(name: str) -> str:
    """The one identifier of a robot's files and symbols (``<identifier>.h``,
    ``<identifier>_fk_hom``, ``<identifier>.py``, the output folder): the name's letters and
    digits in ASCII lower case (accents dropped), every other run of characters one ``_``, none
    at either end, at most MAX_IDENTIFIER characters; ``r_`` before a leading digit or a prefix
    the C standard reserves for external names (``is``, ``to``, ``str``, ``mem``, ``wcs`` and a
    letter), ``robot`` for a name with no letter or digit, ``_robot`` after a RESERVED word.

    >>> [identifier(n) for n in ("lwr4", "LWR4_Hartl", "test-arm", "Roboter Ünï", "7dof", "")]
    ['lwr4', 'lwr4_hartl', 'test_arm', 'roboter_uni', 'r_7dof', 'robot']
    >>> [identifier(n) for n in ("math", "struct", 'x\"\"\"', "x*/ int evil; /*", "机器人")]
    ['math_robot', 'r_struct', 'x', 'x_int_evil', 'robot']
    >>> [identifier(n) for n in ("Stretch", "tool arm", "is_1", "to", "memo", "wcsx")]
    ['r_stretch', 'r_tool_arm', 'is_1', 'to', 'r_memo', 'r_wcsx']
    """
    letters = "".join(ch for ch in unicodedata.normalize("NFKD", name) if not unicodedata.combining(ch))
    ident = re.sub(r"[^a-z0-9]+", "_", letters.lower()).strip("_")
    if ident[:1].isdigit() or _C_RESERVED_PREFIX.match(ident):
        ident = "r_" + ident
    ident = ident[:MAX_IDENTIFIER].rstrip("_") or "robot"
    return ident + "_robot" if ident in RESERVED else ident


def is_identifier(text: str) -> bool:
    """Whether ``text`` has the shape of an identifier or a generated function's name (ASCII
    letters, digits and underscores, a letter first; what :func:`identifier` gives, what
    earlier versions gave for ASCII names, ``fk_hom``, ``Y_m``): safe in a path, a module name,
    an Octave function handle.

    >>> is_identifier("lwr4_hartl"), is_identifier("Y_m"), is_identifier("../x"), is_identifier("_a")
    (True, True, False, False)
    """
    return bool(_IDENTIFIER.fullmatch(text))
