"""Tests of contactfem.expressions: values, refusals, resource limits and robustness on arbitrary text."""

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contactfem.errors import ContactFemError
from contactfem.expressions import Expression, ExpressionError, compile_expression

X = np.linspace(-0.3, 1.7, 11)
Y = np.linspace(0.2, 2.4, 11)

VALID = [
    ("-1e4*(1-1.5*x)", lambda x, y: -1e4 * (1 - 1.5 * x)),
    ("0.01*sin(pi*x)*exp(-y)", lambda x, y: 0.01 * np.sin(np.pi * x) * np.exp(-y)),
    ("where(x < 0.5, 1, 0)", lambda x, y: np.where(x < 0.5, 1.0, 0.0)),
    ("x**2 + y**2 - 2*x*y", lambda x, y: x**2 + y**2 - 2 * x * y),
    ("x % 0.3 + -y / 4 + +x", lambda x, y: np.mod(x, 0.3) - y / 4 + x),
    ("2**-x", lambda x, y: 2.0 ** (-x)),
    ("e**y - exp(y)", lambda x, y: np.e**y - np.exp(y)),
    ("cos(x)+tan(x)+sinh(x)+cosh(y)+tanh(y)", lambda x, y: np.cos(x) + np.tan(x) + np.sinh(x) + np.cosh(y) + np.tanh(y)),
    ("arcsin(x/2) + asin(x/2) + arccos(x/2) + acos(x/2)",
     lambda x, y: 2 * np.arcsin(x / 2) + 2 * np.arccos(x / 2)),
    ("arctan(x) + atan(y) + arctan2(y, x) + atan2(x, y)",
     lambda x, y: np.arctan(x) + np.arctan(y) + np.arctan2(y, x) + np.arctan2(x, y)),
    ("log(y) + log10(y) + log2(y) + sqrt(y)", lambda x, y: np.log(y) + np.log10(y) + np.log2(y) + np.sqrt(y)),
    ("abs(x) + sign(x) + floor(3*x) + ceil(3*x)",
     lambda x, y: np.abs(x) + np.sign(x) + np.floor(3 * x) + np.ceil(3 * x)),
    ("hypot(x, y) + minimum(x, y) + maximum(x, y) + min(x, 0) + max(y, 1)",
     lambda x, y: np.hypot(x, y) + np.minimum(x, y) + np.maximum(x, y)
     + np.minimum(x, 0) + np.maximum(y, 1)),
    ("0 < x <= 0.5", lambda x, y: ((0 < x) & (x <= 0.5)).astype(float)),
    ("(x == 0.1) + (x != 0.1) + (y >= 1) + (y > 1) + (x < y)",
     lambda x, y: 1.0 + (y >= 1) + (y > 1) + (x < y)),
    ("where(x > 0.5, where(y < 1, -1, 2*y), x)", lambda x, y: np.where(x > 0.5, np.where(y < 1, -1.0, 2 * y), x)),
    ("  3 *\n  x  ", lambda x, y: 3 * x),
]


@pytest.mark.parametrize("text, reference", VALID, ids=[t for t, _ in VALID])
def test_valid_expressions_match_numpy(text, reference):
    """Each valid expression evaluates to the numpy value, as float64 of the shape of x."""
    expr = compile_expression(text)
    with np.errstate(all="ignore"):
        expected = reference(X, Y)
        got = expr(X, Y)
    assert got.dtype == np.float64 and got.shape == X.shape
    np.testing.assert_allclose(got, expected, rtol=1e-14, atol=1e-14)


def test_flags_and_normalised_text():
    """variables/is_constant report which of x, y are used; text is whitespace-normalised."""
    assert compile_expression("sin(pi*x)").variables == frozenset({"x"})
    assert compile_expression("y + x").variables == frozenset({"x", "y"})
    constant = compile_expression("2*pi + e")
    assert constant.is_constant and constant.variables == frozenset()
    assert not compile_expression("0*y").is_constant
    assert compile_expression("  3 *\n  x  ").text == "3 * x"
    assert isinstance(compile_expression("x"), Expression)


@pytest.mark.parametrize("value, expected", [(3, 3.0), (-2.5, -2.5), ("1e4", 1e4), ("-3", -3.0),
                                             ("2*pi", 2 * np.pi), (np.float64(0.5), 0.5)])
def test_constants_broadcast_to_shape(value, expected):
    """Numbers and constant strings give a float64 array filled with the value, shaped like x and y."""
    expr = compile_expression(value)
    assert expr.is_constant
    got = expr(np.zeros((2, 3)), np.zeros((2, 3)))
    assert got.dtype == np.float64 and got.shape == (2, 3)
    assert np.all(got == expected)
    if not isinstance(value, str):
        assert expr.text == str(value)


def test_result_broadcasts_x_against_y_and_is_writable():
    """x of shape (3, 1) and y of shape (4,) give a (3, 4) result; scalars give a 0-d array."""
    got = compile_expression("x").__call__(np.arange(3.0)[:, None], np.arange(4.0))
    assert got.shape == (3, 4) and got.flags.writeable
    np.testing.assert_array_equal(got, np.repeat(np.arange(3.0)[:, None], 4, axis=1))
    assert compile_expression("x + y")(1.0, 2.0).shape == ()


