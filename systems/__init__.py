"""Registry of physical systems.

Each module below registers its systems with ``@SYSTEMS.add(name, *tags)``.
Adding a system: write one module and add it to the import line.
"""

from systems.base import SYSTEMS, Domain, ParametricForm, System, get_system

from systems import (  # noqa: E402,F401  (registers)
    cart_pole,
    delan_characters,
    dfki_double_pendulum,
    double_pendulum,
    n_link_pendulum,
    single_pendulum,
    spring_pendulum,
)

#: why the arms from URDF files (panda, ur5, kuka_lwr4, ``urdf:`` and ``measured:`` files) are not
#: registered, where their engine, Pinocchio, cannot be imported; ``None`` where they are
WITHOUT_ARMS: str | None = None
try:
    from systems import measured_arm, urdf_arm  # noqa: E402,F401  (registers; builds the arms with Pinocchio)
except ModuleNotFoundError as exc:
    if exc.name is None or exc.name.split(".")[0] not in ("pinocchio", "pin"):
        raise
    WITHOUT_ARMS = f"the arms from URDF files need Pinocchio, which is not installed here ({exc}; pip install pin)"

__all__ = ["SYSTEMS", "Domain", "ParametricForm", "System", "get_system"]
