"""Safe evaluation of the numbers and x, y expressions that case files give for loads and displacements."""

from __future__ import annotations

import ast
import math
import warnings
from dataclasses import dataclass, field
from itertools import accumulate
from typing import Any, Callable

import numpy as np

from contactfem.errors import ContactFemError

__all__ = ["ExpressionError", "Expression", "compile_expression", "step_without_derivative", "to_sympy",
           "sympy_symbols"]

#: Refused before evaluation: longer text, more expression nodes, deeper nesting.
MAX_LENGTH = 1000
MAX_NODES = 500
MAX_DEPTH = 50

_Fn = Callable[[np.ndarray, np.ndarray], Any]

_VARIABLES = ("x", "y")
_CONSTANTS = {"pi": np.pi, "e": np.e}
_ONE_ARG = ("sin cos tan arcsin arccos arctan sinh cosh tanh exp log log10 log2 sqrt abs sign floor ceil").split()
_FUNCTIONS: dict[str, tuple[Callable[..., Any], int]] = {
    **{name: (getattr(np, name), 1) for name in _ONE_ARG},
    **{name: (getattr(np, name), 2) for name in ("arctan2", "hypot", "minimum", "maximum")},
    "where": (np.where, 3),
}
_CANONICAL = ", ".join(_FUNCTIONS)
_ALIASES = {"asin": "arcsin", "acos": "arccos", "atan": "arctan", "atan2": "arctan2", "min": "minimum", "max": "maximum"}
_FUNCTIONS.update({alias: _FUNCTIONS[name] for alias, name in _ALIASES.items()})

_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply,
           ast.Div: np.true_divide, ast.Pow: np.power, ast.Mod: np.mod}
_UNARY = {ast.UAdd: np.positive, ast.USub: np.negative}
_COMPARE = {ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater,
            ast.GtE: np.greater_equal, ast.Eq: np.equal, ast.NotEq: np.not_equal}
_SYMBOLS = {ast.FloorDiv: "//", ast.MatMult: "@", ast.BitAnd: "&", ast.BitOr: "|", ast.BitXor: "^",
            ast.LShift: "<<", ast.RShift: ">>", ast.Invert: "~", ast.Not: "not",
            ast.In: "in", ast.NotIn: "not in", ast.Is: "is", ast.IsNot: "is not"}
_REFUSED = {
    ast.Attribute: "attribute access is not allowed", ast.Subscript: "subscripts (indexing) are not allowed",
    ast.Slice: "slices are not allowed", ast.Lambda: "lambda is not allowed",
    **dict.fromkeys((ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp), "comprehensions are not allowed"),
    **dict.fromkeys((ast.JoinedStr, ast.FormattedValue), "f-strings are not allowed"),
    ast.BoolOp: "'and'/'or' are not allowed; use where(cond, a, b)",
    ast.IfExp: "if-expressions are not allowed; use where(cond, a, b)",
    ast.NamedExpr: "':=' assignments are not allowed", ast.Starred: "starred arguments are not allowed",
    ast.List: "lists are not allowed", ast.Tuple: "tuples are not allowed",
    ast.Set: "sets are not allowed", ast.Dict: "dicts are not allowed",
}


class ExpressionError(ContactFemError):
    """A number or expression from a case file is refused.

    The message says, in one short line, what is wrong with the text; the
    caller adds the file and the YAML key.
    """


