"""A fitted model to keep: one file that loads without running code from it.

The file is a NumPy ``.npz`` archive (read with ``allow_pickle=False``): its
arrays are the model's parameters, and one entry, ``model.json``, says what
the model is, in JSON: its kind, the method and hyperparameters it was fitted
with, its system and joints, where its arrays are, and, for a model with laws
or an expression, each expression as a tree of sympy's operations
(:func:`expression_to_json`) that :func:`expression_from_json` reads back
node by node from a fixed list of operations and functions, never through
``eval``. Floats keep all their digits, so a loaded model predicts what the
fitted one did to round-off.

A model says how it is saved (:meth:`~bench.physics.models.FittedModel.saved`:
a kind and a JSON tree holding :class:`Packer` references to arrays), and
each kind has a loader (:data:`LOADERS`, :func:`loader`), registered beside
the model it loads. A file that is not such a model, is truncated or does not
parse is refused in one line naming it (:class:`ModelFileError`).
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np
import sympy
import torch

from bench.core.errors import UserError
from bench.core.fileio import atomic_write
from bench.core.registry import Registry

#: the format a model file says it is in
FORMAT = "syrenets-bench/model/1"
#: the archive entry that holds the model's description
HEADER = "model.json"


class ModelFileError(UserError):
    """A file that is not a model this suite saved, or cannot be read as one; the message names the file."""


# -- arrays ----------------------------------------------------------------------------------

class Packer:
    """Collects a model's arrays while its tree is written: :meth:`array` puts
    one in and gives the reference the tree holds."""

    def __init__(self):
        self.arrays: dict[str, np.ndarray] = {}

    def array(self, value) -> dict:
        name = f"a{len(self.arrays)}"
        self.arrays[name] = np.ascontiguousarray(np.asarray(value))
        return {"$array": name}

    def tensors(self, state: dict) -> dict:
        """A torch ``state_dict`` as references (each tensor as an array, its dtype kept)."""
        return {k: self.array(v.detach().cpu().numpy()) for k, v in state.items()}


class Unpacker:
    """The arrays of a file being loaded, by reference, each checked to exist."""

    def __init__(self, arrays: dict[str, np.ndarray], source: str):
        self.arrays, self.source = arrays, source

    def array(self, ref) -> np.ndarray:
        if not isinstance(ref, dict) or not isinstance(ref.get("$array"), str):
            raise ModelFileError(f"{self.source}: not a model file (an array reference is {ref!r:.80})")
        try:
            return self.arrays[ref["$array"]]
        except KeyError:
            raise ModelFileError(f"{self.source}: not a model file (its array {ref['$array']} is missing)") from None

    def tensors(self, refs: dict) -> dict:
        return {k: torch.from_numpy(np.array(self.array(v))) for k, v in refs.items()}


# -- expressions -----------------------------------------------------------------------------

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


def expression_from_json(tree, source: str = "model") -> sympy.Expr:
    """The sympy expression of a tree from :func:`expression_to_json`, built
    node by node from :data:`OPERATIONS`, :data:`FUNCTIONS` and
    :data:`CONSTANTS`; anything else is refused (:class:`ModelFileError`)."""
    def bad(why: str):
        return ModelFileError(f"{source}: not a model file (an expression {why})")

    def build(node, depth: int):
        if depth > 200:
            raise bad("is nested too deeply")
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
                return sympy.Integer(int(str(node["int"])))
            if "rational" in node:
                p, q = node["rational"]
                return sympy.Rational(int(str(p)), int(str(q)))
            if "float" in node:
                return sympy.Float(float(str(node["float"])))
            if "constant" in node:
                return CONSTANTS[node["constant"]]
            op = node.get("op")
            args = [build(a, depth + 1) for a in node.get("args", [])]
        except ModelFileError:
            raise
        except (KeyError, TypeError, ValueError, ZeroDivisionError):
            raise bad(f"node is {node!r:.80}") from None
        if op in OPERATIONS:
            return OPERATIONS[op](*args)
        if op in FUNCTIONS:
            return FUNCTIONS[op](*args)
        raise bad(f"holds {op!r:.40}, which is no operation a model file may hold")

    return build(tree, 0)


# -- the file --------------------------------------------------------------------------------

#: how each kind of saved model is loaded: ``(tree, unpacker, context) -> FittedModel``
LOADERS: Registry[Callable] = Registry("kind of saved model")


def loader(kind: str):
    """Register the function that loads saved models of ``kind``."""
    return LOADERS.add(kind)


def save(path: str | Path, header: dict, model_tree: dict, packer: Packer) -> None:
    """Write a model file: ``header`` (what it was fitted with), the model's
    tree (:meth:`~bench.physics.models.FittedModel.saved`) and its arrays, atomically."""
    text = json.dumps({"format": FORMAT, **header, "model": model_tree}, indent=1, sort_keys=True)

    def write(f):
        with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED) as z:
            z.writestr(HEADER, text)
            for name, array in packer.arrays.items():
                buffer = io.BytesIO()
                np.save(buffer, array, allow_pickle=False)
                z.writestr(f"{name}.npy", buffer.getvalue())

    atomic_write(Path(path), write, binary=True)


def read(path: str | Path) -> tuple[dict, Unpacker]:
    """A model file's description and its arrays; :class:`ModelFileError` in one line otherwise."""
    source = str(path)
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            if HEADER not in names:
                raise ModelFileError(f"{source}: not a model file of this suite (no {HEADER} in it)")
            try:
                header = json.loads(z.read(HEADER).decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise ModelFileError(f"{source}: its {HEADER} does not parse ({exc})") from None
            if not isinstance(header, dict) or header.get("format") != FORMAT:
                raise ModelFileError(f"{source}: not a model file of this suite (format "
                                     f"{header.get('format') if isinstance(header, dict) else None!r}, not {FORMAT!r})")
            arrays = {}
            for name in names - {HEADER}:
                if not name.endswith(".npy"):
                    raise ModelFileError(f"{source}: not a model file of this suite (it holds {name!r:.60})")
                arrays[name[:-4]] = np.load(io.BytesIO(z.read(name)), allow_pickle=False)
    except ModelFileError:
        raise
    except FileNotFoundError:
        raise ModelFileError(f"{source}: no such file") from None
    except zipfile.BadZipFile:
        raise ModelFileError(f"{source}: not a model file of this suite (not a complete archive: truncated or "
                             f"another kind of file)") from None
    except (ValueError, EOFError, OSError, zipfile.LargeZipFile, NotImplementedError) as exc:
        raise ModelFileError(f"{source}: a model file that cannot be read ({type(exc).__name__}: {exc})"[:300]) from None
    if not isinstance(header.get("model"), dict):
        raise ModelFileError(f"{source}: not a model file of this suite (no model in it)")
    return header, Unpacker(arrays, source)


def build(tree: dict, unpacker: Unpacker, context: dict):
    """The fitted model a saved tree describes, by its kind's loader."""
    kind = tree.get("kind") if isinstance(tree, dict) else None
    if not isinstance(kind, str) or kind not in LOADERS:
        raise ModelFileError(f"{unpacker.source}: holds a model of kind {kind!r:.40}, which this suite cannot load "
                             f"(it loads {', '.join(LOADERS.names())})")
    try:
        return LOADERS[kind](tree, unpacker, context)
    except ModelFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, RuntimeError) as exc:
        raise ModelFileError(f"{unpacker.source}: its {kind} model does not load ({type(exc).__name__}: {exc})"[:300]) \
            from None
