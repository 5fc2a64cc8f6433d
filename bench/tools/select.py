"""``python -m bench select``: one model of a measured arm, chosen by validation
on its training data alone, fitted on all of it and scored on the test data once.

The candidates (:data:`CANDIDATES`) are the field's models of a real arm: the
standard model, the feasible rigid body with nonnegative joint friction,
hybrids of either with a learned residual, the residual loop's model from
SysId's rigid body alone and from its feasible body with friction on each
joint (``loop_feasible``: which start generalises better is a question for
validation), and the first loop's model with a Gaussian process of what it
leaves. Each
is one run of the matrix with ``--tune`` (:mod:`bench.evaluation.tuning`):
its hyperparameters chosen by the
suite's validation protocol (:mod:`bench.core.folds`) on the training
trajectories, within the run's budget, then fitted on all the training data
and saved (:mod:`methods.saving`). Every candidate is bounded by work, so
that the same command gives the same page on any machine: its own steps
(:meth:`Candidate.steps`: a learned residual's grow with the training
samples) unless ``--steps`` gives them all one count, the seconds only a
ceiling. ``loop`` runs its rounds until one accepts nothing,
and ``loop+gp``'s prior does the same before its residual's steps start
(:mod:`bench.residual.prior`). Its folds are by default ``pooled``
(:mod:`bench.core.protocols`): regions of the states of one, two or three
training trajectories pooled, so that each fold is fitted on part of every
one, and whole trajectories of more. The candidate chosen is the one with the
lowest validation MSE, or, where two or three trajectories are each left out
whole (``--folds time`` or ``auto``), the one whose fold scores agree best
among those within one standard error of it (:func:`choose`); the test data
are read by each run to score it, and nothing is chosen on them. The runs' records are kept, so that the same
command resumes where it stopped, as a matrix does.

Writes ``DIR/select.json`` (``chosen`` and ``candidates``, each with its
``name``, ``validation_mse`` and ``test_mse``; ``test_informed``, the test
trajectories that chose a setting of the system's file), ``DIR/select.md``
(every candidate's validation and test figures side by side, ranked by each,
flagged where they are test-informed) and ``DIR/model.npz``, the chosen
model (``python -m bench predict``).

Beside the choice, ``select.json``'s ``stack`` and the page give the
candidates' stack (:func:`stacked`, :mod:`bench.evaluation.stacking`):
convex weights fitted on their held-out predictions, its nested
validation MSE, and its test MSE, read after the choice to score
(:mod:`bench.tools.stack_score`). It is reported, not chosen: the model kept
is one candidate's.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from bench.core.data import Dataset
from bench.core.errors import UserError
from bench.core.distance import TrainingStates
from bench.core.fileio import atomic_write, write_json
from bench.core.modelfile import ModelFileError
from bench.core.protocols import folds as fold_data, parse as parse_protocol, resolve as resolve_protocol
from bench.evaluation import stacking
from bench.evaluation.domain import domain, sentences
from bench.evaluation.tuning import MAX_FOLDS, PROTOCOL, SCORE_RULE
from bench.runner import matrix
from bench.runner.provenance import provenance
from bench.runner.records import Record, record_path
from bench.runner.spec import RunSpec
from bench.tools import stack_score
from bench.tools.candidates import CANDIDATES, GP_EPOCHS, Candidate  # noqa: F401  (select's, by name)
from methods import METHODS
from methods.saving import held_out
from systems import SYSTEMS


#: the learned residuals' steps at least: a GP's (:mod:`methods.gp`) and a network's (the MLP's, DeLaN's), the
#: work each method declares (:attr:`methods.base.Method.work`)
GP_STEPS, NETWORK_STEPS = METHODS["gp"].work, METHODS["mlp"].work
def specs(system: str, split: str | None, budget_s: float | None, steps: int | None, seed: int, out: Path,
          plugins: tuple[str, ...], candidates=CANDIDATES, rollout: bool = False,
          protocol: str | None = None, samples: int | None = None) -> list[tuple[Candidate, RunSpec]]:
    """Each candidate's tuned run (validated by ``protocol``'s folds, :mod:`bench.core.protocols`), its model
    file under ``out/models``; their records go to ``out/runs`` (two configurations of one method, SysId's
    standard and feasible bodies, are two runs: :func:`bench.runner.spec.run_id`). Without ``steps``, each
    does its own (:meth:`Candidate.steps` on the ``samples`` of the training data)."""
    out = Path(out).resolve()
    rows = []
    for c in candidates:
        spec = RunSpec(system=system, method=c.method, experiment="indirect", seed=seed,
                       budget_s=budget_s,
                       steps=c.steps(samples) if steps is None else steps, profile=c.profile, hyperparameters=dict(c.fixed),
                       split=split, plugins=plugins,
                       tune=True, rollout=rollout, save=str(out / "models" / f"{c.name.replace('+', '_')}.npz"),
                       folds=protocol)
        rows.append((c, spec))
    return rows


def run(rows, out: Path, workers: int | None, report=print, cluster=None) -> list[tuple[Candidate, Record]]:
    """The candidates' runs, as one matrix in ``out/runs`` (resumed from their records), started in the order of
    their :attr:`Candidate.start`: the longest first, so that the workers end together; on a Dask ``cluster``
    (:mod:`bench.runner.cluster`) each is a task, whose record and model file come back to ``out``."""
    folder = Path(out).resolve() / "runs"
    for _, spec in rows:  # a run whose model file is missing is redone: the file is part of its result
        path = record_path(folder, spec.run_id)
        if path.exists() and not Path(spec.save).exists():
            path.unlink()
    ordered = sorted(rows, key=lambda row: row[0].start)
    report(f"select: {len(rows)} candidate(s) in {folder}: {', '.join(c.name for c, _ in ordered)}")
    records = matrix.run_matrix([s for _, s in ordered], folder, workers=workers, cluster=cluster, share_priors=True)
    done = dict(zip((c.name for c, _ in ordered), records))
    return [(c, done[c.name]) for c, _ in rows]


def entry(candidate: Candidate, record: Record, out: Path) -> dict:
    """A candidate's line of ``select.json`` (its model file's path relative to ``out``)."""
    details = record.details or {}
    saved = (details.get("saved") or {}).get("path")
    tuning = details.get("tuning") or {}
    standard = (details.get("standard_model") or {}).get("test_mse")
    chosen = next((c for c in tuning.get("combinations") or [] if c.get("hyperparameters") == tuning.get("chosen")
                   and c.get("validation_mse") is not None), None)
    folds = [v for v in (chosen or {}).get("fold_mse") or [] if v is not None]
    return {"name": candidate.name, "method": record.method, "status": record.status,
            "validation_mse": tuning.get("validation_mse"), "validation_far_mse": tuning.get("validation_far_mse"),
            "test_mse": record.test_mse,
            "validation_stderr": float(np.std(folds, ddof=1) / np.sqrt(len(folds))) if len(folds) > 1 else None,
            "fold_mse": folds or None,
            "train_mse": record.train_mse, "test_over_standard": None if not (standard and record.test_mse) else
            record.test_mse / standard, "hyperparameters": tuning.get("chosen", {}),
            "model": None if saved is None else os.path.relpath(saved, Path(out).resolve()),
            "budget": record.describe_budget(), "error": record.error_line or
            (record.failed_stages.get("save") if record.failed_stages else None), "run_id": record.run_id,
            "work": tuning.get("work")}


def usable(entries: list[dict]) -> list[dict]:
    """The candidates that ran, validated and saved their model: those a choice may fall on."""
    return [e for e in entries if e["status"] == "ok" and e["validation_mse"] is not None
            and math.isfinite(e["validation_mse"]) and e["model"]]


#: the training trajectories under which select chooses by :data:`FEW_RULE` where its folds leave one trajectory
#: out (``--folds time``, or ``auto``), each fold then fitted on one or two trajectories
FEW_TRAJECTORIES = (2, 3)
FEW_RULE = ("where the training data hold two or three trajectories and each is left out whole, the candidate "
            "whose fold scores agree best (the least highest over lowest) among those whose validation MSE is "
            "within one standard error (over the folds) of the lowest: each fold is then fitted on one or two "
            "trajectories, farther from the final fit on all of them than the use will be, and the lowest mean of "
            "two or three such scores does not tell the candidates apart")
LOWEST_RULE = "the lowest validation MSE"


def spread(entry: dict) -> float:
    """A candidate's highest fold score over its lowest (``inf`` where it has fewer than two, or one is zero)."""
    folds = [v for v in entry.get("fold_mse") or [] if v is not None]
    return max(folds) / min(folds) if len(folds) > 1 and min(folds) > 0 else math.inf


