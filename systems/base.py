"""The system contract, for the modules of this package: it lives in
:mod:`bench.core.system` (below ``methods/``, which reads systems' declared
forms) and is re-exported here."""

from bench.core.system import HALF_PI, SYSTEMS, Domain, ParametricForm, System, get_system

__all__ = ["HALF_PI", "SYSTEMS", "Domain", "ParametricForm", "System", "get_system"]
