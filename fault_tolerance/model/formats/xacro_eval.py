"""Safe xacro: ``${...}`` through an ``ast`` whitelist, confined file reads, bounded expansion.

The ``xacro`` package evaluates ``${...}`` with Python's ``eval`` behind a name check that looks
only at the outer expression, so a comprehension reaches ``().__class__.__subclasses__()`` and
``os.system``; ``xacro.load_yaml`` and ``<xacro:include>`` open any path (``/etc/passwd``, a FIFO
that blocks forever, ``/dev/zero``), and nothing bounds ``${9**9**9}`` or a macro that doubles
itself thirty times. :func:`confined` patches the ``xacro`` module for one expansion so that

* every ``${...}`` (and ``$(eval ...)``, and the unit tags of YAML files) goes through
  :func:`evaluate`, which walks the expression's ``ast`` and accepts only arithmetic,
  comparisons, boolean logic, conditionals, literals, property names, subscripts of plain
  dict/list/str values, a fixed list of functions (:data:`FUNCTIONS`, ``math.X``,
  ``xacro.load_yaml``, ...) and a few ``str`` methods (:data:`STR_METHODS`); everything else
  raises :class:`~fault_tolerance.errors.UnsafeDescription` naming the file, line and expression;
* ``xacro.load_yaml``, ``<xacro:include>`` (also its globs) read only regular files inside the
  given folders (:func:`read_confined`: real paths, no FIFO, device or directory, opened
  non-blocking and checked again after opening), at most :data:`MAX_FILE_BYTES` each;
* the expansion stops with a clear error past the limits below (time, macro calls and depth,
  elements, includes, sizes of numbers, strings and text).

This module imports only the standard library, ``xacro`` (and the ``yaml`` it uses) and the
toolkit's errors. ``xacro`` keeps its state in module globals: hold one lock around
:func:`confined` (:mod:`fault_tolerance.model.formats.xacro` does).

Example:
    >>> evaluate("degrees(a) if 'x' in axis else -a", {"a": 0.5, "axis": "x y"}, functions=FUNCTIONS)
    28.64788975654116
"""

from __future__ import annotations

import ast
import contextlib
import datetime
import functools
import glob as _glob
import math
import operator
import os
import re
import stat
import time
import types
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, NamedTuple, cast

from fault_tolerance.errors import FaultToleranceError, UnsafeDescription

#: Wall time one expansion may take [s]; checked in the evaluator and in every element/macro.
DEADLINE_SECONDS = 30.0
#: Longest ``${...}`` expression text [characters].
MAX_EXPRESSION_CHARS = 10_000
#: Deepest nesting of an expression's syntax tree.
MAX_EXPRESSION_DEPTH = 100
#: Largest integer an expression may produce [decimal digits] (Python's own str limit).
MAX_INT_DIGITS = 4300
#: Largest string, list or dict one expression or one evaluated text may produce [characters].
MAX_VALUE_CHARS = 1_000_000
#: All the text the evaluations of one expansion may produce together [characters].
MAX_EXPANDED_CHARS = 50_000_000
#: Largest expanded document [characters of XML].
MAX_OUTPUT_CHARS = 50_000_000
#: Most macro calls of one expansion.
MAX_MACRO_CALLS = 10_000
#: Deepest nesting of macro calls (macros calling macros, recursion).
MAX_MACRO_DEPTH = 100
#: Most elements one expansion may evaluate (copies made by macros and blocks included).
MAX_ELEMENTS = 100_000
#: Most steps xacro's DOM updates may take: nodes moved times the siblings at the place (the
#: minidom insertion xacro uses is linear in the siblings, so a block bomb is quadratic).
MAX_DOM_WORK = 200_000_000
#: Deepest nesting of ``<xacro:include>``.
MAX_INCLUDE_DEPTH = 50
#: Most files (includes and YAML files) one expansion may read.
MAX_FILES_READ = 2_000
#: Largest file xacro may read [bytes] (the URDF limit).
MAX_FILE_BYTES = 20 * 1024 * 1024

_INT_BITS = int(MAX_INT_DIGITS / math.log10(2)) + 1


# -- the functions and values expressions may use ----------------------------------------------


def _refuse(reason: str) -> UnsafeDescription:
    """An :class:`UnsafeDescription` for ``reason``, placed at the expression being evaluated."""
    session = _SESSION
    where = session.where(_EXPR[-1] if _EXPR else None) if session else ""
    expr = f"${{{_EXPR[-1]}}}: " if _EXPR else ""
    return UnsafeDescription(f"{where + ': ' if where else ''}{expr}{reason}")


def _power(a, b):
    """``a ** b``, refused when the result would be huge."""
    if _is_int(a) and _is_int(b) and b > 0 and abs(a) > 1:
        digits = b * math.log10(abs(a))
        if digits > MAX_INT_DIGITS:
            raise _refuse(
                f"the power {a} ** {b} would have about {digits:.3g} digits, more than the "
                f"{MAX_INT_DIGITS} allowed"
            )
    return a**b


