"""The residual loop's outputs: the JSON contract and a markdown report with
residual-versus-state plots before and after the loop."""

from __future__ import annotations

from pathlib import Path

from bench.core.data import Dataset
from bench.core.fileio import atomic_write, write_json
from bench.evaluation.driven import describe as describe_driven, pooled
from bench.evaluation.per_joint import percent
from bench.reporting.plots import residual_plot
from bench.residual.result import ResidualResult
from bench.runner.provenance import made_at


def write_outputs(result: ResidualResult, train: Dataset, test: Dataset | None, json_path=None, report_path=None) -> None:
    """Write the JSON (:meth:`ResidualResult.to_json`) and the report.

    Each file is written atomically; the plot and the report's text are made
    before the JSON and the report are written. A result without its models
    (one taken from the loop's checkpoint, :func:`bench.residual.job.run_residual`)
    has a report without the plot.
    """
    if report_path is not None:
        report_path = Path(report_path)
        data = test if test is not None else train
        plot = None
        if result.models is not None and data is not None:
            first, final = result.models
            split = "test" if test is not None else "train"
            stem = report_path.with_suffix("")
            plot = residual_plot(data, data.tau - first.predict_torque(data), Path(f"{stem}_residuals.png"),
                                 title=f"{result.system}, {result.method}: torque residual on the {split} set, "
                                       "before and after the loop",
                                 after=data.tau - final.predict_torque(data)).name
        text = markdown(result, plot)
    if json_path is not None:
        write_json(json_path, result.to_json())
    if report_path is not None:
        atomic_write(report_path, lambda f: f.write(text))


def _cell(x) -> str:
    return "—" if x is None else f"{x:.4g}"


def _ratio(x, y) -> str:
    return "—" if x is None or y is None or y == 0 else f"{x / y:.3g}"


def markdown(result: ResidualResult, plot_name: str | None = None) -> str:
    """The report: errors before and after, the effects, the rounds."""
    b, a = result.mse_before, result.mse_after
    lines = _heading(result)
    most = unexplained_line(result)
    if most:
        lines += [f"**{most}**", ""]
    if result.stopped:
        lines += [f"**Stopped early:** {result.stopped}.", ""]
    lines += [
        "| torque MSE | train | test |",
        "|---|---:|---:|",
        f"| before (declared model only) | {_cell(b['train'])} | {_cell(b['test'])} |",
        f"| after (with the effects below) | {_cell(a['train'])} | {_cell(a['test'])} |",
        f"| after ÷ before | {_ratio(a['train'], b['train'])} | {_ratio(a['test'], b['test'])} |",
        "",
    ]
    lines += per_joint_table(result.per_joint) + _physics(result) + _effects(result)
    lines += [""] + summary_lines(result)
    lines += ["", "Rounds:", ""] + [_round_line(r) for r in result.rounds]
    if plot_name:
        lines += ["", f"![residuals before and after]({plot_name})"]
    if result.lagrangian:
        lines += ["", "Final Lagrangian:", "", f"    {result.lagrangian}"]
    lines += _inputs(result.inputs, result.provenance)
    return "\n".join(lines) + "\n"


def _heading(result: ResidualResult) -> list[str]:
    """The report's title and its data, budget, times and held-out protocol."""
    return [
        f"# Residual loop: {result.system}, {result.method}",
        "",
        f"Training data: `{result.train_source}`; test data: `{result.test_source}`. "
        f"{_budget(result)}, seed {result.seed}; "
        f"{result.seconds:g} s in all"
        + (f", {result.loop_seconds:g} s of it the fit and the rounds" if result.loop_seconds is not None else "")
        + (f", {result.statistics_seconds:g} s the loop's statistics" if result.statistics_seconds is not None else "")
        + (f", {result.rollout_seconds:g} s the driven rollouts after the rounds" if result.rollout_seconds is not None else "")
        + f". Held out: {result.validation}"
        + (f"; what it holds out: {result.heldout_holds_out}" if result.heldout_holds_out else "") + ".",
        "",
    ]


def _physics(result: ResidualResult) -> list[str]:
    """What the report says of the final model as physics: a mass matrix not positive definite, the rigid
    bodies' feasibility, and the driven rollouts of the test recordings."""
    lines = []
    mass = result.mass_matrix
    if mass and not mass["positive_definite"]:
        lines += [f"The final model's mass matrix is not positive definite at the {mass['states']} training states "
                  f"checked (smallest eigenvalue {mass['smallest_eigenvalue_after']:.4g}): the fitted Lagrangian "
                  "is not a physical one there.", ""]
    feasible = result.feasibility
    if feasible:
        def eigen(part):
            return ", ".join(f"{x:.3g}" for x in feasible[part]["smallest_eigenvalues"])

        lines += [f"The rigid bodies' inertial parameters {'are' if feasible['after']['feasible'] else 'are not'} "
                  f"physically feasible after the loop ({'were' if feasible['before']['feasible'] else 'were not'} "
                  f"before). Smallest pseudo-inertia eigenvalue of each body, before: {eigen('before')}; "
                  f"after: {eigen('after')}. Masses after: "
                  + ", ".join(f"{m:.4g}" for m in feasible["after"]["masses"]) + ".", ""]
    if result.rollout:
        def driven(entry):
            return "; ".join(f"{k} s: " + describe_driven(*pooled([w]), lambda x: f"{x:.4g} rad")
                             for k, w in entry.get("windows", {}).items()) or entry.get("detail") or entry.get("status", "")
        lines += [f"Driven rollouts of the test recordings under their measured torques, median q RMSE over all "
                  f"windows (a diverged window counted as infinitely far): before {driven(result.rollout['before'])}; "
                  f"after {driven(result.rollout['after'])}.", ""]
    return lines


