"""The standard model of each shipped measured arm, the field's (rigid-body base parameters plus Coulomb and
viscous friction, rotor inertia and a torque offset on each joint, :mod:`methods.sysid`), beside friction alone,
on each split; and every published record read against friction alone, with the factor that reads its "x the
standard model" figures against the field's model (results/measured/standard_model.md).

For each arm and split, four models are fitted on the training data as a run fits its standard model
(:func:`bench.evaluation.reference.standard_reference`: one solve, seed 0) and scored once on the test data:
the standard model with friction alone and with the drive's columns too, and the feasible model the same two
ways. Each folder of published records that carry a standard model is then listed with the standard model's
test MSE its records hold, the same model fitted again here (which must give it), and the factor
``old / new``: a learner's test MSE over the standard model's, read against the field's model, is its figure
on the page times that factor. A hybrid whose prior is the standard or the feasible model had the prior of
friction alone, and its own figures are not remade by the factor.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from bench.core.budget import Budget
from bench.core.data import mse
from bench.core.fileio import atomic_write, check_output, write_json
from bench.core.scoring import scoring
from bench.evaluation.reference import METHOD
from bench.physics.system import get_system
from bench.runner.plugins import file_prefix, register_by_file
from bench.runner.provenance import provenance
from methods import METHODS

#: the shipped measured arms, by the name a command gives
ARMS = ("kuka_lwr4", "measured:systems/data/dfki_double_pendulum_arm.toml")
SPLITS = ("default", "swapped")
#: the models compared: (key, label, SysId's hyperparameters, the key of the model it is read against)
MODELS = (("standard_friction_alone", "standard, friction alone", {"feasible": False, "friction": True},
           "standard_friction_alone"),
          ("standard", "standard", METHODS[METHOD].configuration("standard"), "standard_friction_alone"),
          ("feasible_friction_alone", "feasible, friction alone", {"feasible": True, "friction": True},
           "feasible_friction_alone"),
          ("feasible", "feasible", METHODS[METHOD].configuration("feasible"), "feasible_friction_alone"))
#: where the published records lie
RESULTS = Path("results")


def fitted(system, hyperparameters: dict) -> dict:
    """SysId with ``hyperparameters`` fitted on ``system``'s training split and scored once on its test split."""
    train, test = system.load("train"), system.load("test")
    model = METHODS[METHOD](**hyperparameters)
    model.fit(train, "indirect", 0, Budget(steps=1), system=system)
    facts = model.record_details()
    with scoring():
        test_mse = mse(model.predict_torque(test), test.tau)
    return {"train_mse": mse(model.predict_torque(train), train.tau), "test_mse": test_mse,
            "mass_matrix_positive_definite": facts.get("mass_matrix_positive_definite"),
            "dropped_joint_columns": facts.get("dropped_joint_columns", []),
            "joint_columns_not_significant": facts.get("joint_columns_not_significant", [])}


def published(root: Path = RESULTS) -> dict[tuple[str, str, str], list[float]]:
    """Each folder of published records that carry a standard model, by ``(folder, system, split)``: the
    standard model's test MSEs its records hold."""
    found: dict[tuple[str, str, str], list[float]] = defaultdict(list)
    for path in sorted(root.rglob("records/*.json")):
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        standard = (record.get("details") or {}).get("standard_model")
        if not standard or standard.get("test_mse") is None:
            continue
        split = (record.get("spec") or {}).get("split") or "default"
        found[(str(path.parent.parent), record["system"], split)].append(float(standard["test_mse"]))
    return dict(found)


def measure() -> dict:
    """The four models on each arm and split, by system, then split, then :data:`MODELS`' key, and the factor
    that reads a figure over friction alone over the field's standard model (``factor``)."""
    out: dict[str, dict] = {}
    for arm in ARMS:
        name = register_by_file(arm) if file_prefix(arm) else arm
        for split in SPLITS:
            system = get_system(name, split=split)
            row = out.setdefault(name, {})[split] = {key: fitted(system, h) for key, _, h, _ in MODELS}
            row["factor"] = row["standard_friction_alone"]["test_mse"] / row["standard"]["test_mse"]
            print(f"{name}, split {split}: standard model test MSE {row['standard']['test_mse']:.4g} "
                  f"(friction alone {row['standard_friction_alone']['test_mse']:.4g}); feasible "
                  f"{row['feasible']['test_mse']:.4g} ({row['feasible_friction_alone']['test_mse']:.4g})", flush=True)
    return out


