"""Measure what stacking seeds (:mod:`methods.stacking`) gains: training
steps per second per seed, and seed-steps per second, of S seeds trained as
one stacked model against the same seeds trained one by one, in one run, on
one device.

For each method and number of seeds S, the S seeds' fits do ``--steps``
steps each (the method's default configuration, ``--n-train`` generated
samples a seed), once stacked and once one by one; a fit's time is its
loop's, ``loop_seconds`` (from its budget's start, after its one-time
compiling, to its loop's end), evaluations on its schedule included, as a
run spends it, and the work after the loop (SyReNets' pruning) left out. The ratio is the
stacked seed-steps per second over the one-by-one's::

    python -m bench study stacking-speed [--device cpu] [--n-seeds 1 10 100] [--steps 20] [--out PAGE.md]

SyReNets is measured without its refinement after training
(``refine=False``), which a step count does not bound.
"""

from __future__ import annotations

import time

import torch

from bench.core.arguments import positive_int
from bench.core.data import generate
from bench.core.devices import CHOICES, describe, resolve
from bench.core.errors import UserError
from bench.core.fileio import atomic_write, check_output
from bench.runner.progress import print_now
from bench.runner.provenance import cpu_model
from methods import METHODS
from methods.stacking import fit_stacked
from systems import get_system
from bench.core.budget import Budget

#: what is measured by default: SyReNets on the double pendulum (1 and 10 seeds), the MLP and DeLaN on the Panda
DEFAULT_CASES = ("syrenets:double_pendulum:1,10", "mlp:panda", "delan:panda")
#: each method's configuration here: its defaults, less the work after training (not timed here, and not bounded by steps)
MEASURED_CONFIG = {"syrenets": {"refine": False}}


def measure(method: str, system_name: str, seeds: int, steps: int, n_train: int, device: str) -> dict:
    """One case: S seeds stacked, and one by one."""
    system = get_system(system_name)
    data = [generate(system, n_train, k) for k in range(seeds)]
    cls = METHODS[method]

    def fresh():
        return cls(**MEASURED_CONFIG.get(method, {})).use_device(device)

    fresh().fit(data[0], "indirect", 0, Budget(steps=1), system=system)  # the process's one-time work (imports, compiling)
    alone = [fresh().fit(d, "indirect", k, budget=Budget(steps=steps), system=system) for k, d in enumerate(data)]
    alone_s = sum(m.fit_info["loop_seconds"] for m in alone)
    start = time.perf_counter()
    stacked = fit_stacked([fresh() for _ in data], data, "indirect", list(range(seeds)), Budget(steps=steps),
                          system=system)
    wall = time.perf_counter() - start
    stacked_s = stacked[0].fit_info["loop_seconds"]  # the first seed's clock starts first and its loop ends with all
    return {"method": method, "system": system_name, "seeds": seeds, "steps": steps,
            "alone_seed_steps_per_s": seeds * steps / alone_s, "stacked_seed_steps_per_s": seeds * steps / stacked_s,
            "stacked_steps_per_s": steps / stacked_s, "stacked_wall_s": wall,
            "ratio": alone_s / stacked_s}


#: the subcommand's one-line help


def parse_case(case: str, n_seeds: list[int]) -> tuple[str, str, list[int]]:
    """``METHOD:SYSTEM[:S,...]`` as (method, system, numbers of seeds); a :class:`UserError` naming what is wrong."""
    parts = case.split(":")
    if len(parts) not in (2, 3):
        raise UserError(f"--cases {case}: expected METHOD:SYSTEM or METHOD:SYSTEM:S,S,...")
    method, system = parts[:2]
    stackable = [n for n in METHODS.names() if METHODS.entry(n).available and METHODS[n].stackable]
    if method not in stackable:
        raise UserError(f"--cases {case}: {method} is not a stackable method (stackable: {', '.join(stackable)})")
    if len(parts) == 2:
        return method, system, n_seeds
    try:
        counts = [positive_int(x) for x in parts[2].split(",")]
    except Exception:
        raise UserError(f"--cases {case}: the numbers of seeds must be positive integers, e.g. {method}:{system}:1,10") from None
    return method, system, counts


def add_arguments(parser) -> None:
    parser.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES), metavar="METHOD:SYSTEM[:S,...]",
                        help=f"stackable methods, their systems and, optionally, their numbers of seeds in place of "
                             f"--n-seeds (default {' '.join(DEFAULT_CASES)})")
    parser.add_argument("--n-seeds", type=positive_int, nargs="+", default=[1, 10, 100],
                        help="numbers of seeds to stack (default 1 10 100)")
    parser.add_argument("--steps", type=positive_int, default=20, help="training steps of each seed's fit (default 20)")
    parser.add_argument("--n-train", type=positive_int, default=2048, help="generated training samples a seed (default 2048)")
    parser.add_argument("--device", choices=CHOICES, default="cpu", help="where the fits train (default cpu)")
    parser.add_argument("--out", default=None, help="also write the table to this markdown page")


def main(args) -> int:
    if args.out:
        check_output(args.out)
    device = resolve(args.device)
    cases = [parse_case(c, args.n_seeds) for c in args.cases]
    for method, system, _ in cases:
        get_system(system)
    torch.set_num_threads(1)
    where = describe(device)
    machine = where.get("name") or cpu_model()
    print_now(f"on {where['type']} ({machine}), one thread; {args.steps} steps a seed, {args.n_train} samples a seed")
    rows = []
    for method, system, counts in cases:
        for s in counts:
            row = measure(method, system, s, args.steps, args.n_train, device)
            rows.append(row)
            print_now(f"{method} on {system}, {s} seed(s): stacked {row['stacked_steps_per_s']:.3g} steps/s, "
                      f"{row['stacked_seed_steps_per_s']:.3g} seed-steps/s; one by one {row['alone_seed_steps_per_s']:.3g} "
                      f"seed-steps/s; stacked ÷ one by one {row['ratio']:.2f}")
    lines = [f"Measured by `python -m bench study stacking-speed --device {args.device} --cases {' '.join(args.cases)} "
             f"--n-seeds {' '.join(map(str, args.n_seeds))} --steps {args.steps} --n-train {args.n_train}` on {where['type']} ({machine}), one thread.", "",
             "| method | system | seeds | stacked steps/s (each seed) | stacked seed-steps/s | one by one seed-steps/s "
             "| stacked ÷ one by one |", "|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['method']} | {r['system']} | {r['seeds']} | {r['stacked_steps_per_s']:.3g} "
                     f"| {r['stacked_seed_steps_per_s']:.3g} | {r['alone_seed_steps_per_s']:.3g} | {r['ratio']:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        atomic_write(args.out, lambda f: f.write(text))
    return 0