def _effects(result: ResidualResult) -> list[str]:
    """The table of the effects and findings, each law with its parameters and standard errors."""
    if not result.effects:
        return []
    lines = ["| effect | kind | law | joints | parameters (± std. error) |", "|---|---|---|---|---|"]
    for e in result.effects:
        name = f"symbolic: `{e['expression']}`" if e.get("expression") else e["name"]
        params = ", ".join(f"{k} = {p['value']:.6g} ± {p['stderr']:.2g}" for k, p in e["parameters"].items()) \
            or e.get("finding", "")
        if e.get("reference_joint"):
            params += f" (relative to joint {e['reference_joint']})"
        if e.get("per_recording"):
            params += "; each recording's own: " + ", ".join(f"{k} {p['value']:.4g} ± {p['stderr']:.2g}"
                                                             for k, p in e["per_recording"].items())
        joints = ", ".join(map(str, e["joints"]))
        lines.append(f"| {name} | {e['kind']} | `{e['law']}` | {joints} | {params} |")
    return lines


def _round_line(r: dict) -> str:
    """One round of the report's list: its test and held-out MSEs, what it added and dropped, why it stopped,
    the best term its trace rejected, and its laws the data could not tell apart."""
    added = ", ".join(r["accepted"]) or "nothing"
    removed = f"; dropped as redundant: {', '.join(r['removed'])}" if r.get("removed") else ""
    stop = f" ({r['stop']})" if r.get("stop") else ""
    last = next((t for t in reversed(r["trace"]) if "term" in t and not t["accepted"]), None)
    why = ""
    if last:
        t, gain = last.get("t"), last.get("heldout_gain")
        why = (f" (best rejected: {last['term']}, BIC drop {last['bic_drop']:.3g}"
               + ("" if "t" not in last else f", |t| {'∞' if t is None else format(t, '.3g')}")
               + ("" if gain is None else f", held-out gain {gain:.2%}") + ")")
    held = f", held out {_cell(r['heldout_mse'])}" if r.get("heldout_mse") is not None else ""
    same = "".join(f"; equivalent on these data: {' ≡ '.join([e['kept'], *e['equivalent']])}"
                   for e in r.get("equivalent") or ())
    return f"- round {r['round']}: test MSE {_cell(r['mse']['test'])}{held}; added {added}{removed}{stop}{why}{same}"


#: a final model that leaves more than this share of the training torques' variance has left most of it
MOST = 0.5


def _left(result: ResidualResult) -> str:
    """What the final model leaves of the training torques' variance, pooled and per joint, in words."""
    u = result.unexplained
    joints = ", ".join(f"{x:.0%}" for x in u["per_joint"])
    return f"{u['train']:.0%} of the training torques' variance (per joint {joints})"


def unexplained_line(result: ResidualResult) -> str:
    """Where the final model leaves most of the training torques' variance (:data:`MOST`), a sentence that says so
    in numbers; else empty (as for a result that does not carry :attr:`~ResidualResult.unexplained`)."""
    if not result.unexplained or not result.unexplained["train"] > MOST:
        return ""
    return (f"Most of the torque is unexplained: the final model leaves {_left(result)}; what it lacks is none "
            f"of the laws the loop tried, or one that failed a test (the rounds below say which)")