def _round(number, ndigits=None):
    """``round`` with at most 1000 digits either side."""
    if ndigits is None:
        return round(number)
    if not _is_int(ndigits) or abs(ndigits) > 1000:
        raise _refuse(f"round(..., {ndigits!r}): ndigits must be an integer within ±1000")
    return round(number, ndigits)


def _int(value=0, *base):
    """``int`` of a number or of a string of at most :data:`MAX_INT_DIGITS` digits."""
    if isinstance(value, str | bytes) and len(value) > MAX_INT_DIGITS + 10:
        raise _refuse(f"int() of a {len(value)}-character string")
    return int(value, *base)


def _str(value=""):
    """``str`` of a value no larger than :data:`MAX_VALUE_CHARS`."""
    _check_size(value, "str()")
    return str(value)


_MATH_NAMES = (
    "sin cos tan asin acos atan atan2 sinh cosh tanh asinh acosh atanh sqrt exp log log10 log2 "
    "pow fabs floor ceil trunc radians degrees hypot fmod copysign isclose isnan isinf isfinite"
).split()
#: Constants ``math.X`` may name (plain names resolve through the symbol table, where xacro
#: puts them).
MATH_CONSTANTS: dict[str, float] = {k: getattr(math, k) for k in ("pi", "e", "tau", "inf", "nan")}
#: Functions expressions may call, by name (``math.X`` for the math ones as well).
FUNCTIONS: dict[str, Callable] = {
    **{k: getattr(math, k) for k in _MATH_NAMES},
    "abs": abs,
    "min": min,
    "max": max,
    "round": _round,
    "int": _int,
    "float": float,
    "str": _str,
    "bool": bool,
    "len": len,
}
#: ``str`` methods expressions may call (``xyz.split(' ')[0]``).
STR_METHODS = frozenset(
    "split rsplit strip lstrip rstrip lower upper startswith endswith replace join find rfind "
    "count".split()
)
_XACRO_FUNCTIONS = frozenset(
    "load_yaml arg warning message error fatal print_location abs_filename dotify tokenize".split()
)

_SCALARS = (bool, int, float, complex, str, bytes, type(None))
_CONTAINERS = (list, tuple, dict)
_INERT = (datetime.date, datetime.datetime, datetime.time, set, frozenset)


class _Func(NamedTuple):
    """A function an expression may call."""

    name: str
    fn: Callable


class _Space(NamedTuple):
    """``math`` or ``xacro``: members an expression may name after the dot."""

    name: str


class _Method(NamedTuple):
    """A bound ``str`` method of :data:`STR_METHODS`."""

    text: str
    name: str


def _is_int(v) -> bool:
    return type(v) in (int, bool)


@functools.cache
def _yaml_types() -> tuple[type, ...]:
    """The wrappers xacro puts around YAML dicts and lists (dotted access)."""
    try:
        import xacro
    except ImportError:  # pragma: no cover - evaluate() without xacro
        return ()
    return (xacro.YamlDictWrapper, xacro.YamlListWrapper)


def _is_plain(v) -> bool:
    """True for the data values expressions compute with (numbers, strings, lists, dicts, YAML)."""
    t = type(v)
    return t in _SCALARS or t in _CONTAINERS or t in _yaml_types() or t in _INERT


def _size(value, limit: int = MAX_VALUE_CHARS) -> int:
    """Characters ``str(value)`` takes, roughly; stops counting once past ``limit``."""
    total, stack = 0, [value]
    while stack and total <= limit:
        v = stack.pop()
        if isinstance(v, str | bytes):
            total += len(v) + 2
        elif isinstance(v, dict):
            total += 2 + 2 * len(v)
            stack.extend(v.keys())
            stack.extend(v.values())
        elif isinstance(v, list | tuple | set | frozenset):
            total += 2 + 2 * len(v)
            stack.extend(v)
        else:
            total += 24
    return total


def _check_size(value, what: str) -> None:
    if _size(value) > MAX_VALUE_CHARS:
        raise _refuse(f"{what} would be larger than {MAX_VALUE_CHARS} characters")


# -- the evaluator ------------------------------------------------------------------------------

_BINOPS: dict[type, Callable] = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.FloorDiv: operator.floordiv,
    ast.Mod: operator.mod,
    ast.Pow: _power,
}
_UNARY: dict[type, Callable] = {
    ast.UAdd: operator.pos,
    ast.USub: operator.neg,
    ast.Not: operator.not_,
}
_COMPARE: dict[type, Callable] = {
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
    ast.Is: operator.is_,
    ast.IsNot: operator.is_not,
    ast.In: lambda a, b: a in b,
    ast.NotIn: lambda a, b: a not in b,
}
_FORBIDDEN = {
    "ListComp": "comprehensions",
    "SetComp": "comprehensions",
    "DictComp": "comprehensions",
    "GeneratorExp": "generator expressions",
    "Lambda": "lambdas",
    "NamedExpr": "assignments (:=)",
    "JoinedStr": "f-strings",
    "Starred": "* unpacking",
    "Await": "await",
    "Yield": "yield",
    "YieldFrom": "yield",
}
_FORMAT_SPEC = re.compile(r"%(?:\([^)]*\))?[-#0 +]*(\*|\d+)?(?:\.(\*|\d+))?")
_EXPR: list[str] = []  # the raw expressions being evaluated, innermost last (for messages)