def rule(trajectories: int | None, protocol: str | None = "time") -> str:
    """The rule select chooses by on training data of ``trajectories`` trajectories (``None``: unknown) validated
    by ``protocol``'s folds: :data:`FEW_RULE` where two or three trajectories are each left out whole."""
    few = trajectories in FEW_TRAJECTORIES and resolve_protocol(parse_protocol(protocol)[0], trajectories) == "time"
    return FEW_RULE if few else LOWEST_RULE


def choose(entries: list[dict], trajectories: int | None = None, protocol: str | None = "time") -> dict | None:
    """The candidate :func:`rule` chooses among :func:`usable`'s: the lowest validation MSE, or with two or
    three training ``trajectories`` each left out whole, among those within one standard error of it, the one
    whose fold scores agree best (:func:`spread`; ties to the lower validation MSE)."""
    candidates = usable(entries)
    if not candidates:
        return None
    lowest = min(candidates, key=lambda e: e["validation_mse"])
    if rule(trajectories, protocol) != FEW_RULE:
        return lowest
    bound = lowest["validation_mse"] + (lowest.get("validation_stderr") or 0.0)
    within = [e for e in candidates if e["validation_mse"] <= bound]
    return min(within, key=lambda e: (spread(e), e["validation_mse"]))


def stacked(entries: list[dict], out: Path, train: Dataset | None) -> dict:
    """The stack of the :func:`usable` candidates (:func:`bench.evaluation.stacking.stack`) from the held-out
    predictions their model files keep, with ``models`` (each one's file, relative to ``out``); or
    ``{"unavailable": why}``."""
    if train is None:
        return {"unavailable": "select was not handed the training data"}
    kept = []
    try:
        for e in usable(entries):
            predictions = held_out(Path(out) / e["model"])
            if predictions is not None:
                kept.append((e, predictions))
    except ModelFileError as exc:
        return {"unavailable": str(exc)}
    if len(kept) < 2:
        missing = len(usable(entries)) - len(kept)
        return {"unavailable": "fewer than two candidates kept their held-out predictions"
                + (f" ({missing} model file(s) made before tuned runs kept them: bench select into a new --out "
                   f"makes them again)" if missing else "")}
    first = kept[0][1]
    if not all(np.array_equal(h["index"], first["index"]) and np.array_equal(h["fold"], first["fold"])
               for _, h in kept):
        return {"unavailable": "the candidates were validated on different folds"}
    target = np.asarray(train.target("indirect"), np.float64)
    if (first["index"].size and first["index"].max() >= len(target)) or \
            any(h["prediction"].shape[1:] != target.shape[1:] for _, h in kept):
        return {"unavailable": "the candidates' held-out predictions are not of these training data"}
    target = target[first["index"]]
    result = stacking.stack([e["name"] for e, _ in kept], [h["prediction"] for _, h in kept], target, first["fold"])
    return {**result, "models": {e["name"]: e["model"] for e, _ in kept}}