def summary_lines(result: ResidualResult) -> list[str]:
    """Why the loop ended and what that means for the laws it reports, in sentences
    (the report's and the console's): where nothing was added, whether the residual held
    nothing significant or the budget, an undone round or a failure ended the loop, with
    the laws the last round had found and the budget it would have needed; then every
    law that the data could not tell from others, with the rule that kept it."""
    ending = result.ending or {}
    reason, lines = ending.get("reason"), []
    most = unexplained_line(result)
    if most:
        lines.append(most + ".")
    added = [e for e in result.effects if "finding" not in e]
    found = ending.get("found") or []
    laws = ", ".join(f"{f['law']}" + ("" if f.get("heldout_gain") is None else
                                      f" (held-out gain {f['heldout_gain']:.1%} in the trace)") for f in found)
    held = ending.get("heldout_mse")
    with_them = "" if not held else (f"; with them refitted, the held-out MSE went from {held['before']:.4g} to "
                                     f"{held['with_them']:.4g}")
    if reason == "budget":
        head = "No effect added: the budget ended the loop, not the residual" if not added else \
            "The budget ended the loop before the residual did"
        lines.append(f"{head}: {ending['detail']}.")
        if found:
            lines.append(f"Round {ending['round']} had found {len(found)} law(s) before it was undone: {laws}{with_them}.")
        needed = ending.get("budget_needed_s") or {}
        if "more_than" in needed:
            lines.append(f"A time budget of more than {needed['more_than']:g} s would let the round finish "
                         f"({needed['estimate']}); --steps N bounds the loop by work instead, and every round finishes.")
        elif "at_least" in needed:
            lines.append(f"A time budget of at least {needed['at_least']:g} s would let the round run "
                         f"({needed['estimate']}); --steps N bounds the loop by work instead.")
    elif reason == "undone" and not added:
        lines.append(f"No effect added: round {ending['round']} found {laws or 'laws'}{with_them}, but "
                     f"{ending['detail'].split(': ', 1)[-1]}, so it was undone.")
    elif reason == "failed":
        lines.append(f"{'No effect added: ' if not added else ''}{ending['detail']}; the rounds before it are kept.")
    elif not added:
        lines.append("No effect added: no law passed every test (significance, held-out gain, physical sense) on a "
                     "residual of " + (_left(result) if result.unexplained else "the declared model") + ".")
    for entry in result.equivalent_laws or ():
        figures = ", ".join(f"{law} {mse:.3g}" for law, mse in entry["heldout_mse"].items())
        lines.append(f"Equivalent on these data (round {entry['round']}): {' ≡ '.join([entry['kept'], *entry['equivalent']])}: "
                     f"held-out MSE {figures}, each within the standard error of its difference from the first's, "
                     f"or at round-off; kept {entry['kept']} by {entry.get('chosen_by', entry['rule'])}.")
    return lines


def _inputs(inputs: dict | None, provenance: dict) -> list[str]:
    """The report's last section: what it was made from (:attr:`ResidualResult.inputs`)."""
    if not inputs:
        return []
    lines = ["", "## Made from", "", f"    {inputs['command']}" if inputs.get("command") else "    (no command line)", ""]
    given = ", ".join(f"{k}={v}" for k, v in inputs.get("set", {}).items()) or "none"
    lines.append(f"- configuration `{inputs.get('configuration', 'default')}`; --set: {given}; "
                 f"{made_at(provenance, 10)}")
    for path, entry in inputs.get("files", {}).items():
        convert = entry.get("convert")
        made = "" if not convert else f"; converted by `{convert.get('command', 'convert')}`"
        lines.append(f"- `{path}`: sha256 {entry['sha256'][:16]}…{made}")
    return lines


def _budget(result: ResidualResult) -> str:
    """The loop's budget in words: seconds with the fit's share, or steps of work."""
    if (result.budget or {}).get("kind") == "steps":
        return f"a work budget of {result.budget['steps']} steps for the method's fit (and each cross-fit)"
    return f"{result.budget_s:g} s for the loop ({result.fit_budget_s:g} s of it the method's fit)"


def per_joint_table(before_after: dict | None) -> list[str]:
    """Per test trajectory, each joint's test MSE and nMSE before and after the
    loop, against the logged torque too where it is known, with the filter's noise floor."""
    if not before_after:
        return []
    lines = []
    for name, b in before_after["before"]["trajectories"].items():
        a = before_after["after"]["trajectories"][name]
        logged = "mse_logged" in b
        head = "| joint | MSE before | after | nMSE % before | after |"
        rule = "|---:|---:|---:|---:|---:|"
        if logged:
            head += " logged: MSE before | after | nMSE % before | after | noise floor MSE | nMSE % |"
            rule += "---:|---:|---:|---:|---:|---:|"
        lines += [f"Test trajectory {name} ({b['n']} samples), per joint: against the scored torque"
                  + (", and against the logged torque, unfiltered, beside the filter's noise floor (the MSE "
                     "between the two torques)" if logged else "") + ".", "", head, rule]
        for j in range(len(b["mse"])):
            row = (f"| {j + 1} | {b['mse'][j]:.4g} | {a['mse'][j]:.4g} | {percent(b['nmse'][j])} | "
                   f"{percent(a['nmse'][j])} |")
            if logged:
                row += (f" {b['mse_logged'][j]:.4g} | {a['mse_logged'][j]:.4g} | {percent(b['nmse_logged'][j])} | "
                        f"{percent(a['nmse_logged'][j])} | {b['noise_floor'][j]:.4g} | "
                        f"{percent(b['noise_floor_nmse'][j])} |")
            lines.append(row)
        lines.append("")
    return lines