class _Evaluator:
    """Walks one expression's syntax tree over the symbol table; refuses what is not listed."""

    def __init__(self, symbols: Mapping, functions: Mapping[str, Any] | None, trusted: Mapping):
        self.symbols = symbols
        self.functions = functions or {}
        self.trusted = trusted  # xacro's global symbols: the functions behind FUNCTIONS' names
        self.budget = _SESSION.budget if _SESSION else Budget()

    def visit(self, node: ast.AST, depth: int = 0):
        """The value of ``node``, a plain value or a function/namespace marker."""
        if depth > MAX_EXPRESSION_DEPTH:
            raise _refuse(f"the expression is nested more than {MAX_EXPRESSION_DEPTH} deep")
        self.budget.tick()
        method = getattr(self, "_" + type(node).__name__, None)
        if method is None:
            what = _FORBIDDEN.get(type(node).__name__, f"'{type(node).__name__}' expressions")
            raise _refuse(f"{what} are not allowed in xacro expressions ({_ALLOWED})")
        return method(node, depth + 1)

    def value(self, node: ast.AST, depth: int):
        """A plain value (not a function or namespace)."""
        v = self.visit(node, depth)
        if not _is_plain(v):
            what = (
                "a function or namespace"
                if isinstance(v, _Func | _Space | _Method)
                else (f"a {type(v).__name__}")
            )
            raise _refuse(f"'{ast.unparse(node)}' is {what}, not a value expressions may use")
        return v

    def _Constant(self, node: ast.Constant, depth: int):
        if type(node.value) not in _SCALARS:
            raise _refuse(f"the literal {node.value!r} is not allowed")
        return node.value

    def _Name(self, node: ast.Name, depth: int):
        name = node.id
        if name.startswith("__"):
            raise _refuse(f"the name '{name}' is not allowed (double underscore)")
        try:
            value = self.symbols[name]
        except KeyError:
            if name not in self.functions:
                raise NameError(f"name '{name}' is not defined") from None
            value = self.functions[name]
            return _Func(name, value) if callable(value) else value
        if _is_plain(value):
            return value
        return self._global(name, value)

    def _global(self, name: str, value):
        """The marker for a name bound to one of xacro's global functions or namespaces."""
        import xacro

        if self.trusted.get(name) is value:
            if name in FUNCTIONS:
                return _Func(name, FUNCTIONS[name])
            if name in ("math", "xacro"):
                return _Space(name)
            if name == "load_yaml":  # deprecated direct spelling
                return _Func(name, _deprecated_load_yaml)
        elif isinstance(value, xacro.NameSpace):  # <xacro:include ns="..."> properties
            return value
        raise _refuse(
            f"'{name}' ({type(value).__name__}) is not among what xacro expressions may use "
            f"({_ALLOWED})"
        )

    def _Attribute(self, node: ast.Attribute, depth: int):
        import xacro

        attr = node.attr
        if attr.startswith("_"):
            raise _refuse(f"the attribute '.{attr}' is not allowed (underscore)")
        base = self.visit(node.value, depth)
        if isinstance(base, _Space):
            return _member(base.name, attr)
        if type(base) is xacro.NameSpace:
            try:
                value = base[attr]
            except KeyError:
                raise NameError(f"name '{attr}' is not defined") from None
            return value if _is_plain(value) else self._global(attr, value)
        if type(base) is xacro.YamlDictWrapper:
            return getattr(base, attr)  # the dict's key, as xacro's dotted access does
        if type(base) is str and attr in STR_METHODS:
            return _Method(base, attr)
        raise _refuse(
            f"the attribute '.{attr}' of a {type(base).__name__} is not allowed (only "
            "math.X, xacro.X, dotted keys of YAML dicts and the str methods "
            f"{sorted(STR_METHODS)})"
        )

    def _Call(self, node: ast.Call, depth: int):
        func = self.visit(node.func, depth)
        if not isinstance(func, _Func | _Method):
            raise _refuse(f"'{ast.unparse(node.func)}' is not a function expressions may call")
        args = [self.value(a, depth) for a in node.args]
        kwargs = {}
        for kw in node.keywords:
            if kw.arg is None:
                raise _refuse("** unpacking is not allowed in xacro expressions")
            kwargs[kw.arg] = self.value(kw.value, depth)
        if isinstance(func, _Method):
            result = _str_method(func.text, func.name, args, kwargs)
        else:
            result = func.fn(*args, **kwargs)
        if not _is_plain(result):
            raise _refuse(f"{ast.unparse(node.func)}() returned a {type(result).__name__}")
        return result

    def _BinOp(self, node: ast.BinOp, depth: int):
        fn = _BINOPS.get(type(node.op))
        if fn is None:
            raise _refuse(f"the operator {type(node.op).__name__} is not allowed ({_ALLOWED})")
        a, b = self.value(node.left, depth), self.value(node.right, depth)
        _check_binop(node.op, a, b)
        result = fn(a, b)
        if isinstance(result, str | bytes | list | tuple):
            _check_size(result, "the result")
        return result

    def _UnaryOp(self, node: ast.UnaryOp, depth: int):
        fn = _UNARY.get(type(node.op))
        if fn is None:
            raise _refuse(f"the operator {type(node.op).__name__} is not allowed ({_ALLOWED})")
        return fn(self.value(node.operand, depth))

    def _BoolOp(self, node: ast.BoolOp, depth: int):
        is_and = isinstance(node.op, ast.And)
        for item in node.values:
            result = self.value(item, depth)
            if bool(result) != is_and:
                return result
        return result

    def _Compare(self, node: ast.Compare, depth: int):
        left = self.value(node.left, depth)
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = self.value(right_node, depth)
            if not _COMPARE[type(op)](left, right):
                return False
            left = right
        return True

    def _IfExp(self, node: ast.IfExp, depth: int):
        test = self.value(node.test, depth)
        return self.value(node.body if test else node.orelse, depth)

    def _Tuple(self, node: ast.Tuple, depth: int):
        return tuple(self.value(e, depth) for e in node.elts)

    def _List(self, node: ast.List, depth: int):
        return [self.value(e, depth) for e in node.elts]

    def _Dict(self, node: ast.Dict, depth: int):
        if any(k is None for k in node.keys):
            raise _refuse("** unpacking is not allowed in xacro expressions")
        return {
            self.value(k, depth): self.value(v, depth)  # type: ignore[arg-type]  # None refused above
            for k, v in zip(node.keys, node.values, strict=True)
        }

    def _Subscript(self, node: ast.Subscript, depth: int):
        base = self.value(node.value, depth)
        if type(base) not in (str, list, tuple, dict, *_yaml_types()):
            raise _refuse(f"subscripts of a {type(base).__name__} are not allowed")
        return base[self.value(node.slice, depth)]

    def _Slice(self, node: ast.Slice, depth: int):
        parts = [
            None if p is None else self.value(p, depth) for p in (node.lower, node.upper, node.step)
        ]
        if any(p is not None and not _is_int(p) for p in parts):
            raise _refuse("slice bounds must be integers")
        return slice(*parts)