@dataclass(frozen=True)
class Expression:
    """A checked expression in x and y, callable on numpy arrays.

    Attributes
    ----------
    text : str
        The normalised source text (whitespace runs collapsed to one space;
        ``str(value)`` for numbers).
    is_constant : bool
        True if the expression uses neither x nor y.
    variables : frozenset of str
        The subset of ``{"x", "y"}`` the expression uses.
    """

    text: str
    is_constant: bool
    variables: frozenset[str]
    _fn: _Fn = field(repr=False, compare=False)

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Evaluate at the points (x, y).

        Parameters
        ----------
        x, y : array_like
            Coordinates; must broadcast against each other.

        Returns
        -------
        numpy.ndarray
            float64 values of shape ``np.broadcast(x, y).shape`` (also for
            constants). Computed under ``np.errstate(all="ignore")``, so
            overflow, division by zero or domain errors give inf or nan: the
            caller checks finiteness.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast_shapes(x.shape, y.shape)
        with np.errstate(all="ignore"):
            value = np.asarray(self._fn(x, y), dtype=np.float64)
        return np.array(np.broadcast_to(value, shape), dtype=np.float64)


def compile_expression(value: int | float | str) -> Expression:
    """Check a case-file value and turn it into an :class:`Expression`.

    The text is parsed with :func:`ast.parse`, every node is checked against a
    whitelist and the tree becomes nested closures over numpy ufuncs; the text
    never reaches Python's own evaluation.

    Parameters
    ----------
    value : int, float or str
        A finite number, or an expression in x and y using numbers, ``pi``,
        ``e``, ``+ - * / ** %``, unary ``+ -``, comparisons (1.0 if true, 0.0
        if false) and the functions sin cos tan arcsin arccos arctan sinh cosh
        tanh exp log log10 log2 sqrt abs sign floor ceil (one argument),
        arctan2 hypot minimum maximum (two), where (three), plus the aliases
        asin acos atan atan2 min max.

    Returns
    -------
    Expression

    Raises
    ------
    ExpressionError
        For a boolean or other non-number non-string, a non-finite number, an
        empty, invalid, too long (> 1000 characters), too large (> 500 nodes)
        or too deeply nested (> 50 levels) text, or any construct outside the
        whitelist.
    """
    if isinstance(value, (bool, np.bool_)):
        raise ExpressionError("expected a number or an expression string, got a boolean")
    if isinstance(value, (int, float, np.integer, np.floating)):
        fn = _constant(value)
        return Expression(str(value), True, frozenset(), fn)
    if not isinstance(value, str):
        got = "None" if value is None else type(value).__name__
        raise ExpressionError(f"expected a number or an expression string, got {got}")
    text = " ".join(value.split())
    tree = _parse(text)
    variables: set[str] = set()
    fn = _build(tree, variables)
    return Expression(text, not variables, frozenset(variables), fn)


#: The functions that are steps (constant between integers), by their sympy names.
_STEPS = {"floor": "floor", "ceil": "ceiling"}
#: Why a step (floor, ceil) or a remainder (%) of x or y stops the derivation of the exact fields.
NO_DERIVATIVE = "cannot be differentiated (floor, ceil and % have no derivative)"


def step_without_derivative(expression: Expression) -> str | None:
    """Why ``expression`` cannot be differentiated, read from its text without sympy, or None.

    A call of floor or ceil on x or y is a step: its derivative is no function, so a
    manufactured displacement holding one gives no stress. The reason names the first
    such call as sympy would (``floor(x) cannot be differentiated ...``, ``ceil`` as
    ``ceiling``). A ``%`` is left to the derivation (:mod:`contactfem.exact`), which also
    refuses a divisor that simplifies to zero.
    """
    if expression.is_constant:
        return None
    tree = _parse(expression.text)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _STEPS:
            argument = node.args[0]
            if any(isinstance(child, ast.Name) and child.id in _VARIABLES for child in ast.walk(argument)):
                text = ast.get_source_segment(expression.text, argument) or ast.unparse(argument)
                return f"{_STEPS[node.func.id]}({text}) {NO_DERIVATIVE}"
    return None


