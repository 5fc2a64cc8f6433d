"""Registry of physical systems.

Each module below registers its systems with ``@SYSTEMS.add(name, *tags)``.
Adding a system: write one module and add it to the import line.
"""

from systems.base import SYSTEMS, Domain, ParametricForm, System, get_system

from systems import (  # noqa: E402,F401  (registers)
    cart_pole,
    delan_characters,
    dfki_double_pendulum,
    measured_arm,
    double_pendulum,
    n_link_pendulum,
    single_pendulum,
    spring_pendulum,
    urdf_arm,
)

__all__ = ["SYSTEMS", "Domain", "ParametricForm", "System", "get_system"]
