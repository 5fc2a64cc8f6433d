"""A method's hyperparameters: a frozen dataclass per method, typed and
ranged, validated when the method is built.

``Config`` subclasses :class:`MethodConfig`; each field's annotation gives its
type and, with :class:`Range`, its allowed values. :func:`build_config`
checks what a user passed (``--set``), and the defaults too, and refuses a
bad value in one line naming the method and the field.

Beside its defaults a method may offer :class:`Named` configurations (the
authors' code's settings, say), which a user picks with ``--config NAME`` and
can still ``--set`` on top of.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np

from bench.core.errors import ConfigError


@dataclass(frozen=True)
class Range:
    """The values a numeric hyperparameter may take, declared next to its type::

        batch_size: Annotated[int, Range(1)] = 32           # at least 1
        lr: Annotated[float, Range(0, low_open=True)] = 1e-3  # positive
        post_fraction: Annotated[float, Range(0, 1, high_open=True)] = 0.1

    For a tuple, every item must lie in the range.
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def __contains__(self, value) -> bool:
        if self.low is not None and not (value > self.low if self.low_open else value >= self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)

    def __str__(self) -> str:
        if self.high is None:
            return f"{'greater than' if self.low_open else 'at least'} {self.low:g}"
        if self.low is None:
            return f"{'less than' if self.high_open else 'at most'} {self.high:g}"
        return f"in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}{')' if self.high_open else ']'}"


#: a positive number
POSITIVE = Range(0, low_open=True)
#: a probability or a fraction
FRACTION = Range(0, 1)

@dataclass(frozen=True)
class Named:
    """A named configuration: ``values`` set beside the defaults, and what it is, in a line."""

    summary: str
    values: dict


_BOOLEANS = {"true": True, "yes": True, "1": True, "false": False, "no": False, "0": False}


@dataclass(frozen=True)
class MethodConfig:
    """Hyperparameters every method has.

    Attributes
    ----------
    max_steps
        Stop after this many optimisation steps (or generations), even with
        budget left. ``None``: only the budget stops the run. Smoke
        configurations set it, so that a run is deterministic for its seed.
    eval_samples
        Size of the fixed random subset of the training data on which the
        training MSE is measured during the fit, to pick the best state.
    """

    max_steps: Annotated[int, Range(1)] | None = None
    eval_samples: Annotated[int, Range(1)] = 2048


def _check_value(owner: str, name: str, value: Any, hint: Any) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is Annotated:
        value = _check_value(owner, name, value, args[0])
        for bound in (a for a in args[1:] if isinstance(a, Range)):
            if any(v not in bound for v in (value if isinstance(value, tuple) else (value,))):
                raise ConfigError(f"{owner}: {name} must be {bound}{' (each item)' if isinstance(value, tuple) else ''}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _check_value(owner, name, value, inner[0])
        return value
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{owner}: {name} must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    if origin is tuple or hint is tuple:
        if not isinstance(value, (tuple, list)):
            raise ConfigError(f"{owner}: {name} must be a tuple, got {type(value).__name__}")
        if args and args[-1] is not Ellipsis and len(args) != len(value):
            raise ConfigError(f"{owner}: {name} must have {len(args)} items, got {len(value)}")
        if args:
            items = args[:1] * len(value) if args[-1] is Ellipsis else args
            return tuple(_check_value(owner, name, v, h) for v, h in zip(value, items))
        return tuple(value)
    if hint is bool:
        if isinstance(value, str) and value.strip().lower() in _BOOLEANS:
            return _BOOLEANS[value.strip().lower()]
        if isinstance(value, (int, np.integer)) and value in (0, 1):
            return bool(value)
        if not isinstance(value, bool):
            raise ConfigError(f"{owner}: {name} must be true or false (or yes/no, 1/0), got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ConfigError(f"{owner}: {name} must be an integer, got {value!r}")
        return int(value)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
            raise ConfigError(f"{owner}: {name} must be a finite number, got {value!r}")
        return float(value)
    if hint is str and not isinstance(value, str):
        raise ConfigError(f"{owner}: {name} must be a string, got {value!r}")
    return value


def build_config(config_cls: type, overrides: dict, owner: str):
    """Validate ``overrides`` against ``config_cls`` and return a new config.

    Unknown names get a "did you mean"; values are type-checked against the
    dataclass annotations, ranges included (:class:`Range`), and so are the
    defaults. ``overrides`` itself is not modified.
    """
    fields = {f.name: f for f in dataclasses.fields(config_cls)}
    hints = typing.get_type_hints(config_cls, include_extras=True)
    clean = {}
    for key, value in overrides.items():
        if key not in fields:
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ConfigError(f"{owner}: unknown hyperparameter {key!r}{hint} (known: {', '.join(sorted(fields))})")
        clean[key] = _check_value(owner, key, value, hints[key])
    for key in fields.keys() - clean.keys():
        if fields[key].default is not dataclasses.MISSING:
            _check_value(owner, key, fields[key].default, hints[key])
    config = config_cls(**clean)
    if hasattr(config, "validate"):
        config.validate()
    return config