_ALLOWED = (
    "allowed: numbers, strings, property names, + - * / // % **, comparisons, and/or/not, "
    "a if c else b, lists/tuples/dicts, [index], math functions, xacro.load_yaml; see docs/xacro.md"
)


def _check_binop(op: ast.operator, a, b) -> None:
    """Refuse ``a op b`` before computing it when the result would be too large."""
    if isinstance(op, ast.Mult):
        if _is_int(a) and _is_int(b) and a.bit_length() + b.bit_length() > _INT_BITS:
            raise _refuse(f"the product would have more than {MAX_INT_DIGITS} digits")
        seq, n = (a, b) if _is_int(b) else (b, a)
        if isinstance(seq, str | bytes | list | tuple) and _is_int(n) and n > 0:
            if _size(seq) * n > MAX_VALUE_CHARS:
                raise _refuse(
                    f"repeating a {type(seq).__name__} {n} times would be larger than "
                    f"{MAX_VALUE_CHARS} characters"
                )
    elif isinstance(op, ast.Add) and isinstance(a, str | bytes | list | tuple):
        if _size(a) + _size(b) > MAX_VALUE_CHARS:
            raise _refuse(f"the sum would be larger than {MAX_VALUE_CHARS} characters")
    elif isinstance(op, ast.Mod) and isinstance(a, str | bytes):
        if isinstance(a, bytes):
            raise _refuse("%-formatting of bytes is not allowed")
        for width, precision in _FORMAT_SPEC.findall(a):
            for n in (width, precision):
                if n == "*" or (n and int(n) > 1000):
                    raise _refuse(f"a %-format width or precision of {n!r} is not allowed")


def _str_method(text: str, name: str, args: list, kwargs: dict):
    """``text.name(*args, **kwargs)`` for :data:`STR_METHODS`, with its result size checked."""
    if name == "replace" and len(args) >= 2 and isinstance(args[1], str):
        if (len(text) + 1) * (len(args[1]) + 1) > MAX_VALUE_CHARS:
            raise _refuse(f"str.replace would be larger than {MAX_VALUE_CHARS} characters")
    if name == "join" and args and _size(args[0]) * (len(text) + 1) > MAX_VALUE_CHARS:
        raise _refuse(f"str.join would be larger than {MAX_VALUE_CHARS} characters")
    return getattr(text, name)(*args, **kwargs)


def _member(space: str, attr: str):
    """``math.attr`` or ``xacro.attr``."""
    if space == "math":
        if attr in MATH_CONSTANTS:
            return MATH_CONSTANTS[attr]
        if attr in _MATH_NAMES:
            return _Func(attr, FUNCTIONS[attr])
    elif attr in _XACRO_FUNCTIONS:
        return _Func(attr, _xacro_function(attr))
    raise _refuse(f"'{space}.{attr}' is not among what xacro expressions may use ({_ALLOWED})")


