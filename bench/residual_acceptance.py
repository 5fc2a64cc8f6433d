"""Measure the residual loop on simulated data with known undeclared effects.

For each effect type (and clean data), each noise level and each method, the
double pendulum's torques get the effect (``bench.data`` with ``--effects``)
and Gaussian noise on train and test torques (a fraction of each joint's
torque standard deviation); the loop (:func:`bench.residual.residual_loop`)
is run, and the table says whether it named exactly the right effects on the
right joints, the worst relative coefficient error, the test torque MSE before
and after, and the test set's noise floor (the mean square of the noise that
was added), so that "after ÷ floor" near 1 means that all but the noise was
explained. Usage::

    python -m bench.residual_acceptance [--noise 0 0.01 0.1] [--methods sysid sparse] [--out results/residual/acceptance.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

#: the undeclared effects, one case each, with a coefficient on each joint
CASES = {
    "viscous_friction": {"viscous_friction": (0.8, 0.5)},
    "coulomb_friction": {"coulomb_friction": (1.5, 0.7)},
    # on one joint: with armatures on both joints the double pendulum's SysId form is not identifiable
    # from torques (six unknowns m1, m2, l1, l2, Ia1, Ia2 map to five coefficients of L)
    "armature": {"armature": (0.3, 0.0)},
    "spring": {"spring": (2.0, 1.0)},
    "offset": {"offset": (0.5, -0.3)},
    "clean": {},
}


def run_case(case: str, noise: float, method: str, n_train: int, n_test: int, budget: float) -> dict:
    import torch

    from bench.data import add_noise, generate
    from bench.effects import add_effects
    from bench.harness import quiet
    from bench.residual import residual_loop
    from systems import SYSTEMS

    torch.set_num_threads(1)
    effects = CASES[case]
    system = SYSTEMS["double_pendulum"]()
    train = add_effects(generate(system, n_train, 0), effects)
    test = clean_test = add_effects(generate(system, n_test, 1000), effects)
    if noise:
        train, test = add_noise(train, "indirect", noise, 0), add_noise(clean_test, "indirect", noise, 1)
    floor = float(np.mean((test.tau - clean_test.tau) ** 2))
    start = time.perf_counter()
    out = residual_loop(method, train, test, budget_s=budget, report=quiet)
    want = {(name, j + 1): c for name, coefs in effects.items() for j, c in enumerate(coefs) if c}
    found = {(e["name"], e["joint"]): e["coefficient"] for e in out["effects"]}
    errors = [abs(found[k] - c) / abs(c) for k, c in want.items() if k in found]
    return {
        "case": case, "noise": noise, "method": method, "named_right": set(found) == set(want),
        "found": sorted(f"{n} j{j}" for n, j in found), "worst_coef_error": max(errors) if errors else None,
        "before": out["mse_before"]["test"], "after": out["mse_after"]["test"], "floor": floor,
        "seconds": time.perf_counter() - start,
    }


def table(rows: list[dict]) -> str:
    lines = [
        "| effect | noise | method | right effects, right joints | found | worst coefficient error | test MSE before "
        "| test MSE after | after ÷ before | noise floor | after ÷ floor | seconds |",
        "|---|---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        err = "—" if r["worst_coef_error"] is None else f"{r['worst_coef_error']:.2%}"
        floor = f"{r['floor']:.3g}" if r["floor"] else "0"
        over = f"{r['after'] / r['floor']:.3g}" if r["floor"] else "—"
        lines.append(
            f"| {r['case']} | {r['noise']:g} | {r['method']} | {'yes' if r['named_right'] else '**no**'} "
            f"| {', '.join(r['found']) or 'nothing'} | {err} | {r['before']:.3g} | {r['after']:.3g} "
            f"| {r['after'] / r['before']:.3g} | {floor} | {over} | {r['seconds']:.1f} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    from bench.fileio import atomic_write
    from bench.harness import fork_server
    from bench.records import provenance

    parser = argparse.ArgumentParser(prog="python -m bench.residual_acceptance", description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.01, 0.1])
    parser.add_argument("--methods", nargs="+", default=["sysid", "sparse"])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--n-train", type=int, default=3000)
    parser.add_argument("--n-test", type=int, default=1500)
    parser.add_argument("--budget", type=float, default=5.0, help="seconds per fit of the method")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("results/residual/acceptance.md"))
    args = parser.parse_args(argv)
    jobs = [(c, z, m) for c in args.cases for z in args.noise for m in args.methods]
    rows = []
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=fork_server()) as pool:
        futures = [pool.submit(run_case, c, z, m, args.n_train, args.n_test, args.budget) for c, z, m in jobs]
        for i, future in enumerate(as_completed(futures), 1):
            r = future.result()
            rows.append(r)
            print(f"[{i}/{len(jobs)}] {r['case']} noise={r['noise']:g} {r['method']}: named right {r['named_right']}, "
                  f"test MSE {r['before']:.3g} -> {r['after']:.3g} (floor {r['floor']:.3g})", flush=True)
    order = {c: i for i, c in enumerate(args.cases)}
    rows.sort(key=lambda r: (order[r["case"]], r["noise"], args.methods.index(r["method"])))
    prov = provenance()
    command = "python -m bench.residual_acceptance " + " ".join(argv if argv is not None else sys.argv[1:])
    text = "\n".join([
        "# The residual loop on undeclared effects: acceptance figures",
        "",
        f"Generated by `{command.strip()}` (commit {prov.get('commit', '?')[:7]}"
        f"{', dirty tree' if prov.get('dirty') else ''}). Double pendulum, {args.n_train} training and {args.n_test} "
        f"test samples; each effect on both joints, the armature on joint 1 only (coefficients and why in "
        f"[bench/residual_acceptance.py]"
        f"(../../bench/residual_acceptance.py)); noise on train and test torques as a fraction of each joint's "
        f"torque standard deviation; {args.budget:g} s per fit of the method. The noise floor is the test set's "
        "mean squared noise: at \"after ÷ floor\" ≈ 1 everything but the noise is explained.",
        "",
        table(rows),
        "",
    ])
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
