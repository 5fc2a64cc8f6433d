"""The expressions a model file holds, as JSON trees of sympy's operations.

:func:`expression_to_json` writes an expression node by node;
:func:`expression_from_json` reads one back from a fixed list of operations,
functions and constants (:data:`OPERATIONS`, :data:`FUNCTIONS`,
:data:`CONSTANTS`), never through ``eval``, checking its depth, its nodes
and the digits of its numbers, and the size of any power of numbers sympy
would compute, before sympy evaluates anything (:data:`EXPRESSION_LIMITS`).
Floats keep all their digits. A tree that is not such an expression is a
:class:`~bench.core.modelfile.ModelFileError` naming its file.

Its own module so that reading a model file's container
(:mod:`bench.core.modelfile`) does not import sympy.
"""

from __future__ import annotations

import math

import numpy as np
import sympy

from bench.core.modelfile import ModelFileError

#: the sympy functions an expression in a model file may hold, by name
FUNCTIONS = {f.__name__: f for f in (sympy.sin, sympy.cos, sympy.tan, sympy.exp, sympy.log, sympy.sign, sympy.Abs,
                                     sympy.tanh, sympy.sinh, sympy.cosh, sympy.atan, sympy.asin, sympy.acos,
                                     sympy.Heaviside, sympy.erf)}
#: the operations, by name
OPERATIONS = {"Add": sympy.Add, "Mul": sympy.Mul, "Pow": sympy.Pow}
#: the assumptions a symbol keeps (the suite's coordinates are real)
ASSUMPTIONS = ("real", "positive", "nonnegative", "integer")
#: the constants, by name
CONSTANTS = {"pi": sympy.pi, "E": sympy.E}


def expression_to_json(expr) -> object:
    """``expr`` (sympy) as a JSON tree: ``{"op": name, "args": [...]}`` for an
    operation or function, ``{"symbol": name}`` (with the :data:`ASSUMPTIONS` it was made with), ``{"int": "12"}``,
    ``{"rational": ["1", "3"]}``, ``{"float": "0.1"}`` (Python's shortest
    repr, exact for a double) or ``{"constant": "pi"}``. A ``ValueError`` names
    what it cannot write."""
    expr = sympy.sympify(expr)
    if isinstance(expr, sympy.Symbol):
        given = {k: bool(v) for k, v in expr._assumptions_orig.items() if k in ASSUMPTIONS and v is not None}
        return {"symbol": expr.name, **({"assumptions": given} if given else {})}
    if isinstance(expr, sympy.Integer):
        return {"int": str(int(expr))}
    if isinstance(expr, sympy.Rational):
        return {"rational": [str(expr.p), str(expr.q)]}
    if isinstance(expr, sympy.Float):
        value = float(expr)
        if not np.isfinite(value):  # its decimal digits are not written: a float of 10^(10^9) takes hours to print
            sign, mantissa, exponent, bits = expr._mpf_
            size = f"about 10^{(exponent + bits) * math.log10(2):.0f}" if mantissa else "infinite"
            raise ValueError(f"the expression holds a float {size}, beyond a double")
        if sympy.Float(value) != expr:
            raise ValueError(f"the expression holds {expr}, which a double cannot hold exactly")
        return {"float": repr(value)}
    for name, value in CONSTANTS.items():
        if expr == value:
            return {"constant": name}
    name = type(expr).__name__
    if name in OPERATIONS or name in FUNCTIONS:
        return {"op": name, "args": [expression_to_json(a) for a in expr.args]}
    if expr is sympy.nan or expr in (sympy.oo, -sympy.oo, sympy.zoo):
        raise ValueError(f"the expression holds {expr}, which is no number")
    raise ValueError(f"the expression holds {name} ({str(expr)[:60]}), which a model file cannot hold")


#: what an expression in a model file may hold: its depth, its nodes, the digits of one number written in it,
#: and the digits of all the numbers it holds or that sympy would compute from them (a power of two numbers is
#: computed when it is built; its digits are counted, and refused, before it is)
EXPRESSION_LIMITS = {"depth": 200, "nodes": 100_000, "digits": 40, "total_digits": 20_000}


