"""A fitted model to keep: one file that loads without running code from it.

The file is a NumPy ``.npz`` archive (read with ``allow_pickle=False``): its
arrays are the model's parameters, and one entry, ``model.json``, says what
the model is, in JSON: its kind, the method and hyperparameters it was fitted
with, its system and joints, where its arrays are, and, for a model with laws
or an expression, each expression as a tree of sympy's operations
(:mod:`bench.core.expressions`), read back node by node from a fixed list
of operations and functions, never through ``eval``. Floats keep all their
digits, so a loaded model predicts what the fitted one did to round-off.

A model says how it is saved (:meth:`~bench.physics.models.FittedModel.saved`:
a kind and a JSON tree holding :class:`Packer` references to arrays), and
each kind has a loader (:data:`LOADERS`, :func:`loader`), registered beside
the model it loads.

A model file may come from anyone, so it is data, checked before it is used:

* the archive's size, each entry's size unpacked, and the entries' names are
  checked before anything is unpacked (:data:`MAX_HEADER_BYTES`,
  :data:`MAX_ARRAY_BYTES`);
* the header is checked against :data:`HEADER_SCHEMA` (JSON Schema, by
  ``jsonschema``), every field's type and range stated;
* an expression is checked as it is read, before sympy evaluates anything:
  its depth, its nodes, the digits of its numbers, and the size of any power
  of numbers sympy would compute (:data:`bench.core.expressions.EXPRESSION_LIMITS`);
* the file names no path that is opened: a URDF's or a measured arm's file is
  named by the user (``--plugin``), and a linear model's regressor is compared
  with the one it was fitted on at probe states;
* its header holds the sha256 of its contents (:func:`digest`: the header and
  every array), so that a file edited or corrupted since it was saved is
  refused, not read with other numbers;
* every number of its arrays is finite and at most :data:`MAX_COEFFICIENT` in
  magnitude, and the header states the bound its torques keep on any log
  (``torque_bound``, :data:`TORQUE_BOUND_FACTOR` times the largest torque of
  each joint in the data it was fitted on), which ``bench predict`` checks
  before it writes anything.

A file that is not such a model, is truncated, corrupt, too large or does not
parse is refused in one line naming it (:class:`ModelFileError`).
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
import zlib
from pathlib import Path
from typing import Callable

import numpy as np

from bench.core.errors import UserError
from bench.core.fileio import atomic_write
from bench.core.registry import Registry

#: the format a model file says it is in
FORMAT = "syrenets-bench/model/1"
#: the archive entry that holds the model's description
HEADER = "model.json"


class ModelFileError(UserError):
    """A file that is not a model this suite saved, or cannot be read as one; the message names the file."""


#: the most bytes a model file's header and all its arrays may take unpacked, and a file on disk
MAX_HEADER_BYTES, MAX_ARRAY_BYTES, MAX_FILE_BYTES = 64 << 20, 4 << 30, 4 << 30
#: the largest magnitude any number of a model file's arrays may have: a coefficient, a weight, a scale
MAX_COEFFICIENT = 1e12
#: a saved model's torques on any log stay within this many times the largest torque of each joint in the data
#: it was fitted on (the header's ``torque_bound``): a model whose numbers were scaled by a thousand, or a log
#: far from the fit, is refused rather than predicted
TORQUE_BOUND_FACTOR = 100.0
#: a name a system or a method may have in a header
_NAME = {"type": "string", "minLength": 1, "maxLength": 200}
#: what a model file's header holds, each field's type and range (JSON Schema); the model's own tree is its
#: kind's loader's to check
HEADER_SCHEMA = {
    "type": "object",
    "required": ["format", "dof", "kind", "model"],
    "properties": {
        "format": {"const": FORMAT},
        "dof": {"type": "integer", "minimum": 1, "maximum": 64},
        "kind": {"type": "string", "minLength": 1, "maxLength": 64},
        "model": {"type": "object", "required": ["kind"], "properties": {"kind": {"type": "string", "maxLength": 64}}},
        "method": _NAME,
        "system": {"anyOf": [_NAME, {"type": "null"}]},
        "plugins": {"type": "array", "maxItems": 64, "items": {"type": "string", "maxLength": 1000}},
        "split": {"anyOf": [{"type": "string", "maxLength": 200}, {"type": "null"}]},
        "experiment": {"type": "string", "maxLength": 64},
        "seed": {"type": "integer", "minimum": 0},
        "hyperparameters": {"type": "object"},
        "budget": {"type": "object"},
        "train_source": {"type": "string"},
        "n_train": {"type": "integer", "minimum": 0},
        "tuned": {"type": "boolean"},
        "provenance": {"type": "object"},
        "digest": {"type": "string", "pattern": "^[0-9a-f]{64}$"},
        "torque_bound": {"type": "array", "minItems": 1, "maxItems": 64,
                         "items": {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_COEFFICIENT}},
        "held_out": {"type": "object", "required": ["index", "fold", "prediction"],
                     "properties": {k: {"type": "object", "required": ["$array"]}
                                    for k in ("index", "fold", "prediction")}},
    },
}


def check_header(header, source: str) -> dict:
    """``header`` where it is what :data:`HEADER_SCHEMA` says; :class:`ModelFileError` naming the first field that
    is not, otherwise."""
    import jsonschema

    validator = jsonschema.Draft202012Validator(HEADER_SCHEMA)
    error = jsonschema.exceptions.best_match(validator.iter_errors(header))
    if error is None:
        return header
    where = "/".join(str(p) for p in error.absolute_path) or "the header"
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        got = header.get("format") if isinstance(header, dict) else None
        raise ModelFileError(f"{source}: not a model file of this suite (format {got!r:.60}, not {FORMAT!r})")
    raise ModelFileError(f"{source}: not a model file of this suite ({HEADER}: {where}: {error.message})"[:300])


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
        import torch  # here, so that a model file's container is read without torch

        return {k: torch.from_numpy(np.array(self.array(v))) for k, v in refs.items()}


# -- the file --------------------------------------------------------------------------------

#: how each kind of saved model is loaded: ``(tree, unpacker, context) -> FittedModel``
LOADERS: Registry[Callable] = Registry("kind of saved model")


def loader(kind: str):
    """Register the function that loads saved models of ``kind``."""
    return LOADERS.add(kind)


def digest(header: dict, arrays: dict[str, np.ndarray]) -> str:
    """The sha256 of a model file's contents: its header but its ``digest``, as JSON with sorted keys, and each
    array's name, dtype, shape and bytes, in the order of their names."""
    h = hashlib.sha256(json.dumps({k: v for k, v in header.items() if k != "digest"}, sort_keys=True,
                                  separators=(",", ":")).encode())
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        h.update(f"\n{name} {array.dtype.str} {array.shape}\n".encode())
        h.update(array.tobytes())
    return h.hexdigest()


