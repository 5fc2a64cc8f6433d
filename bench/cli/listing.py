"""``python -m bench list``: the systems and methods, with availability."""

from __future__ import annotations

from bench.cli.options import add_plugin, load_plugins
import systems
from methods import METHODS
from methods.hybrid import naming
from systems import SYSTEMS


def add_arguments(parser) -> None:
    add_plugin(parser)


def main(args) -> int:
    load_plugins(args)
    print("Systems:")
    for entry in SYSTEMS.entries():
        sys_obj = entry.obj()
        kind = "simulated" if sys_obj.simulated else "measured"
        splits = f"  splits={','.join(sys_obj.splits)}" if len(sys_obj.splits) > 1 else ""
        print(f"  {entry.name:<20} dof={sys_obj.dof}  {kind:<9}  coordinates={','.join(sys_obj.coordinates)}  "
              f"tags={','.join(sorted(entry.tags))}{splits}")
        if sys_obj.listing():
            print(f"  {'':<20} {sys_obj.listing()}")
    if systems.WITHOUT_ARMS:
        print(f"  {'panda, ur5, kuka_lwr4':<20} unavailable: {systems.WITHOUT_ARMS}")
    print("Methods:")
    for entry in METHODS.entries():
        reason = entry.unavailable_reason()
        state = "available" if reason is None else f"unavailable: {reason}"
        exps = ",".join(entry.obj.experiments)
        print(f"  {entry.name:<20} {state}  experiments={exps}  tags={','.join(sorted(entry.tags))}")
        for name, named in entry.obj.configurations.items():
            print(f"  {'':<20} --config {name}: {named.summary}")
        if entry.obj.search_space:
            space = ", ".join(f"{k} in {{{', '.join(map(str, v))}}}" for k, v in entry.obj.search_space.items())
            print(f"  {'':<20} --tune searches {space}")
    print("Hybrids (an identified rigid body plus a learned residual of the torque):")
    print(f"  {naming()}; a residual that does not fall back to zero far from the training states by itself is gated "
          f"towards zero there (methods/hybrid.py), and --tune searches its gate_length in {{1.0, 3.0}} beside the "
          f"residual's own space")
    return 0