def _digits(value) -> float:
    """Decimal digits of a sympy number's numerator and denominator (a float: its exponent's)."""
    if isinstance(value, sympy.Rational):
        return max(abs(int(value.p)), abs(int(value.q)), 1).bit_length() * math.log10(2) + 1
    if isinstance(value, sympy.Float):
        return abs(float(value._mpf_[2]) + float(value._mpf_[3])) * math.log10(2) + 1 if value._mpf_[1] else 1
    return 1.0


def expression_from_json(tree, source: str = "model") -> sympy.Expr:
    """The sympy expression of a tree from :func:`expression_to_json`, built
    node by node from :data:`OPERATIONS`, :data:`FUNCTIONS` and
    :data:`CONSTANTS` within :data:`EXPRESSION_LIMITS`; anything else is
    refused (:class:`ModelFileError`)."""
    limits = EXPRESSION_LIMITS
    count = {"nodes": 0, "digits": 0.0}

    def bad(why: str):
        return ModelFileError(f"{source}: not a model file (an expression {why})")

    def literal(text) -> str:
        text = str(text)
        if len(text) > limits["digits"] + 8:
            raise bad(f"writes a number of {len(text)} characters (at most {limits['digits']} digits)")
        spend(len(text))
        return text

    def spend(digits: float) -> None:
        count["digits"] += digits
        if count["digits"] > limits["total_digits"]:
            raise bad(f"holds numbers of more than {limits['total_digits']} digits in all")

    def power(base, exponent):
        if isinstance(base, sympy.Number) and isinstance(exponent, sympy.Rational) and not base.is_zero:
            spend(abs(float(exponent)) * _digits(base))  # what sympy computes, counted before it does
        return sympy.Pow(base, exponent)

    def build(node, depth: int):
        if depth > limits["depth"]:
            raise bad("is nested too deeply")
        count["nodes"] += 1
        if count["nodes"] > limits["nodes"]:
            raise bad(f"has more than {limits['nodes']} nodes")
        if not isinstance(node, dict) or not 1 <= len(node) <= 2:
            raise bad(f"node is {node!r:.80}")
        try:
            if "symbol" in node:
                name, given = node["symbol"], node.get("assumptions", {})
                if not isinstance(name, str) or not name.isidentifier():
                    raise bad(f"names the symbol {name!r:.40}")
                if not isinstance(given, dict) or set(given) - set(ASSUMPTIONS) or \
                        not all(isinstance(v, bool) for v in given.values()):
                    raise bad(f"gives the symbol {name} the assumptions {given!r:.60}")
                return sympy.Symbol(name, **given)
            if "int" in node:
                return sympy.Integer(int(literal(node["int"])))
            if "rational" in node:
                p, q = node["rational"]
                p, q = int(literal(p)), int(literal(q))
                if q == 0:
                    raise bad("divides by zero")
                return sympy.Rational(p, q)
            if "float" in node:
                value = float(literal(node["float"]))
                if not math.isfinite(value):
                    raise bad(f"holds the float {value}, which is no number")
                return sympy.Float(value)
            if "constant" in node:
                return CONSTANTS[node["constant"]]
            op = node.get("op")
            if not isinstance(op, str) or not isinstance(node.get("args", []), list):
                raise bad(f"node is {node!r:.80}")
            if op not in OPERATIONS and op not in FUNCTIONS:
                raise bad(f"holds {op!r:.40}, which is no operation a model file may hold")
            if count["nodes"] + len(node.get("args", [])) > limits["nodes"]:  # before any of them is built
                raise bad(f"has more than {limits['nodes']} nodes")
            args = [build(a, depth + 1) for a in node.get("args", [])]
            if op == "Pow":
                if len(args) != 2:
                    raise bad(f"raises to a power with {len(args)} arguments")
                return power(*args)
            return OPERATIONS[op](*args) if op in OPERATIONS else FUNCTIONS[op](*args)
        except ModelFileError:
            raise
        except (KeyError, TypeError, ValueError, ZeroDivisionError, AttributeError):
            raise bad(f"node is {node!r:.80}") from None

    return build(tree, 0)