def _xacro_function(name: str) -> Callable:
    """The confined or harmless version of ``xacro.name``."""
    import xacro

    def message(*args, **_):
        getattr(xacro, name)(*(str(a) for a in args))
        return ""

    def fatal(*args):
        raise xacro.XacroException(" ".join(map(str, args)))

    def tokenize(s, sep=",; ", skip_empty=True):
        parts = re.split(f"[{re.escape(sep)}]", s)
        return [p for p in parts if p] if skip_empty else parts

    table = {
        "load_yaml": _load_yaml,
        "arg": lambda arg: xacro.substitution_args_context["arg"][arg],
        "warning": message,
        "message": message,
        "error": message,
        "fatal": fatal,
        "print_location": lambda: "",
        "abs_filename": lambda spec: xacro.abs_filename_spec(str(spec)),
        "dotify": lambda d: xacro.YamlDictWrapper(dict(d)),
        "tokenize": tokenize,
    }
    return cast("Callable[..., Any]", table[name])


def evaluate(
    expr: str,
    symbols: Mapping,
    *,
    raw: str | None = None,
    functions: Mapping[str, Any] | None = None,
):
    """The value of one xacro expression (the text inside ``${...}``).

    Args:
        expr: The expression, after xacro substituted its ``$(...)`` parts.
        symbols: xacro's symbol table (properties; their globals are xacro's), or a plain dict.
        raw: The expression as written, for error messages (default: ``expr``).
        functions: Names to resolve when the symbols lack them (for ``$(eval ...)``): functions
            expressions may call, or constants.

    Raises:
        UnsafeDescription: the expression uses what is not accepted, or would be too large.
        NameError, TypeError, ValueError, ...: as Python's ``eval`` would (xacro reports them).
    """
    if not isinstance(expr, str):
        raise TypeError(f"a xacro expression must be text, not {type(expr).__name__}")
    _EXPR.append(expr if raw is None else raw)
    try:
        text = expr.strip()
        if len(text) > MAX_EXPRESSION_CHARS:
            raise _refuse(f"the expression is longer than {MAX_EXPRESSION_CHARS} characters")
        try:
            tree = ast.parse(text, mode="eval")
        except (RecursionError, MemoryError):
            raise _refuse("the expression is nested too deeply") from None
        evaluator = _Evaluator(symbols, functions, _trusted_globals())
        return evaluator.value(tree.body, 0)
    finally:
        _EXPR.pop()


def _trusted_globals() -> Mapping:
    try:
        import xacro
    except ImportError:  # pragma: no cover - evaluate() without xacro
        return {}
    return getattr(xacro, "_global_symbols", {})


# -- confined reads -------------------------------------------------------------------------------


def _inside(real: str, roots: Sequence[str]) -> bool:
    return any(real == r or real.startswith(r.rstrip(os.sep) + os.sep) for r in roots)


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def read_confined(
    path: str | os.PathLike,
    roots: Sequence[str],
    *,
    what: str = "file",
    max_bytes: int = MAX_FILE_BYTES,
) -> bytes:
    """The bytes of a regular file whose real path lies inside one of ``roots``.

    The path is resolved (symlinks followed) and must lie inside a root (real paths); it must be
    a regular file, not larger than ``max_bytes``. It is opened non-blocking and without
    following a last symlink, then checked again on the open descriptor (same file, regular,
    and on Linux its ``/proc/self/fd`` path inside a root), so a FIFO, device or a swap cannot
    block or escape.

    Raises:
        UnsafeDescription: outside the roots, not a regular file, too large or swapped.
        OSError: the file is missing or unreadable.
    """
    given = os.path.abspath(os.fspath(path))
    real = os.path.realpath(given)
    roots = [os.path.realpath(r) for r in roots]
    shown = given if real == given else f"{given} (-> {real})"
    if not _inside(real, roots):
        raise UnsafeDescription(
            f"{what} {shown} lies outside the folders xacro may read {list(roots)}; pass the "
            "folder that holds it with package_dirs=[...] (--package-dir DIR)"
        )
    st = os.stat(real)
    if not stat.S_ISREG(st.st_mode):
        raise UnsafeDescription(f"{what} {shown} is {_kind(st.st_mode)}, not a regular file")
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOFOLLOW", 0)
    fd = os.open(real, flags | getattr(os, "O_CLOEXEC", 0))
    try:
        now = os.fstat(fd)
        if not stat.S_ISREG(now.st_mode) or (now.st_dev, now.st_ino) != (st.st_dev, st.st_ino):
            raise UnsafeDescription(f"{what} {shown} changed while it was opened")
        with contextlib.suppress(OSError):
            if not _inside(os.readlink(f"/proc/self/fd/{fd}"), roots):
                raise UnsafeDescription(f"{what} {shown} changed while it was opened")
        if now.st_size > max_bytes:
            raise UnsafeDescription(
                f"{what} {shown}: {now.st_size} bytes is larger than the {max_bytes} allowed"
            )
        chunks, left = [], max_bytes + 1
        while left > 0 and (chunk := os.read(fd, min(left, 1 << 20))):
            chunks.append(chunk)
            left -= len(chunk)
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > max_bytes:
        raise UnsafeDescription(f"{what} {shown} is larger than the {max_bytes} bytes allowed")
    return data


