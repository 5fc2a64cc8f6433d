"""A method's name, parsed once into its parts.

A name is ``[PRIOR+]METHOD[@VARIANT][ tuned]``:

* ``PRIOR+METHOD`` is a hybrid, a prior with ``METHOD`` learning the torque it
  leaves (``feasible+gp``; :mod:`methods.hybrid`);
* ``@VARIANT`` is a model a run derives from its own fit and scores beside it
  (``syrenets@pruned``; :meth:`methods.base.Method.variants`), a column of a
  table but no run of its own;
* `` tuned`` marks the column of runs that chose their hyperparameters on
  their training data (:mod:`bench.evaluation.tuning`).

Every piece of code that needs a part of a name reads the fields of a
:class:`MethodName`; nothing else splits a name.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from bench.core.errors import UserError

#: joins a hybrid's prior and the method that learns its residual
HYBRID = "+"
#: joins a run's method and a variant of its fit
VARIANT = "@"
#: ends the column of tuned runs
TUNED = " tuned"


class MethodNameError(UserError, ValueError):
    """A method name that does not parse; the message says which part is wrong, and
    ``hybrid`` whether the name joins a prior to a method (``PRIOR+...``)."""

    def __init__(self, message: str, hybrid: bool = False):
        super().__init__(message)
        self.hybrid = hybrid


def is_name(text: str) -> bool:
    """Whether ``text`` is a name of the suite's registries (a method's, a system's, a law's, an effect's, a
    family's): letters, digits and ``_``, at least one of them."""
    return bool(text) and text.replace("_", "").isalnum()


def _part(text: str, what: str, name: str, hybrid: bool) -> str:
    if not is_name(text):
        raise MethodNameError(f"method name {name!r}: its {what} {text!r} is not a name (letters, digits and '_')",
                              hybrid)
    return text


@dataclass(frozen=True, order=True)
class MethodName:
    """The parts of a method's name: ``method`` (a hybrid's residual learner, or the
    method itself), ``prior`` (a hybrid's, else ``None``), ``variant`` (a variant of
    the run's fit, else ``None``) and ``tuned``."""

    method: str
    prior: str | None = None
    variant: str | None = None
    tuned: bool = False

    @classmethod
    def parse(cls, name: str) -> "MethodName":
        """The parts of ``name``; :class:`MethodNameError` naming the part that is wrong."""
        if not isinstance(name, str):
            raise MethodNameError(f"a method name must be a string, got {name!r}")
        text, tuned = (name[: -len(TUNED)], True) if name.endswith(TUNED) else (name, False)
        run, at, variant = text.partition(VARIANT)
        prior, plus, method = run.partition(HYBRID)
        hybrid = bool(plus)
        if not hybrid:
            prior, method = None, run
        elif HYBRID in method:
            raise MethodNameError(f"method name {name!r}: the residual of a hybrid cannot be a hybrid", hybrid)
        return cls(
            method=_part(method, "method", name, hybrid),
            prior=_part(prior, "prior", name, hybrid) if hybrid else None,
            variant=_part(variant, "variant", name, hybrid) if at else None,
            tuned=tuned,
        )

    def __str__(self) -> str:
        return (f"{self.prior}{HYBRID}" if self.prior else "") + self.method + (
            f"{VARIANT}{self.variant}" if self.variant else "") + (TUNED if self.tuned else "")

    @property
    def hybrid(self) -> bool:
        return self.prior is not None

    @property
    def run(self) -> "MethodName":
        """The name of the runs this column comes from: no variant, not tuned."""
        return replace(self, variant=None, tuned=False)

    @property
    def parts(self) -> tuple[str, ...]:
        """The registered methods and priors the name is made of."""
        return (self.prior, self.method) if self.prior else (self.method,)

    def with_variant(self, variant: str) -> "MethodName":
        return replace(self, variant=_part(variant, "variant", f"{self}{VARIANT}{variant}", self.hybrid))

    def with_tuned(self, tuned: bool = True) -> "MethodName":
        return replace(self, tuned=tuned)
