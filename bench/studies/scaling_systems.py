"""The n-link pendulums of the scaling study (:mod:`bench.studies.scaling`),
registered as ``pendulum_<n>link`` when this module is imported: the study
imports it as a plugin, in its own process and in each run's, so that the
rest of the suite does not list them."""

from __future__ import annotations

from systems import SYSTEMS
from systems.n_link_pendulum import n_link_pendulum

#: the pendulums' sizes
LINKS = range(1, 8)


def pendulum_name(n: int) -> str:
    return f"pendulum_{n}link"


for _n in LINKS:
    if pendulum_name(_n) not in SYSTEMS:
        SYSTEMS.add(pendulum_name(_n), "simulated", "scaling")(
            type(f"Pendulum{_n}Link", (n_link_pendulum(_n),), {"__module__": __name__}))