def _text(data: bytes, where: str) -> str:
    """UTF-8 text without NUL bytes."""
    if b"\x00" in data:
        raise UnsafeDescription(f"{where}: not text (NUL bytes)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise UnsafeDescription(
            f"{where}: not UTF-8 text (invalid byte at offset {err.start})"
        ) from None


# -- one expansion ----------------------------------------------------------------------------


class Budget:
    """Counters and deadline of one expansion; each limit raises :class:`UnsafeDescription`."""

    def __init__(self, seconds: float | None = None) -> None:
        seconds = DEADLINE_SECONDS if seconds is None else seconds
        self.seconds = seconds
        self.deadline = time.monotonic() + seconds
        self.counts: dict[str, int] = {}
        self.macro_depth = 0
        self._ticks = 0

    def tick(self) -> None:
        """Raise once the deadline has passed (the clock is read every 64th call)."""
        self._ticks += 1
        if self._ticks & 63 == 0 and time.monotonic() > self.deadline:
            raise _refuse(
                f"the xacro expansion took longer than {self.seconds:g} s "
                "(DEADLINE_SECONDS); refused as unbounded"
            )

    def count(self, what: str, limit: int, n: int = 1, name: str = "") -> None:
        """Add ``n`` to counter ``what``; raise past ``limit`` (``name``: the module constant)."""
        total = self.counts.get(what, 0) + n
        self.counts[what] = total
        if total > limit:
            raise _refuse(
                f"the xacro expansion needs more than {limit} {what} ({name}); refused as unbounded"
            )


_SESSION: _Session | None = None


def _load_yaml(filename):
    """``xacro.load_yaml`` through the confined reader of the expansion under way."""
    if _SESSION is None:
        raise _refuse("xacro.load_yaml is only available while a file is expanded")
    return _SESSION.load_yaml(filename)


def _deprecated_load_yaml(filename):
    import xacro

    xacro.warning("Using load_yaml() directly is deprecated. Use xacro.load_yaml() instead.")
    return _load_yaml(filename)


_TOKENS = (
    ("dollars", re.compile(r"\$\$+(\{|\()")),
    ("expr", re.compile(r"\$\{[^\}]*\}")),
    ("extension", re.compile(r"\$\([^\)]*\)")),
    ("text", re.compile(r"[^$]+|\$[^{($]+|\$$")),
)