def score_stack(stack: dict, entries: list[dict], out: Path, test: Dataset | None) -> dict:
    """``stack`` with its ``test_mse`` and ``test_over_standard``, scored after the choice
    (:mod:`bench.tools.stack_score`); as it is where it has no weights or there is no test data."""
    if "weights" not in stack or test is None:
        return stack
    models = {name: Path(out) / path for name, path in stack["models"].items()}
    try:
        value = stack_score.test_mse(models, stack["weights"], test)
    except (ModelFileError, ValueError, RuntimeError) as exc:  # the page says why the stack has no test figure
        return {**stack, "test_mse": None, "test_error": f"{type(exc).__name__}: {exc}"[:300]}
    standard = next((e["test_mse"] / e["test_over_standard"] for e in entries
                     if e.get("test_mse") and e.get("test_over_standard")), None)
    return {**stack, "test_mse": value, "test_over_standard": None if not standard else value / standard}


def page(result: dict) -> str:
    """``select.md``: every candidate's validation and test figures side by side."""
    entries = result["candidates"]
    ok = [e for e in entries if e["validation_mse"] is not None and e["test_mse"] is not None]
    by_validation = {e["name"]: i + 1 for i, e in enumerate(sorted(ok, key=lambda e: e["validation_mse"]))}
    by_test = {e["name"]: i + 1 for i, e in enumerate(sorted(ok, key=lambda e: e["test_mse"]))}
    chosen = result["chosen"]
    lines = [f"# A model of {result['system']}, chosen by validation", "",
             f"Command: `{result['command']}`"
             + (f"; this page written again from its select.json by `{result['page_only']['command']}` at commit "
                f"{result['page_only']['commit']}, its test-informed flags read again from the arm's declaration "
                f"(no figure changed)" if result.get("page_only") else ""), "",
             f"Split: {result['split'] or 'default'}; budget per candidate: {result['budget']}; "
             f"seed {result['seed']}. "
             f"Each candidate is {PROTOCOL} (validation folds: {result['folds'] or 'none'}) by successive halving over "
             f"work, each fold fit of the combination it keeps doing the steps of the final fit on all the training "
             f"data; its validation MSE is {SCORE_RULE}. Chosen: {result.get('rule') or LOWEST_RULE}; the "
             f"test data are read only to score. The test columns are there to show whether validation chose well.",
             ""]
    flag = informed_sentence(result)
    if flag:
        lines += [flag, ""]
    lines += ["| candidate | hyperparameters chosen | work: each fold fit → the final fit | validation MSE | "
              "each fold's validation MSE | validation MSE, farther half | test MSE | test / standard model | "
              "rank by validation | rank by test |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for e in entries:
        mark = " **(chosen)**" if chosen and e["name"] == chosen["name"] else ""
        hp = ", ".join(f"{k}={v}" for k, v in sorted(e["hyperparameters"].items())) or "—"
        if e["status"] != "ok" or e["validation_mse"] is None:
            lines.append(f"| {e['name']}{mark} | {hp} | {work_cell(e.get('work'))} | {e['status']}: "
                         f"{e['error'] or 'no validation'} | | | | | | |")
            continue
        ratio = "—" if e["test_over_standard"] is None else f"{e['test_over_standard']:.3f}x"
        far = "—" if e.get("validation_far_mse") is None else f"{e['validation_far_mse']:.4g}"
        lines.append(f"| {e['name']}{mark} | {hp} | {work_cell(e.get('work'))} | {e['validation_mse']:.4g} | "
                     f"{spread_cell(e)} | {far} | "
                     f"{e['test_mse']:.4g} | {ratio} | {by_validation.get(e['name'], '—')} | {by_test.get(e['name'], '—')} |")
    lines.append("")
    if chosen:
        best = min(ok, key=lambda e: e["test_mse"]) if ok else None
        verdict = ("validation chose the candidate with the lowest test MSE too" if best and best["name"] == chosen["name"]
                   else f"the lowest test MSE was {best['name']}'s ({best['test_mse']:.4g})" if best else "")
        lines += [f"Chosen: **{chosen['name']}**, validation MSE {chosen['validation_mse']:.4g}, test MSE "
                  f"{chosen['test_mse']:.4g}" + (f" ({chosen['test_over_standard']:.3f}x the standard model)"
                                                  if chosen["test_over_standard"] else "") + f"; {verdict}. "
                  f"Its model: `model.npz` (`{predict_command(result)}`)."]
    else:
        lines.append("No candidate ran and validated: nothing chosen.")
    lines += stack_lines(result.get("stack"), chosen)
    report = result.get("domain")
    if report:
        lines += ["", "## What validation could see", "", sentences(report) + farther(entries, chosen)]
        if report.get("test_median_distance") is not None:
            beyond = report["test_median_distance"] > report["reach"]["median"]
            lines += ["", f"For comparison, read from the test trajectory's states after the choice (never to make "
                          f"it): it lies a median {report['test_median_distance']:.3g} from the training states, "
                          + ("beyond" if beyond else "within") + " what validation reached."]
    return "\n".join(lines) + "\n"


#: the least weight the page names a candidate of the stack with
SHOWN_WEIGHT = 1e-3


def stack_lines(stack: dict | None, chosen: dict | None) -> list[str]:
    """The page's paragraph on the candidates' stack (:func:`stacked`)."""
    if not stack:
        return []
    if "weights" not in stack:
        return ["", f"The candidates' stack: unavailable ({stack['unavailable']})."]
    used = ", ".join(f"{n} {w:.3g}" for n, w in sorted(stack["weights"].items(), key=lambda kv: -kv[1])
                     if w >= SHOWN_WEIGHT)
    rest = sum(w < SHOWN_WEIGHT for w in stack["weights"].values())
    nested = "—" if stack["validation_mse"] is None else f"{stack['validation_mse']:.4g}"
    test = (f"; no test figure ({stack['test_error']})" if stack.get("test_error") else "") \
        if stack.get("test_mse") is None else (
        f"; test MSE {stack['test_mse']:.4g}" + (f" ({stack['test_over_standard']:.3f}x the standard model)"
                                                  if stack.get("test_over_standard") else ""))
    beside = "" if chosen is None else f", against the chosen candidate's {chosen['validation_mse']:.4g}"
    others = f" (the other {rest} under {SHOWN_WEIGHT:g})" if rest else ""
    return ["", f"The candidates' stack (convex weights fitted on their held-out predictions, "
                f"`bench.evaluation.stacking`): weights {used or 'none'}{others}; validation MSE {nested} (nested: "
                f"each fold scored with the weights of the others){beside}{test}. It is reported beside the choice, "
                f"not chosen."]


def farther(entries: list[dict], chosen: dict | None) -> str:
    """The page's sentence on the farther half of the folds' scored samples (:data:`bench.evaluation.tuning.FAR_RULE`): which candidate
    validation puts first there, beside the choice."""
    far = [e for e in usable(entries) if e.get("validation_far_mse") is not None]
    if not far or chosen is None:
        return ""
    ranked = [e["name"] for e in sorted(far, key=lambda e: e["validation_far_mse"])]
    then = f" (then {', '.join(ranked[1:3])})" if len(ranked) > 1 else ""
    same = ("the candidate chosen on all of them" if ranked[0] == chosen["name"] else
            "not the candidate chosen on all of them: the ranking changes as validation moves away from the fit")
    return (f" Scored on the farther half of each fold's samples only (those at least the fold's median distance "
            f"from the states it is fitted on), validation puts {ranked[0]} first{then}: {same}.")


def spread_cell(entry: dict) -> str:
    """A candidate's validation MSE on each fold, lowest to highest, and their :func:`spread`: how far the folds
    agree (``—`` for a record made before tuning kept them)."""
    if not entry.get("fold_mse"):
        return "—"
    ratio = spread(entry)
    return ", ".join(f"{v:.4g}" for v in sorted(entry["fold_mse"])) + (f" ({ratio:.3g}x)" if math.isfinite(ratio) else "")


def work_cell(work: dict | None) -> str:
    """The work of a candidate's fold fits beside its final fit's: median steps and seconds of the
    folds → the final fit's (``—`` for a record made before tuning recorded it)."""
    if not work:
        return "—"
    folds = [s for s in work.get("fold_steps") or [] if s is not None]
    seconds = work.get("fold_fit_seconds") or []

    def median(xs):
        xs = sorted(xs)
        return xs[len(xs) // 2] if xs else None

    fold = (f"{median(folds):g} steps, {median(seconds):.3g} s" if folds and seconds else "not fitted")
    return f"{fold} → {work.get('final_steps')} steps, {work.get('final_fit_seconds', 0):.3g} s"


def applicability(train: Dataset, test: Dataset | None, target: Dataset | None, protocol: str | None = None) -> dict:
    """:func:`bench.evaluation.domain.domain` on the training data, folded as tuning folds them, with
    ``test_median_distance``: the test states' distance, for the page's comparison after the choice."""
    report = domain(train, fold_data(train, protocol, MAX_FOLDS, target), target)
    report["test_median_distance"] = None if test is None else \
        float(np.median(TrainingStates(train).distance(test)))
    report["test_beyond_reach"] = None if test is None else report["test_median_distance"] > report["reach"]["median"]
    return report


def test_informed(system: str, split: str | None) -> dict:
    """The test trajectories of ``split`` whose torques chose a setting of the file that declares the system (its
    filter's cut-off: ``[filter] chosen_on``) or were read while a rule was chosen (``[informed]``), so that a test
    figure rests on a choice that read them, and what rests on them in words: the page's ``test_informed`` and
    ``test_informed_by``; none for a system that no such file declares."""
    declaration = getattr(SYSTEMS[system], "measured", None)
    if declaration is None:
        return {"test_informed": [], "test_informed_by": []}
    return {"test_informed": declaration.test_informed(split or "default"),
            "test_informed_by": declaration.informed_by(split or "default")}


def informed_sentence(result: dict) -> str | None:
    """The page's flag where its test figures are test-informed (:func:`test_informed`)."""
    informed = result.get("test_informed")
    if not informed:
        return None
    by = result.get("test_informed_by") or ["the cut-off of the filter that the system's file declares "
                                            "(`[filter] chosen_on`)"]
    return (f"**Test-informed:** the test trajectories {', '.join(informed)} were read while these were chosen: "
            f"{'; '.join(by)}. Every test figure below rests on a choice that read their torques. The choice of "
            f"candidate read none of them.")


def predict_command(result: dict) -> str:
    """How to use the chosen model: ``bench predict``, naming the file that declares the arm where it is not
    built in (``declared``, the ``--system`` given: ``urdf:PATH`` or ``measured:PATH``)."""
    declared = f" --system {result['declared']}" if result.get("declared") else ""
    return f"python -m bench predict --model model.npz{declared} --log LOG.csv --out PRED.csv"


def repage(out: Path, command: str) -> dict:
    """``out``'s ``select.json`` with its test-informed flags read again from the system's declaration
    (:func:`test_informed`), and ``select.md`` written again from it; nothing is run and no figure changes."""
    made = Path(out) / "select.json"
    if not made.is_file():
        raise UserError(f"{made}: no select page to write again; run bench select into {out} first")
    result = json.loads(made.read_text())
    if result.get("system") not in SYSTEMS:
        raise UserError(f"{made}: its system {result.get('system')!r} is not registered here; name its file with "
                        f"--system")
    result.update(test_informed(result["system"], result.get("split")))
    result["page_only"] = {"command": command, "commit": provenance().get("commit")}
    write_json(made, result)
    text = page(result)
    atomic_write(Path(out) / "select.md", lambda f: f.write(text))
    return result


def select(system: str, out: Path, *, split: str | None, budget_s: float | None, steps: int | None, seed: int,
           workers: int | None, plugins: tuple[str, ...], command: str, candidates=CANDIDATES, rollout: bool = False,
           report=print, data: tuple[Dataset, Dataset | None] | None = None, target: Dataset | None = None,
           protocol: str | None = None, cluster=None, declared: str | None = None) -> dict:
    """Run the candidates, choose one, write ``select.json``, ``select.md`` and ``model.npz`` into ``out``.
    ``declared`` is the ``--system`` as given where a file declares the arm (``measured:PATH``), which
    ``bench predict`` then needs too.
    ``data`` is the system's training and test data, for the page's report of what validation could see
    (with ``target``, the states the user says the model will be asked: :mod:`bench.evaluation.domain`).
    ``protocol`` names the validation folds (:mod:`bench.core.protocols`)."""
    out = Path(out)
    rows = specs(system, split, budget_s, steps, seed, out, plugins, candidates, rollout, protocol,
                 samples=None if data is None else len(data[0]))
    done = run(rows, out, workers, report, cluster)
    entries = [entry(c, r, out) for c, r in done]
    trajectories = None if data is None else len(data[0].trajectories())
    chosen = choose(entries, trajectories, protocol)
    folds = next(((r.details or {}).get("tuning", {}).get("folds", {}).get("description") for _, r in done
                  if (r.details or {}).get("tuning", {}).get("folds")), None)
    ceiling = f", at most {budget_s:g} s" if budget_s is not None else ""
    budget = f"{steps} steps{ceiling}" if steps is not None else f"each candidate's own steps (its work column){ceiling}"
    result = {"system": system, "declared": declared, "split": split, "seed": seed, "budget": budget, "command": command,
              "protocol": PROTOCOL, "folds_protocol": protocol or "time", "folds": folds,
              "training_trajectories": trajectories, "rule": rule(trajectories, protocol), "chosen": chosen, "candidates": entries,
              "domain": None if data is None else applicability(data[0], data[1], target, protocol),
              **test_informed(system, split),
              "stack": score_stack(stacked(entries, out, None if data is None else data[0]), entries, out,
                                   None if data is None else data[1])}
    if chosen:
        content = (out / chosen["model"]).read_bytes()
        atomic_write(out / "model.npz", lambda f: f.write(content), binary=True)
        result["model"] = "model.npz"
    write_json(out / "select.json", result)
    text = page(result)
    atomic_write(out / "select.md", lambda f: f.write(text))
    return result
