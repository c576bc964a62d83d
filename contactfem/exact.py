"""Manufactured solutions: an exact displacement in sympy and everything derived from it.

:class:`ExactSolution` takes u = (u_x, u_y) as sympy expressions in the real symbols x, y
(:func:`contactfem.expressions.sympy_symbols`) and the Lamé parameters of the plane law,
and derives, once and by plain ``sympy.diff`` (no ``simplify``):

- the gradient ∇u, [a, b] = ∂u_a/∂x_b, the strain ε = (∇u + ∇uᵀ)/2,
- the stress σ = λ tr ε I + 2 μ ε (λ the plane law's: ``Elasticity.lam``),
- the body force f = −div σ,
- for the obstacle normal n (pointing into the obstacle) and t = (−n_y, n_x): the normal
  displacement u_n = u·n, the contact pressure p = −n·σ n and the tangential traction
  σ_t = t·σ n.

Derivatives are classical, taken piecewise: ``where``/``Piecewise`` branches are
differentiated separately and the Dirac deltas that ``Abs``/``sign`` produce are evaluated
as 0, so a displacement whose gradient jumps across a curve (which would need a line
load there) is not reproduced. ``floor``, ``ceil`` and ``%`` cannot be differentiated
and are refused.

Numerical values come from :class:`Program`, a small evaluator that walks the sympy
trees (shared subexpressions once) with numpy ufuncs: no ``lambdify``, no generated code.

A case's ``exact:`` block holds only the checked expressions (the reader derives
nothing); :func:`exact_solution` derives its fields where they are used, once per case.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Sequence

import numpy as np
import sympy
from sympy.core.relational import Relational

from contactfem.assembly import Elasticity
from contactfem.case.messages import CANNOT_DERIVE, refusal, shortened
from contactfem.case.model import Case, ExactBlock
from contactfem.expressions import NO_DERIVATIVE, Expression, ExpressionError, sympy_symbols, to_sympy

__all__ = ["ExactSolution", "Program", "evaluate", "exact_solution"]

#: The most nodes the four entries of ∇u may hold together (sympy's expression trees,
#: shared subtrees counted at each use). Deriving σ and f = −div σ costs about the square
#: of the gradient's size: at this bound about two seconds, where the manufactured
#: solutions of cases/ need under 200 and a balanced product of 60 factors (500
#: characters of expression) would take a minute or more.
MAX_GRADIENT_SIZE = 3000


# --------------------------------------------------------------------------- the evaluator


def _reduce(ufunc: Callable[..., Any]) -> Callable[..., Any]:
    return lambda *args: functools.reduce(ufunc, args)


def _heaviside(x: Any, at_zero: Any = 0.5) -> Any:
    return np.heaviside(x, at_zero)


def _power(base: Any, exponent: Any) -> Any:
    if np.ndim(exponent) == 0:
        if exponent == 0.5:
            return np.sqrt(base)
        if exponent == -1.0:
            return np.reciprocal(np.asarray(base, dtype=np.float64))
    return np.power(np.asarray(base, dtype=np.float64), exponent)


def _piecewise(*pairs: Any) -> Any:
    values, conditions = pairs[0::2], pairs[1::2]
    arrays = np.broadcast_arrays(*values, *conditions)
    n = len(values)
    chosen = np.select([np.asarray(c, dtype=bool) for c in arrays[n:]], arrays[:n], default=np.nan)
    return chosen


_FUNCTIONS: dict[Any, Callable[..., Any]] = {
    sympy.Add: _reduce(np.add),
    sympy.Mul: _reduce(np.multiply),
    sympy.Pow: _power,
    sympy.sin: np.sin, sympy.cos: np.cos, sympy.tan: np.tan,
    sympy.cot: lambda a: 1.0 / np.tan(a), sympy.sec: lambda a: 1.0 / np.cos(a), sympy.csc: lambda a: 1.0 / np.sin(a),
    sympy.asin: np.arcsin, sympy.acos: np.arccos, sympy.atan: np.arctan, sympy.atan2: np.arctan2,
    sympy.sinh: np.sinh, sympy.cosh: np.cosh, sympy.tanh: np.tanh,
    sympy.asinh: np.arcsinh, sympy.acosh: np.arccosh, sympy.atanh: np.arctanh,
    sympy.exp: np.exp, sympy.log: np.log,
    sympy.Abs: np.abs, sympy.sign: np.sign, sympy.floor: np.floor, sympy.ceiling: np.ceil,
    sympy.Mod: np.mod,
    sympy.Min: _reduce(np.minimum), sympy.Max: _reduce(np.maximum),
    sympy.Heaviside: _heaviside,
    # The classical (pointwise) derivative: the delta's mass on a null set is dropped.
    sympy.DiracDelta: lambda a, *order: np.zeros_like(np.asarray(a, dtype=np.float64)),
    sympy.Piecewise: _piecewise,
    sympy.And: _reduce(np.logical_and), sympy.Or: _reduce(np.logical_or), sympy.Not: np.logical_not,
    sympy.StrictLessThan: np.less, sympy.LessThan: np.less_equal,
    sympy.StrictGreaterThan: np.greater, sympy.GreaterThan: np.greater_equal,
    sympy.Equality: np.equal, sympy.Unequality: np.not_equal,
}


def _tree_size(expressions: Any, limit: int) -> int:
    """The number of nodes in the expression trees, counted up to just past ``limit``."""
    count = 0
    for expression in expressions:
        for _ in sympy.preorder_traversal(expression):
            count += 1
            if count > limit:
                return count
    return count


def _brief(value: Any, limit: int = 60) -> str:
    text = str(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _as_sympy(value: Any) -> Any:
    """A sympy object from a sympy object or a Python number; text is refused (never parsed)."""
    if isinstance(value, sympy.Basic):
        return value
    if isinstance(value, (bool, np.bool_)):
        return sympy.true if value else sympy.false
    if isinstance(value, (int, np.integer)):
        return sympy.Integer(int(value))
    if isinstance(value, (float, np.floating)):
        return sympy.Float(float(value))
    raise TypeError(f"expected a sympy expression or a number, got {type(value).__name__}")


def _number(expr: Any) -> float:
    if expr in (sympy.zoo, sympy.nan):
        return np.nan
    if expr is sympy.oo:
        return np.inf
    if expr is sympy.S.NegativeInfinity:
        return -np.inf
    if not expr.is_real:
        raise ExpressionError(f"the value {expr} is not a real number")
    try:
        return float(expr)
    except OverflowError:
        return np.inf if expr > 0 else -np.inf


class Program:
    """Sympy expressions in x and y, compiled once into a list of numpy operations.

    Every distinct subexpression becomes one slot, computed once per call (the derived
    fields share most of their subtrees). Supported: numbers (Integer, Rational, Float,
    pi, E, and zoo/nan/±oo as nan/±inf), the symbols x and y, Add, Mul, Pow, the
    functions of :data:`_FUNCTIONS` (trigonometric and hyperbolic with inverses, exp,
    log, Abs, sign, floor, ceiling, Mod, Min, Max, atan2, Heaviside, DiracDelta as 0),
    Piecewise, relationals, And/Or/Not and true/false.

    Raises
    ------
    ExpressionError
        At construction, for anything else (an unevaluated ``Derivative``, other
        symbols, complex numbers), naming it.
    """

    def __init__(self, expressions: Sequence[Any], x: Any | None = None, y: Any | None = None) -> None:
        sx, sy = sympy_symbols()
        self._x, self._y = (x if x is not None else sx), (y if y is not None else sy)
        self._slots: dict[Any, int] = {}
        self._steps: list[tuple[str, Any, tuple[int, ...]]] = []
        self._outputs = [self._compile(_as_sympy(e)) for e in expressions]

    def _compile(self, root: Any) -> int:
        # Iterative post-order walk, so deep trees do not hit the recursion limit.
        stack = [(root, False)]
        while stack:
            expr, children_done = stack.pop()
            if expr in self._slots:
                continue
            if not expr.is_Atom and expr.func not in _FUNCTIONS:
                self._step(expr, ())  # refuses it, naming it, before its arguments are looked at
            args = self._arguments(expr)
            if not children_done:
                stack.append((expr, True))
                stack.extend((a, False) for a in args if a not in self._slots)
                continue
            self._slots[expr] = len(self._steps)
            self._steps.append(self._step(expr, args))
        return self._slots[root]

    def _arguments(self, expr: Any) -> tuple[Any, ...]:
        if isinstance(expr, sympy.Piecewise):
            return tuple(part for pair in expr.args for part in pair)  # (e1, c1, e2, c2, ...)
        if expr.is_Atom:
            return ()
        return tuple(expr.args)

    def _step(self, expr: Any, args: tuple[Any, ...]) -> tuple[str, Any, tuple[int, ...]]:
        if expr == self._x:
            return ("x", None, ())
        if expr == self._y:
            return ("y", None, ())
        if expr is sympy.true or expr is sympy.false:
            return ("constant", bool(expr), ())
        if isinstance(expr, sympy.Symbol):
            raise ExpressionError(f"the symbol {expr} is not x or y")
        if expr.is_Atom and (expr.is_number or expr in (sympy.zoo, sympy.nan)):
            return ("constant", _number(expr), ())
        function = _FUNCTIONS.get(expr.func)
        if function is None:
            if isinstance(expr, sympy.Derivative):
                raise ExpressionError(f"{expr.expr} {NO_DERIVATIVE}")
            if isinstance(expr, Relational):  # other relational subclasses
                raise ExpressionError(f"the relation {expr} is not supported")
            raise ExpressionError(f"{type(expr).__name__} ({expr}) cannot be evaluated")
        return ("call", function, tuple(self._slots[a] for a in args))

    def __call__(self, x: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
        """The expressions at the points (x, y): float64 arrays of the broadcast shape.

        Computed under ``np.errstate(all="ignore")``: the caller checks finiteness.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast_shapes(x.shape, y.shape)
        values: list[Any] = []
        with np.errstate(all="ignore"):
            for kind, payload, args in self._steps:
                if kind == "x":
                    values.append(x)
                elif kind == "y":
                    values.append(y)
                elif kind == "constant":
                    values.append(payload)
                else:
                    values.append(payload(*[values[i] for i in args]))
        return [np.array(np.broadcast_to(np.asarray(values[i], dtype=np.float64), shape)) for i in self._outputs]