class _Session:
    """The hooks one expansion installs into the ``xacro`` module."""

    def __init__(self, xacro, top: str, roots: Sequence[str], check_xml, seconds: float):
        self.xacro = xacro
        self.top = os.path.realpath(top)
        self.roots = [os.path.realpath(r) for r in roots]
        self.check_xml = check_xml
        self.budget = Budget(seconds)
        self.texts: dict[str, str] = {}  # file -> text read, for line numbers
        self.original: dict[str, Any] = {}
        self._loader = None

    def where(self, raw: str | None) -> str:
        """``file:line`` of the expression ``raw`` (the file being expanded if not found)."""
        stack = [os.path.abspath(f) for f in (self.xacro.filestack or []) if f]
        files = list(dict.fromkeys([*reversed(stack), *self.texts]))
        for needle in [f"${{{raw}}}", raw] if raw else []:
            for f in files:
                line = self.line_of(f, needle)
                if line:
                    return f"{f}:{line}"
        return files[0] if files else self.top

    def line_of(self, file: str, needle: str) -> int | None:
        """The line of ``file`` where ``needle`` first occurs, or None."""
        text = self.texts.get(os.path.abspath(file), "")
        at = text.find(needle) if needle else -1
        return text.count("\n", 0, at) + 1 if at >= 0 else None

    def read(self, path: str, what: str) -> bytes:
        """Bytes of a file xacro reads, confined to the roots (the top file is allowed too)."""
        self.budget.count("files read", MAX_FILES_READ, name="MAX_FILES_READ")
        roots = [*self.roots, self.top]
        return read_confined(path, roots, what=what, max_bytes=MAX_FILE_BYTES)

    def parse(self, inp, filename=None):
        """The ``parse`` of xacro: a file (top or include) read confined and through the byte checks."""
        xacro = self.xacro
        if inp is None:
            if len(xacro.filestack or []) > MAX_INCLUDE_DEPTH:
                raise _refuse(
                    f"includes are nested more than {MAX_INCLUDE_DEPTH} deep "
                    f"(MAX_INCLUDE_DEPTH) at {filename}"
                )
            file = os.path.join(xacro.root_dir, filename)
            try:
                data = self.read(file, self.include_site(filename) + "xacro file")
            except OSError as err:
                xacro.filestack.pop()
                raise xacro.XacroException(f"{err.strerror}: {file}", exc=err) from None
            data = self.check_xml(data, file)
            inp = data.decode("utf-8")
            self.texts[os.path.abspath(file)] = inp
        return self.original["parse"](inp, filename)

    def include_site(self, filename: str) -> str:
        """``"file:line: "`` of the ``<xacro:include>`` of ``filename`` ("" for the top file)."""
        stack = [f for f in (self.xacro.filestack or []) if f]
        if len(stack) < 2:
            return ""
        line = self.line_of(stack[-2], os.path.basename(filename))
        return f"{stack[-2]}{f':{line}' if line else ''}: "

    def load_yaml(self, filename):
        """``xacro.load_yaml``: a regular YAML file inside the roots, size-checked."""
        import yaml

        xacro = self.xacro
        if not isinstance(filename, str):
            raise TypeError(f"load_yaml needs a file name, not {type(filename).__name__}")
        path = xacro.abs_filename_spec(filename)
        where = self.where(_EXPR[-1] if _EXPR else None)
        text = _text(self.read(path, f"{where}: xacro.load_yaml of"), path)
        self.texts[os.path.abspath(path)] = text
        xacro.filestack.append(path)
        try:
            value = yaml.load(text, Loader=self.yaml_loader())  # noqa: S506 - a SafeLoader
        except RecursionError:
            raise _refuse(f"the YAML file {path} is nested too deeply") from None
        finally:
            xacro.filestack.pop()
            xacro.all_includes.append(path)
        if _size(value) > MAX_VALUE_CHARS:
            raise _refuse(f"the YAML file {path} expands to more than {MAX_VALUE_CHARS} characters")
        return xacro.YamlListWrapper.wrap(value)

    def yaml_loader(self):
        """A SafeLoader with xacro's unit tags (``!degrees``...), not changing yaml's own."""
        if self._loader is None:
            import yaml

            class Loader(yaml.SafeLoader):
                """yaml's SafeLoader with xacro's unit tags."""

            for unit in getattr(self.xacro, "ConstructUnits", ()):
                Loader.add_constructor(unit.value.tag, unit.constructor)
            self._loader = Loader
        return self._loader

    def glob(self, pattern: str) -> list[str]:
        """``glob.glob`` of an include pattern whose folder lies inside the roots."""
        folder = os.path.dirname(re.split(r"[*?[]", pattern, maxsplit=1)[0]) or os.curdir
        if not _inside(os.path.realpath(folder), self.roots):
            raise _refuse(
                f"the include pattern {pattern} lies outside the folders xacro may read "
                f"{self.roots}"
            )
        self.budget.tick()
        return _glob.glob(pattern)  # each file is then read confined

    def eval_text(self, text, symbols):
        """The ``eval_text`` of xacro (same tokens, same results) with its sizes bounded."""
        xacro = self.xacro
        self.budget.tick()
        results, pos = [], 0
        while pos < len(text):
            for kind, pattern in _TOKENS:  # noqa: B007 - kind is used after the loop
                match = pattern.match(text, pos)
                if match:
                    break
            else:
                raise xacro.XacroException("invalid expression: " + text[pos:])
            token, pos = match.group(0), match.end()
            if kind == "expr":
                results.append(self.expression(token[2:-1], symbols))
            elif kind == "extension":
                results.append(xacro.eval_extension(f"$({xacro.eval_text(token[2:-1], symbols)})"))
            elif kind == "text":
                results.append(token)
            else:
                results.append(token[1:])
        if len(results) == 1:
            return results[0]
        pieces = [str(r) for r in results]
        size = sum(map(len, pieces))
        if size > MAX_VALUE_CHARS:
            raise _refuse(f"an evaluated text would be longer than {MAX_VALUE_CHARS} characters")
        self.budget.count(
            "characters of evaluated text", MAX_EXPANDED_CHARS, size, "MAX_EXPANDED_CHARS"
        )
        return "".join(pieces)

    def expression(self, raw: str, symbols):
        """One ``${raw}``: xacro's ``handle_expr`` with :func:`evaluate` in place of ``eval``."""
        xacro = self.xacro
        try:
            value = evaluate(xacro.eval_text(raw, symbols), symbols, raw=raw)
        except FaultToleranceError:
            raise
        except Exception as e:  # as xacro does: its message, with the expression
            raise xacro.XacroException(
                exc=e, suffix=f"{os.linesep}when evaluating expression '{raw}'"
            ) from None
        self.budget.count(
            "characters of evaluated text", MAX_EXPANDED_CHARS, _size(value), "MAX_EXPANDED_CHARS"
        )
        return value

    def safe_eval(self, expr, globals, locals=None):
        """The ``safe_eval`` of xacro (YAML unit tags call it) through :func:`evaluate`."""
        return evaluate(expr, globals if locals is None else _Chain(locals, globals))

    def eval_all(self, node, macros, symbols):
        """The ``eval_all`` of xacro on one element, counted and under the deadline."""
        self.budget.tick()
        self.budget.count("elements", MAX_ELEMENTS, name="MAX_ELEMENTS")
        return self.original["eval_all"](node, macros, symbols)

    def replace_node(self, node, by, content_only=False):
        """The ``replace_node`` of xacro, its quadratic cost counted (:data:`MAX_DOM_WORK`)."""
        parent = node.parentNode
        if by is not None and parent is not None:
            items = by if isinstance(by, list) else [by]
            moved = sum(len(d.childNodes) for d in items) if content_only else len(items)
            work = moved * (len(parent.childNodes) + moved + 1)  # the place moves on
            self.budget.count("steps of DOM updates", MAX_DOM_WORK, work, "MAX_DOM_WORK")
        return self.original["replace_node"](node, by, content_only)

    def macro_call(self, node, macros, symbols):
        """The ``handle_macro_call`` of xacro, counted, its nesting bounded."""
        if not node.tagName.startswith("xacro:"):
            return self.original["handle_macro_call"](node, macros, symbols)
        budget = self.budget
        budget.tick()
        budget.count("macro calls", MAX_MACRO_CALLS, name="MAX_MACRO_CALLS")
        if budget.macro_depth >= MAX_MACRO_DEPTH:
            raise _refuse(
                f"macro calls are nested more than {MAX_MACRO_DEPTH} deep (MAX_MACRO_DEPTH) at "
                f"<{node.tagName}>; refused as unbounded recursion"
            )
        budget.macro_depth += 1
        try:
            return self.original["handle_macro_call"](node, macros, symbols)
        finally:
            budget.macro_depth -= 1

    def subst_eval(self, s, context):
        """``$(eval ...)`` through :func:`evaluate`: the arguments, arg(), find(), math."""
        subst = self.xacro.substitution_args
        args = context.setdefault("arg", {})
        functions: dict[str, Any] = {k: FUNCTIONS[k] for k in _MATH_NAMES}
        functions.update(MATH_CONSTANTS)
        functions.update(
            arg=lambda name: subst.convert_value(subst._eval_arg(name, args=args), "auto"),
            dirname=lambda: subst._eval_dirname(context["filename"]),
            find=lambda pkg: subst._eval_find(pkg),
            env=lambda name: subst._eval_env(name),
            optenv=lambda name, default="": subst._eval_optenv(name, default),
        )
        return str(evaluate(s, dict(args), raw=f"$(eval {s})", functions=functions))