def _parse(text: str) -> ast.expr:
    """Parse normalised text into an expression tree, refusing what is empty, too long, too large or too deep."""
    if not text:
        raise ExpressionError("empty expression")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression is too long ({len(text)} characters, at most {MAX_LENGTH})")
    brackets = accumulate((c in "([{") - (c in ")]}") for c in text)
    if max(brackets) > MAX_DEPTH:
        raise ExpressionError(f"expression is nested too deeply (more than {MAX_DEPTH} levels)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"not a valid expression: {exc.msg}") from None
    except (RecursionError, ValueError, MemoryError, OverflowError) as exc:
        raise ExpressionError(f"not a valid expression: {exc or type(exc).__name__}") from None
    _check_size(tree.body)
    return tree.body


def _check_size(root: ast.AST) -> None:
    """Refuse trees with too many expression nodes or too deep nesting (iteratively)."""
    count, stack = 0, [(root, 1)]
    while stack:
        node, depth = stack.pop()
        count += isinstance(node, ast.expr)
        if count > MAX_NODES:
            raise ExpressionError(f"expression is too large (more than {MAX_NODES} terms and operations)")
        if depth > MAX_DEPTH:
            raise ExpressionError(f"expression is nested too deeply (more than {MAX_DEPTH} levels)")
        stack.extend((child, depth + isinstance(child, ast.expr)) for child in ast.iter_child_nodes(node))


def _constant(value: Any) -> _Fn:
    """A closure returning a finite float64 constant; refuse any other literal."""
    if isinstance(value, (bool, np.bool_)) or value is None:
        raise ExpressionError(f"{value} is not allowed; use a number")
    if isinstance(value, complex):
        raise ExpressionError("complex numbers are not allowed")
    if isinstance(value, (str, bytes)):
        raise ExpressionError("string literals are not allowed")
    if not isinstance(value, (int, float, np.integer, np.floating)):
        raise ExpressionError(f"constant {value!r} is not allowed")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if math.isnan(number):
        raise ExpressionError("nan is not allowed; use a finite number")
    if math.isinf(number):
        raise ExpressionError("number is infinite or too large for float64")
    constant = np.float64(number)
    return lambda x, y: constant


def _build(node: ast.AST, variables: set[str]) -> _Fn:
    """Check one node against the whitelist and return its closure ``f(x, y)``."""
    if isinstance(node, ast.Constant):
        return _constant(node.value)
    if isinstance(node, ast.Name):
        name = node.id
        if name in _VARIABLES:
            variables.add(name)
            return (lambda x, y: x) if name == "x" else (lambda x, y: y)
        if name in _CONSTANTS:
            return _constant(_CONSTANTS[name])
        if name in _FUNCTIONS:
            raise ExpressionError(f"'{name}' is a function; call it as {name}(...)")
        raise ExpressionError(f"name {name!r} is not allowed; use x, y, pi, e")
    if isinstance(node, ast.BinOp):
        op = _operator(node.op, _BINARY)
        left, right = _build(node.left, variables), _build(node.right, variables)
        return lambda x, y: op(left(x, y), right(x, y))
    if isinstance(node, ast.UnaryOp):
        op = _operator(node.op, _UNARY)
        operand = _build(node.operand, variables)
        return lambda x, y: op(operand(x, y))
    if isinstance(node, ast.Compare):
        ops = [_operator(op, _COMPARE) for op in node.ops]
        first = _build(node.left, variables)
        rest = [_build(child, variables) for child in node.comparators]

        def compare(x: np.ndarray, y: np.ndarray) -> np.ndarray:
            left, result = first(x, y), np.True_
            for op, fn in zip(ops, rest):
                right = fn(x, y)
                result, left = np.logical_and(result, op(left, right)), right
            return np.asarray(result, dtype=np.float64)

        return compare
    if isinstance(node, ast.Call):
        return _call(node, variables)
    raise ExpressionError(_REFUSED.get(type(node), f"{type(node).__name__} is not allowed"))


def _operator(op: ast.AST, allowed: dict[type, Callable[..., Any]]) -> Callable[..., Any]:
    """The numpy ufunc for an allowed operator."""
    if type(op) not in allowed:
        raise ExpressionError(f"operator '{_SYMBOLS.get(type(op), type(op).__name__)}' is not allowed")
    return allowed[type(op)]


def _call(node: ast.Call, variables: set[str]) -> _Fn:
    """Check a call of a whitelisted function with the right number of positional arguments."""
    if not isinstance(node.func, ast.Name):
        _build(node.func, variables)  # raises for attributes, subscripts, ...
        raise ExpressionError("only named functions can be called, e.g. sin(x)")
    name = node.func.id
    if name not in _FUNCTIONS:
        if name in _VARIABLES or name in _CONSTANTS:
            raise ExpressionError(f"'{name}' is not a function")
        raise ExpressionError(f"function {name!r} is not allowed; use {_CANONICAL}")
    if node.keywords:
        raise ExpressionError(f"keyword arguments are not allowed (in {name}())")
    if any(isinstance(arg, ast.Starred) for arg in node.args):
        raise ExpressionError(f"starred arguments are not allowed (in {name}())")
    function, arity = _FUNCTIONS[name]
    if len(node.args) != arity:
        plural = "s" if arity > 1 else ""
        raise ExpressionError(f"{name}() takes {arity} argument{plural}, got {len(node.args)}")
    args = [_build(arg, variables) for arg in node.args]
    return lambda x, y: function(*[arg(x, y) for arg in args])


# --------------------------------------------------------------------------- to sympy


def sympy_symbols() -> tuple[Any, Any]:
    """The sympy symbols x and y (real) that :func:`to_sympy` uses."""
    import sympy

    return sympy.Symbol("x", real=True), sympy.Symbol("y", real=True)


def to_sympy(expression: Expression) -> Any:
    """The sympy form of a checked expression, through the same whitelisted tree.

    ``expression.text`` is parsed again and checked node by node by the same rules as
    :func:`compile_expression`; each node is then mapped to its sympy counterpart. The
    text never reaches ``eval``, ``sympify`` or ``lambdify``.

    Integers become ``Integer``; floats the exact rational of their shortest decimal
    form (``0.1`` → 1/10), so ``x**0.5`` is ``sqrt(x)``. ``pi``, ``e`` are ``pi``, ``E``.
    ``hypot(a, b)`` is ``sqrt(a**2 + b**2)``, ``log10``/``log2`` are ``log(a)/log(10|2)``,
    ``minimum``/``maximum`` are ``Min``/``Max``, ``abs`` is ``Abs``, ``ceil`` is
    ``ceiling``. A comparison used as a value is ``Piecewise((1, rel), (0, True))`` (the
    1.0/0.0 of the numeric form); ``where(c, a, b)`` is ``Piecewise((a, c), (b, True))``
    with ``c`` the relational (a chain ``a < b < c`` is an ``And``), or ``Ne(c, 0)`` when
    ``c`` is not a comparison.

    Returns
    -------
    sympy.Expr
        In the real symbols of :func:`sympy_symbols`.

    Raises
    ------
    ExpressionError
        If the text is refused by the checker (it cannot be, for an Expression made by
        :func:`compile_expression`).
    """
    import sympy

    tree = _parse(expression.text)
    _build(tree, set())  # the same whitelist as the numeric form, before any mapping
    try:
        return _Sympy(sympy, *sympy_symbols()).value(tree)
    except (ArithmeticError, RecursionError) as error:  # sympy's exact arithmetic on numbers
        raise ExpressionError(f"{error or type(error).__name__} in {expression.text!r}") from None


def _sympy_power(s: Any) -> Callable[[Any, Any], Any]:
    """sympy's Pow, refusing a number raised to a number whose value is beyond float64.

    sympy evaluates integer powers exactly, so ``9**9**9`` would build a number of 370
    million digits (minutes and gigabytes); the numeric form gives inf for it anyway.
    """

    def power(a: Any, b: Any) -> Any:
        if getattr(a, "is_Number", False) and getattr(b, "is_Number", False) and a != 0:
            magnitude = float(b) * math.log10(abs(float(a))) if abs(float(a)) not in (0.0, math.inf) else math.inf
            if not math.isfinite(magnitude) or abs(magnitude) > 308:
                raise ExpressionError(f"number {a}**{b} is outside the range of float64")
        return s.Pow(a, b)

    return power


def _sympy_modulo(s: Any) -> Callable[[Any, Any], Any]:
    """sympy's Mod, refusing a divisor that is zero once sympy has simplified it (``x % (y-y)``)."""

    def modulo(a: Any, b: Any) -> Any:
        if getattr(b, "is_zero", False):
            raise ExpressionError(f"modulo by zero ({a} % {b})")
        return s.Mod(a, b)

    return modulo


class _Sympy:
    """Maps checked ast nodes to sympy objects (only the whitelisted node types)."""

    def __init__(self, sympy: Any, x: Any, y: Any) -> None:
        self.s = sympy
        self.names = {"x": x, "y": y, "pi": sympy.pi, "e": sympy.E}
        s = sympy
        self.binary = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b,
                       ast.Mult: lambda a, b: a * b, ast.Div: lambda a, b: a / b,
                       ast.Pow: _sympy_power(s), ast.Mod: _sympy_modulo(s)}
        self.compare = {ast.Lt: s.Lt, ast.LtE: s.Le, ast.Gt: s.Gt, ast.GtE: s.Ge, ast.Eq: s.Eq, ast.NotEq: s.Ne}
        self.functions: dict[str, Callable[..., Any]] = {
            "sin": s.sin, "cos": s.cos, "tan": s.tan, "arcsin": s.asin, "arccos": s.acos, "arctan": s.atan,
            "sinh": s.sinh, "cosh": s.cosh, "tanh": s.tanh, "exp": s.exp, "log": s.log,
            "log10": lambda a: s.log(a, 10), "log2": lambda a: s.log(a, 2), "sqrt": s.sqrt,
            "abs": s.Abs, "sign": s.sign, "floor": s.floor, "ceil": s.ceiling, "arctan2": s.atan2,
            "hypot": lambda a, b: s.sqrt(a**2 + b**2), "minimum": s.Min, "maximum": s.Max,
        }

    def value(self, node: ast.AST) -> Any:
        s = self.s
        if isinstance(node, ast.Constant):
            _constant(node.value)  # refuses what the numeric form refuses
            if isinstance(node.value, (int, np.integer)):
                return s.Integer(int(node.value))
            return s.Rational(repr(float(node.value)))
        if isinstance(node, ast.Name) and node.id in self.names:
            return self.names[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in self.binary:
            return self.binary[type(node.op)](self.value(node.left), self.value(node.right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            operand = self.value(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.Compare):
            return s.Piecewise((s.Integer(1), self.condition(node)), (s.Integer(0), True))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS:
            name = _ALIASES.get(node.func.id, node.func.id)
            if name == "where":
                condition, if_true, if_false = node.args
                return s.Piecewise((self.value(if_true), self.condition(condition)), (self.value(if_false), True))
            return self.functions[name](*[self.value(arg) for arg in node.args])
        raise ExpressionError(_REFUSED.get(type(node), f"{type(node).__name__} is not allowed"))

    def condition(self, node: ast.AST) -> Any:
        """A relational (an And of them for a chain), or ``value != 0`` for any other node."""
        s = self.s
        if isinstance(node, ast.Compare) and all(type(op) in self.compare for op in node.ops):
            operands = [self.value(node.left), *(self.value(c) for c in node.comparators)]
            relations = [self.compare[type(op)](a, b) for op, a, b in zip(node.ops, operands, operands[1:])]
            return s.And(*relations)
        return s.Ne(self.value(node), 0)