def evaluate(expression: Any, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """One sympy expression in x, y at the points (x, y) (see :class:`Program`)."""
    return Program([expression])(x, y)[0]


# --------------------------------------------------------------------------- the solution


class ExactSolution:
    """An exact displacement and its derived fields, symbolic once and vectorised on arrays.

    Parameters
    ----------
    ux, uy : sympy.Expr
        The displacement in the real symbols x, y of :func:`sympy_symbols`.
    lam, mu : float
        Lamé parameters of the plane law (``Elasticity.lam`` and ``.mu``: in plane stress
        ``lam`` is already the reduced 2λμ/(λ+2μ)).
    obstacle_normal : (2,) array_like, optional
        Unit normal pointing into the obstacle; needed by :meth:`pressure`,
        :meth:`tangential_traction` and :meth:`normal_displacement`.

    Attributes
    ----------
    u : (2,) tuple, grad : 2×2 sympy.Matrix, stress_matrix : 2×2 sympy.Matrix, force : (2,)
    tuple, and with a normal: normal_u, pressure_expr, tangential_expr.

    Raises
    ------
    ExpressionError
        If u holds a non-finite number (zoo, nan, ±oo), ∇u has more than
        :data:`MAX_GRADIENT_SIZE` nodes, or a derived field cannot be evaluated
        numerically (see :class:`Program`).
    """

    def __init__(self, ux: Any, uy: Any, lam: float, mu: float,
                 obstacle_normal: Sequence[float] | None = None) -> None:
        x, y = sympy_symbols()
        self.x, self.y = x, y
        self.lam, self.mu = float(lam), float(mu)
        self.u = (_as_sympy(ux), _as_sympy(uy))
        extra = (self.u[0].free_symbols | self.u[1].free_symbols) - {x, y}
        if extra:
            raise ExpressionError(f"the displacement uses symbols other than x, y: {sorted(map(str, extra))}")
        for name, component in zip(("u_x", "u_y"), self.u):
            if component.has(sympy.zoo, sympy.nan, sympy.oo, sympy.S.NegativeInfinity):
                raise ExpressionError(f"{name} = {_brief(component)} is not finite (a division by zero or "
                                      "log(0) among its numbers)")
        lam_s, mu_s = sympy.Float(self.lam), sympy.Float(self.mu)
        self.grad = sympy.Matrix(2, 2, lambda a, b: sympy.diff(self.u[a], (x, y)[b]))
        if _tree_size(self.grad, MAX_GRADIENT_SIZE) > MAX_GRADIENT_SIZE:
            raise ExpressionError(
                f"the displacement's gradient has more than {MAX_GRADIENT_SIZE} terms, too many to derive the "
                "stress and body force in reasonable time; expected a simpler manufactured solution")
        strain = (self.grad + self.grad.T) / 2
        self.stress_matrix = lam_s * strain.trace() * sympy.eye(2) + 2 * mu_s * strain
        self.force = tuple(
            -(sympy.diff(self.stress_matrix[a, 0], x) + sympy.diff(self.stress_matrix[a, 1], y)) for a in range(2)
        )
        self._displacement = Program(self.u)
        self._gradient = Program(list(self.grad))
        self._stress = Program(list(self.stress_matrix))
        self._force = Program(self.force)
        self.normal: np.ndarray | None = None
        if obstacle_normal is not None:
            n = np.asarray(obstacle_normal, dtype=float)
            self.normal = n
            ns = sympy.Matrix([sympy.Float(n[0]), sympy.Float(n[1])])
            ts = sympy.Matrix([-ns[1], ns[0]])
            self.normal_u = (sympy.Matrix(self.u).T * ns)[0]
            self.pressure_expr = -(ns.T * self.stress_matrix * ns)[0]
            self.tangential_expr = (ts.T * self.stress_matrix * ns)[0]
            self._contact = Program([self.normal_u, self.pressure_expr, self.tangential_expr])

    @classmethod
    def from_expressions(cls, displacement: Sequence[Expression], lam: float, mu: float,
                         obstacle_normal: Sequence[float] | None = None) -> "ExactSolution":
        """From two checked case-file expressions, converted by :func:`to_sympy`."""
        ux, uy = (to_sympy(e) for e in displacement)
        try:
            return cls(ux, uy, lam, mu, obstacle_normal)
        except (ArithmeticError, TypeError, ValueError, RecursionError) as error:
            # sympy's own failures on odd input (exact arithmetic, undefined products)
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise ExpressionError(f"sympy cannot derive it ({type(error).__name__}: {_brief(reason)})") from None

    # All methods take x, y broadcasting against each other; the leading shape is theirs.

    def displacement(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """u (..., 2)."""
        return np.stack(self._displacement(x, y), axis=-1)

    def gradient(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """∇u (..., 2, 2), [a, b] = ∂u_a/∂x_b."""
        values = self._gradient(x, y)
        return np.stack(values, axis=-1).reshape(*values[0].shape, 2, 2)

    def stress(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """σ (..., 2, 2)."""
        values = self._stress(x, y)
        return np.stack(values, axis=-1).reshape(*values[0].shape, 2, 2)

    def body_force(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """f = −div σ (..., 2)."""
        return np.stack(self._force(x, y), axis=-1)

    def traction(self, x: np.ndarray, y: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """σ n (..., 2) for the outward unit normal ``normal`` (2,) or (..., 2)."""
        return np.einsum("...ab,...b->...a", self.stress(x, y), np.asarray(normal, dtype=float))

    def _contact_values(self, x: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
        if self.normal is None:
            raise ValueError("this ExactSolution was built without an obstacle normal")
        return self._contact(x, y)

    def normal_displacement(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """u·n (...), n the obstacle normal."""
        return self._contact_values(x, y)[0]

    def pressure(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Contact pressure −σ_n = −n·σ n (...), n the obstacle normal (≥ 0 where the body presses)."""
        return self._contact_values(x, y)[1]

    def tangential_traction(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """σ_t = t·σ n (...), t = (−n_y, n_x); zero on ΓC for frictionless contact."""
        return self._contact_values(x, y)[2]


# --------------------------------------------------------------------------- a case's exact block


def exact_solution(case: Case) -> ExactSolution | None:
    """The fields derived from ``case``'s ``exact:`` block, or None without one.

    Derived on first use with the case's plane law and obstacle normal, and kept with the
    block (``ExactBlock.derived``): every later call for the case returns the same object.

    Raises
    ------
    CaseError
        ``file: exact.displacement = [...]: cannot derive the stress and body force: ...``
        when sympy cannot derive or evaluate the fields (see :class:`ExactSolution`).
    """
    if case.exact is None:
        return None
    return _derived(case.exact, shortened(case.source.name))


def _derived(block: ExactBlock, filename: str = "<case>") -> ExactSolution:
    solution = block.derived.get("solution")
    if solution is None:
        material = block.material
        law = Elasticity.from_lame(material.lame_lambda, material.lame_mu, material.plane)
        try:
            solution = ExactSolution.from_expressions(block.displacement, law.lam, law.mu, block.normal)
        except ExpressionError as error:
            texts = [e.text for e in block.displacement]
            raise refusal(filename, "exact.displacement", texts, f"{CANNOT_DERIVE}: {error}") from None
        block.derived["solution"] = solution
    return solution


# ExactBlock.solution, for callers that read the fields from the block, derives them here.
ExactBlock.builder = _derived