class _Chain(dict):
    """Lookup in ``first``, then ``second`` (xacro's ``safe_eval`` with locals)."""

    def __init__(self, first: Mapping, second: Mapping) -> None:
        super().__init__()
        self.first, self.second = first, second

    def __getitem__(self, key):
        try:
            return self.first[key]
        except KeyError:
            return self.second[key]


_NEEDED = (
    "safe_eval eval_text eval_all handle_macro_call parse load_yaml eval_extension "
    "abs_filename_spec XacroException YamlListWrapper YamlDictWrapper NameSpace _global_symbols "
    "filestack root_dir all_includes substitution_args"
).split()
_NEEDED_SUBST = "_eval _eval_arg _eval_dirname _eval_find _eval_env _eval_optenv convert_value"


@contextlib.contextmanager
def confined(
    xacro: types.ModuleType,
    top: str | os.PathLike,
    roots: Sequence[str | os.PathLike],
    *,
    check_xml: Callable[[bytes, str], bytes] = lambda data, where: data,
    seconds: float | None = None,
) -> Iterator[Budget]:
    """Patch ``xacro`` for one expansion of ``top``: safe evaluation, confined reads, limits.

    Args:
        xacro: The imported ``xacro`` module (2.x).
        top: The file to expand (read although it may lie outside ``roots``).
        roots: The folders xacro may read: the package folders and the top file's folder.
        check_xml: Checks and returns the bytes of every XML file xacro reads (``where`` names
            it); raises to refuse one.
        seconds: The deadline of the expansion (default :data:`DEADLINE_SECONDS`).

    Yields:
        The expansion's :class:`Budget`.

    Raises:
        UnsafeDescription: the installed xacro lacks a hook this needs (nothing is patched).
    """
    global _SESSION
    missing = [n for n in _NEEDED if not hasattr(xacro, n)]
    subst = getattr(xacro, "substitution_args", None)
    missing += [f"substitution_args.{n}" for n in _NEEDED_SUBST.split() if not hasattr(subst, n)]
    if missing:
        raise UnsafeDescription(
            f"{top}: the installed xacro {getattr(xacro, '__version__', '')} lacks {missing}, "
            "which safe xacro expansion needs; install xacro 2.x (pip install 'xacro>=2.0,<3')"
        )
    assert subst is not None  # checked above: "missing" names it when absent
    seconds = DEADLINE_SECONDS if seconds is None else seconds
    session = _Session(xacro, os.fspath(top), [os.fspath(r) for r in roots], check_xml, seconds)
    hooks = {
        "safe_eval": session.safe_eval,
        "eval_text": session.eval_text,
        "eval_all": session.eval_all,
        "handle_macro_call": session.macro_call,
        "replace_node": session.replace_node,
        "parse": session.parse,
        "load_yaml": _load_yaml,
        "glob": types.SimpleNamespace(glob=session.glob),
    }
    session.original = {name: getattr(xacro, name) for name in hooks if hasattr(xacro, name)}
    saved_subst, saved_session = subst._eval, _SESSION
    for name in session.original:
        setattr(xacro, name, hooks[name])
    subst._eval = session.subst_eval
    _SESSION = session
    try:
        yield session.budget
    except RecursionError:
        raise _refuse("the description is nested too deeply to expand") from None
    finally:
        _SESSION = saved_session
        subst._eval = saved_subst
        for name, value in session.original.items():
            setattr(xacro, name, value)