def test_expression_error_is_a_contactfem_error():
    """ExpressionError belongs to the package's single error family."""
    assert issubclass(ExpressionError, ContactFemError)


REFUSED = [
    ("x.__class__", "attribute"),
    ("(1).real", "attribute"),
    ("__import__('os')", "function '__import__' is not allowed"),
    ("x[0]", "subscript"),
    ("lambda: 1", "lambda"),
    ("[i for i in x]", "comprehension"),
    ("sum(i for i in x)", "function 'sum'"),
    ("sin(x=1)", "keyword arguments"),
    ("sin(*x)", "starred"),
    ("z", "name 'z' is not allowed; use x, y, pi, e"),
    ("foo(x)", "function 'foo' is not allowed"),
    ("x(1)", "'x' is not a function"),
    ("sin", "'sin' is a function"),
    ("sin(x, y)", "sin() takes 1 argument, got 2"),
    ("atan2(x)", "atan2() takes 2 arguments, got 1"),
    ("where(x, y)", "where() takes 3 arguments, got 2"),
    ("'abc'", "string literal"),
    ("b'abc'", "string literal"),
    ("f'{x}'", "f-string"),
    ("1j", "complex"),
    ("True", "True is not allowed"),
    ("None", "None is not allowed"),
    ("x and y", "'and'/'or'"),
    ("not x", "'not'"),
    ("x if y else 1", "if-expression"),
    ("(z := 1)", "':='"),
    ("x // 2", "'//'"),
    ("x & y", "'&'"),
    ("x in y", "'in'"),
    ("x is y", "'is'"),
    ("[x, y]", "list"),
    ("(x, y)", "tuple"),
    ("{1: 2}", "dict"),
    ("1e400", "too large"),
    ("x +", "not a valid expression"),
    ("x = 1", "not a valid expression"),
    ("", "empty"),
    (" \n\t ", "empty"),
    ("x" * 1001, "too long"),
    ("(" * 200 + "x" + ")" * 200, "nested too deeply"),
    ("(" * 60 + "x" + ")" * 60, "nested too deeply"),
    ("-" * 400 + "x", "nested too deeply"),
    ("sin(" * 60 + "x" + ")" * 60, "nested too deeply"),
    ("+".join(["x*y"] * 60), "nested too deeply"),
    ("max(" + ",".join(["-x"] * 330) + ")", "too large"),
    ("\x00", "not a valid expression"),
]


@pytest.mark.parametrize("text, fragment", REFUSED, ids=[repr(t)[:40] for t, _ in REFUSED])
def test_refused_text_gives_helpful_one_line_message(text, fragment):
    """Each construct outside the whitelist (or over a limit) is refused with a short message saying what."""
    with pytest.raises(ExpressionError) as info:
        compile_expression(text)
    message = str(info.value)
    assert fragment in message
    assert "\n" not in message and len(message) < 250


@pytest.mark.parametrize("value, fragment", [
    (True, "got a boolean"), (np.bool_(False), "got a boolean"), (None, "got None"), ([1], "got list"),
    ({"a": 1}, "got dict"), (b"x", "got bytes"), (float("nan"), "nan"), (float("inf"), "infinite"),
    (-float("inf"), "infinite"), (10**400, "too large"),
])
def test_refused_values(value, fragment):
    """Booleans, None, containers and non-finite numbers are refused, naming what was given."""
    with pytest.raises(ExpressionError, match=fragment):
        compile_expression(value)


@pytest.mark.parametrize("text", ["9**9**9", "1e308*10", "9**9**9**9**9", "(10**400)**(10**400)", "exp(1e6)"])
def test_huge_arithmetic_returns_inf_quickly(text):
    """Huge powers and overflows are computed in float64: inf, quickly, with no Python big-int work."""
    start = time.perf_counter()
    expr = compile_expression(text)
    got = expr(np.zeros(4), np.zeros(4))
    assert time.perf_counter() - start < 0.5
    assert got.shape == (4,) and np.all(np.isposinf(got))


def test_invalid_operations_give_nan_or_inf_without_warnings():
    """Division by zero, log of negatives and nan comparisons give inf/nan silently (the caller checks)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = compile_expression("1/x + log(x - 1) + x % 0")(np.array([0.0, 0.5]), np.zeros(2))
    assert not np.any(np.isfinite(got))


TOKENS = ["x", "y", "pi", "e", "1", "2.5", "1e308", "0", "+", "-", "*", "/", "**", "%", "(", ")", ",", "<",
          "==", "sin(", "where(", "max(", "log(", "atan2(", "sqrt(", " ", "9", ".", "[", "]", "'", "_",
          "__import__(", "lambda", ":", "and", "if", "else", "=", "j", "x.", "__class__"]


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.text(max_size=60), st.lists(st.sampled_from(TOKENS), max_size=25).map("".join)))
def test_arbitrary_text_raises_only_expression_error(text):
    """Any text either compiles or raises ExpressionError; compiled ones evaluate to float64 of the right shape."""
    try:
        expr = compile_expression(text)
    except ExpressionError:
        return
    got = expr(np.linspace(0.0, 1.0, 3)[:, None], np.linspace(-1.0, 2.0, 2))
    assert got.dtype == np.float64 and got.shape == (3, 2)