def report(models: dict, pages: dict) -> str:
    """The page: the models side by side, then each published folder's factor."""
    lines = ["# The standard model of the measured arms: the field's, beside friction alone", "",
             "Command: `python -m bench study standard-model`. Each model is fitted on the split's training data as "
             "every run fits its standard model (SysId, one solve, seed 0) and scored once on its test data. "
             "*standard* is SysId's `standard` configuration: the rigid-body base parameters plus, on each joint, "
             "Coulomb and viscous friction, the rotor's inertia and a torque offset, by least squares (Khalil & "
             "Dombre 2002); *friction alone* leaves out the rotor inertia and the offset, as the suite's standard "
             "model did before. *feasible* is SysId's `feasible` configuration, the rigid bodies held feasible and "
             "friction and rotor inertia held at 0 or above.", "",
             "| arm | split | model | train MSE | test MSE | test / friction alone | mass matrix positive definite | "
             "joint columns dropped | joint columns whose standard error exceeds their value |",
             "|---|---|---|---:|---:|---:|---|---|---|"]
    for system, splits in models.items():
        for split, row in splits.items():
            for key, label, _, against in MODELS:
                m, base = row[key], row[against]
                lines.append(f"| {system} | {split} | {label} | {m['train_mse']:.4g} | {m['test_mse']:.4g} | "
                             f"{m['test_mse'] / base['test_mse']:.3f}x | {_yes(m['mass_matrix_positive_definite'])} | "
                             f"{', '.join(m['dropped_joint_columns']) or '—'} | "
                             f"{', '.join(m['joint_columns_not_significant']) or '—'} |")
    lines += ["", "## The published pages read against friction alone", "",
              "Each folder of records below was made when the standard model had friction alone. Its records hold "
              "that model's test MSE, which the same fit here gives again (*refitted*). Read against the field's "
              "standard model, each \"x the standard model\" figure of a learner on its pages is the page's figure "
              "times the factor. The figures of a hybrid on the `standard` or `feasible` prior, and of "
              "`loop_feasible`, are not remade by it: their prior or start had friction alone.", "",
              "| records | system | split | runs | standard model's test MSE in the records | refitted, friction "
              "alone | the field's standard model | factor |", "|---|---|---|---:|---:|---:|---:|---:|"]
    for (folder, system, split), values in sorted(pages.items()):
        row = models.get(system, {}).get(split)
        if row is None:
            lines.append(f"| {folder} | {system} | {split} | {len(values)} | {_values(values)} | — | — | — |")
            continue
        old, new = row["standard_friction_alone"]["test_mse"], row["standard"]["test_mse"]
        lines.append(f"| {folder} | {system} | {split} | {len(values)} | {_values(values)} | {old:.4g} | {new:.4g} | "
                     f"{row['factor']:.3f} |")
    return "\n".join(lines) + "\n"


def _yes(value) -> str:
    return "—" if value is None else "yes" if value else "**no**"


def _values(values: list[float]) -> str:
    distinct = sorted(set(np.round(values, 12)))
    return ", ".join(f"{v:.4g}" for v in distinct)


#: the subcommand's one-line help


def add_arguments(parser) -> None:
    parser.add_argument("--out", type=Path, default=Path("results/measured/standard_model.md"),
                        help="the page to write (default results/measured/standard_model.md); its numbers go "
                             "beside it, in a .json of the same name")


def main(args) -> int:
    check_output(args.out)
    check_output(args.out.with_suffix(".json"))
    models, pages = measure(), published()
    text = report(models, pages)
    atomic_write(args.out, lambda f: f.write(text))
    write_json(args.out.with_suffix(".json"), {
        "command": args.invocation, "provenance": provenance(), "models": models,
        "published": [{"records": folder, "system": system, "split": split, "runs": len(values),
                       "recorded_test_mse": sorted(set(values))} for (folder, system, split), values in pages.items()]})
    print(text)
    print(f"wrote {args.out}")
    return 0
