"""The generated blocks of results/residual/panda_log/README.md
(:mod:`bench.reporting.pages`): the laws the loop found on a simulated
Panda's converted logs, at each cut-off and for each draw of the logs, against
the values the logs were made with."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.reporting.pages import block
from bench.runner.records import read_record, residual_fields

FOLDER = "residual/panda_log"
#: the values ``robot-log --effects`` put in, per joint (the page's command)
TRUTH = {"b": (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4), "F_c": (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
         "tau_0": (0.2, -0.3, 0.4, -0.5, 0.3, -0.2, 0.1)}
CUTOFFS = (6, 20, 60, 120, 200)
#: the draws of the logs at 60 Hz: the logs' seed and its file (seed 0 is the cut-off run's)
DRAWS = ((0, "cutoff_60hz.json"), (10, "seed_10_60hz.json"), (20, "seed_20_60hz.json"), (30, "seed_30_60hz.json"))


def _read(root: Path, name: str) -> dict:
    path = Path(root) / FOLDER / name
    return residual_fields(read_record(path), path)


def _laws(result: dict) -> dict[int, dict[str, tuple[str, float, float]]]:
    """Per joint: each parameter put in as ``(law, value, stderr)`` the loop reports."""
    out: dict[int, dict[str, tuple[str, float, float]]] = {}
    for e in result["effects"]:
        if e["kind"] in ("structural", "beyond_data", "not_identified") or len(e["joints"]) != 1:
            continue
        for name, p in e["parameters"].items():
            if name in TRUTH:
                out.setdefault(e["joints"][0], {})[name] = (e["name"], p["value"], p["stderr"])
    return out


def _error(name: str, joint: int, value: float) -> float:
    """The relative error ``value / truth - 1``."""
    return value / TRUTH[name][joint - 1] - 1


def _cell(found: dict, name: str, joint: int) -> str:
    if name not in found:
        return "—"
    _, value, _ = found[name]
    return f"{value:.4g} ({_error(name, joint, value):+.1%})"


@block("residual.panda_log.cutoffs")
def cutoffs(root: Path) -> str:
    """Each joint's friction law and offset at each cut-off, with its error against the truth."""
    lines = ["| cut-off | joint | friction law | F_c (error) | b (error) | offset τ₀ (error) |",
             "|---:|---:|---|---|---|---|"]
    for hz in CUTOFFS:
        laws = _laws(_read(root, f"cutoff_{hz}hz.json"))
        for joint in range(1, len(TRUTH["b"]) + 1):
            found = laws.get(joint, {})
            friction = next((found[k][0] for k in ("F_c", "b") if k in found), "—")
            lines.append(f"| {hz} Hz | {joint} | {friction} | {_cell(found, 'F_c', joint)} | {_cell(found, 'b', joint)} "
                         f"| {_cell(found, 'tau_0', joint)} |")
    return "\n".join(lines)


@block("residual.panda_log.cutoff_summary")
def cutoff_summary(root: Path) -> str:
    """Per cut-off: the laws found, the worst parameter error and the test MSE before and after."""
    lines = ["| cut-off | every joint one Coulomb-plus-viscous law and one offset | worst parameter error "
             "| test torque MSE before → after |", "|---:|---|---|---|"]
    for hz in CUTOFFS:
        r = _read(root, f"cutoff_{hz}hz.json")
        laws = _laws(r)
        complete = all(set(laws.get(j, {})) == set(TRUTH) and laws[j]["b"][0] == "coulomb_viscous_friction"
                       for j in range(1, len(TRUTH["b"]) + 1))
        errors = [(abs(_error(n, j, v)), n, j) for j, found in laws.items() for n, (_, v, _) in found.items()]
        worst = max(errors) if errors else None
        lines.append(f"| {hz} Hz | {'yes' if complete else 'no'} | "
                     + ("—" if worst is None else f"{worst[0]:.1%} ({worst[1]}, joint {worst[2]})")
                     + f" | {r['mse_before']['test']:.3g} → {r['mse_after']['test']:.3g} |")
    return "\n".join(lines)


@block("residual.panda_log.draws")
def draws(root: Path) -> str:
    """At 60 Hz, each draw of the logs: the worst error, b's errors and standard errors per joint,
    the range of F_c's errors, the offsets' worst error and the test MSE."""
    lines = ["| logs' seed | every joint one Coulomb-plus-viscous law and one offset | worst error | b error, joints 1–7 "
             "| b's standard error, joints 1–7 | F_c errors | offsets' worst error | test torque MSE |",
             "|---:|---|---:|---|---|---|---|---|"]
    joints = range(1, len(TRUTH["b"]) + 1)
    for seed, name in DRAWS:
        r = _read(root, name)
        laws = _laws(r)
        complete = all(set(laws.get(j, {})) == set(TRUTH) for j in joints)
        if not complete:
            lines.append(f"| {seed} | no | | | | | | {r['mse_before']['test']:.3g} → {r['mse_after']['test']:.3g} |")
            continue
        b = [_error("b", j, laws[j]["b"][1]) for j in joints]
        b_se = [laws[j]["b"][2] / TRUTH["b"][j - 1] for j in joints]
        fc = [_error("F_c", j, laws[j]["F_c"][1]) for j in joints]
        off = [abs(_error("tau_0", j, laws[j]["tau_0"][1])) for j in joints]
        worst = max(max(map(abs, b)), max(map(abs, fc)), max(off))
        lines.append(f"| {seed} | yes | {worst:.1%} | " + " ".join(f"{100 * x:+.1f}" for x in b) + " % | "
                     + " ".join(f"{100 * x:.1f}" for x in b_se) + f" % | {100 * min(fc):+.1f} to {100 * max(fc):+.1f} % | "
                     f"{max(off):.1%} (joint {int(np.argmax(off)) + 1}) | "
                     f"{r['mse_before']['test']:.3g} → {r['mse_after']['test']:.3g} |")
    return "\n".join(lines)