def check_arrays(arrays: dict[str, np.ndarray], source: str) -> None:
    """:class:`ModelFileError` naming the first array holding a number that is not finite or past
    :data:`MAX_COEFFICIENT` in magnitude."""
    for name in sorted(arrays):
        array = arrays[name]
        if array.dtype.kind not in "fc" or not array.size:
            continue
        if not np.isfinite(array).all():
            raise ModelFileError(f"{source}: its array {name} holds a number that is not finite")
        largest = float(np.max(np.abs(array)))
        if largest > MAX_COEFFICIENT:
            raise ModelFileError(f"{source}: its array {name} holds {largest:.3g}, past the {MAX_COEFFICIENT:g} a "
                                 f"model's number may be")


def save(path: str | Path, header: dict, model_tree: dict, packer: Packer) -> None:
    """Write a model file: ``header`` (what it was fitted with), the model's
    tree (:meth:`~bench.physics.models.FittedModel.saved`) and its arrays, with their :func:`digest`,
    atomically."""
    check_arrays(packer.arrays, str(path))
    whole = {"format": FORMAT, **header, "model": model_tree}
    whole["digest"] = digest(whole, packer.arrays)
    text = json.dumps(whole, indent=1, sort_keys=True)

    def write(f):
        with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED) as z:
            z.writestr(HEADER, text)
            for name, array in packer.arrays.items():
                buffer = io.BytesIO()
                np.save(buffer, array, allow_pickle=False)
                z.writestr(f"{name}.npy", buffer.getvalue())

    atomic_write(Path(path), write, binary=True)


def read(path: str | Path) -> tuple[dict, Unpacker]:
    """A model file's description (checked against :data:`HEADER_SCHEMA`) and its arrays;
    :class:`ModelFileError` in one line otherwise."""
    source = str(path)
    try:
        size = Path(path).stat().st_size if Path(path).is_file() else 0
        if size > MAX_FILE_BYTES:
            raise ModelFileError(f"{source}: a file of {size} bytes, more than a model file may take ({MAX_FILE_BYTES})")
        with zipfile.ZipFile(path) as z:
            entries = {i.filename: i for i in z.infolist()}
            if HEADER not in entries:
                raise ModelFileError(f"{source}: not a model file of this suite (no {HEADER} in it)")
            others = [n for n in entries if n != HEADER]
            strange = [n for n in others if not (n.endswith(".npy") and n[:-4].isidentifier())]
            if strange or len(entries) != len(z.infolist()):
                raise ModelFileError(f"{source}: not a model file of this suite (it holds {(strange or ['a name twice'])[0]!r:.60})")
            if entries[HEADER].file_size > MAX_HEADER_BYTES or \
                    sum(entries[n].file_size for n in others) > MAX_ARRAY_BYTES:
                raise ModelFileError(f"{source}: its entries unpack to more than a model file may hold "
                                     f"({MAX_HEADER_BYTES} bytes of header, {MAX_ARRAY_BYTES} of arrays)")
            try:
                header = json.loads(z.read(HEADER).decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
                why = "it is nested too deeply" if isinstance(exc, RecursionError) else exc
                raise ModelFileError(f"{source}: its {HEADER} does not parse ({why})"[:300]) from None
            check_header(header, source)
            arrays = {}
            for name in others:
                arrays[name[:-4]] = np.load(io.BytesIO(z.read(name)), allow_pickle=False)
        if "digest" in header and header["digest"] != digest(header, arrays):
            raise ModelFileError(f"{source}: its contents differ from the digest it was saved with (edited or "
                                 f"corrupt since); not read")
        check_arrays(arrays, source)
    except ModelFileError:
        raise
    except FileNotFoundError:
        raise ModelFileError(f"{source}: no such file") from None
    except (zipfile.BadZipFile, zlib.error):
        raise ModelFileError(f"{source}: not a model file of this suite (not a complete archive: truncated, "
                             f"corrupt or another kind of file)") from None
    except (ValueError, EOFError, OSError, zipfile.LargeZipFile, NotImplementedError, RecursionError,
            MemoryError) as exc:
        raise ModelFileError(f"{source}: a model file that cannot be read ({type(exc).__name__}: {exc})"[:300]) from None
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
    except (KeyError, TypeError, ValueError, IndexError, RuntimeError, AttributeError, ArithmeticError) as exc:
        raise ModelFileError(f"{unpacker.source}: its {kind} model does not load ({type(exc).__name__}: {exc})"[:300]) \
            from None
