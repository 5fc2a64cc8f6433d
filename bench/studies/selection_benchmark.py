"""``python -m bench study selection``: how well each way of choosing a model
chooses, on arms whose truth is known.

Each case is a simulated arm (the Panda, the UR5, the KUKA's URDF) whose
torque holds laws the rigid body lacks (:data:`EFFECT_SETS`), logged as a robot
logs it (:func:`bench.tools.robot_log.fourier_trajectory`: excitation
trajectories of finite Fourier series) and declared as a measured arm of
one's own (a TOML file beside its logs). Its layouts:

* ``one``: one training trajectory recorded twice, tested on another
  trajectory :data:`FASTER` times as fast, as the shipped KUKA's;
* ``two`` and ``three``: two or three training trajectories, each recorded
  twice, tested on another, as an identification lab records an arm;
* ``several``: :data:`SEVERAL` training trajectories, tested on another.

Beside the shipped arms' URDFs, the development set has a large geared
industrial arm (``geared``, :mod:`bench.studies.geared_arm`): its rotors'
inertia, heavy friction and a shoulder counterbalance, its torque the
motor's with a motor current's noise, in the ``two`` layout.

(A third, ``long``, is not among the benchmark's cases: :data:`LONG`
trajectories of :data:`LONG_SECONDS`, the last the test; ``python -m bench
study long-log`` runs ``bench select`` at its default on it.)

On each case ``bench select`` runs once per validation protocol
(:mod:`bench.core.protocols`: ``time``, select's folds before it had others;
``auto``, its default until ``pooled``; ``pooled``, its default, :func:`resolve`;
``regions``; and ``knndm`` where the training data hold several trajectories), under a work budget (``--steps``),
so that the study gives the same numbers on any machine; a protocol that
gives a case the folds of another shares its run. Each run is a job of the
one scheduler (:class:`SelectCase`): the cases run one after another, each
``bench select`` its candidates ``--workers`` at a time, or each case a task
of a Dask ``--cluster``; each is kept as it finishes (``PAGE.partial.jsonl``),
and the same command run again resumes from them. Each run's
candidates are then chosen by each rule (:data:`RULES`):

* ``lowest``: the lowest validation MSE (``bench select``'s);
* ``one_se``: the first candidate in :data:`SIMPLICITY` (from the rigid body
  to the flexible residuals) whose validation MSE is within one standard
  error (over the folds) of the lowest;
* ``farther``: the lowest validation MSE on the farther half of each fold's
  scored samples only (:data:`bench.evaluation.tuning.FAR_RULE`), the half
  that lies as far from the fit as validation reaches;
* ``stack``: the lowest validation MSE among the candidates and their stack
  (:mod:`bench.evaluation.stacking`: convex weights fitted on the
  candidates' held-out predictions, its validation MSE nested), which ``bench
  select`` reports beside its choice. Its regret may be under 1: the stack is
  not one of the candidates it is compared with.

A case's **regret** under a protocol and a rule is the chosen candidate's test
MSE over the best candidate's; the page gives it per case with the rank
correlation (Spearman) between validation and test, and per protocol and rule
the median and worst regret and how often the best was chosen.

The shipped real arms (:data:`REAL`: the KUKA and the DFKI pendulum, each split) go in as their
``bench select`` pages left them: each page's candidates are chosen by every rule, and their test MSEs
give the regret. ``--real-only`` reads those pages again into a published page, keeping its cases.

The **development** set (seeds :data:`DEVELOPMENT_SEEDS`) is for trying rules.
The **former evaluation** set (seeds :data:`FORMER_EVALUATION_SEEDS`, the
``one`` and ``several`` layouts) was the evaluation set until rules were
changed while its page was read; the **second evaluation** set (seeds
:data:`SECOND_EVALUATION_SEEDS`, every layout and the geared arm) was the
evaluation set until it had been run once and a method was then changed on
one of its cases; the **third evaluation** set (seeds
:data:`THIRD_EVALUATION_SEEDS`, the same layouts) was the evaluation set until
it had been run once and select's folds for few trajectories were then chosen
on its cases. All three are development data now, and their pages say so
(:data:`SET_TEXT`). The **evaluation** set (seeds :data:`EVALUATION_SEEDS`,
every layout and the geared arm, effect values drawn per seed) is run once,
when a rule is fixed; no test runs it, and no rule is tuned on it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.core import protocols
from bench.core.arguments import add_workers, csv_list, positive_int
from bench.core.csv_format import write_csv
from bench.core.data import Dataset
from bench.core.errors import UserError
from bench.core.fileio import atomic_write, write_json
from bench.runner.job import CaseJob
from bench.runner.schedule import run_jobs
from bench.runner.ledger import Ledger
from bench.runner.plugins import register_by_file
from bench.runner.progress import print_now
from bench.runner.provenance import provenance
from bench.studies import geared_arm
from bench.tools import select as selection
from bench.tools.candidates import named_candidates
from bench.tools.robot_log import simulate
from systems import get_system
from systems.dfki_double_pendulum import CUTOFF_HZ

DEVELOPMENT, FORMER_EVALUATION, SECOND_EVALUATION, THIRD_EVALUATION, EVALUATION = (
    "development", "former_evaluation", "second_evaluation", "third_evaluation", "evaluation")
SETS = (DEVELOPMENT, FORMER_EVALUATION, SECOND_EVALUATION, THIRD_EVALUATION, EVALUATION)
#: each set's data seeds
DEVELOPMENT_SEEDS = (0,)
FORMER_EVALUATION_SEEDS = (5113, 6271)
SECOND_EVALUATION_SEEDS = (7411, 9043)
THIRD_EVALUATION_SEEDS = (3187, 4729)
EVALUATION_SEEDS = (2203, 5881)
#: the sets that were the evaluation set, by their seeds: a page made while one was named ``evaluation`` is its
FORMER_SETS = {FORMER_EVALUATION: FORMER_EVALUATION_SEEDS, SECOND_EVALUATION: SECOND_EVALUATION_SEEDS,
               THIRD_EVALUATION: THIRD_EVALUATION_SEEDS}
#: what each set is, as its page says it
SET_TEXT = {DEVELOPMENT: "development data: the cases rules are tried on",
            FORMER_EVALUATION: "development data: this set (seeds 5113 and 6271) was the evaluation set until rules "
                               "were changed while its page was read (select's worst regret on it went from 4.201 to "
                               "1.053 so), and it counts as development data from then on; the evaluation set is "
                               "another (`--set evaluation`, new seeds)",
            SECOND_EVALUATION: "development data: this set (seeds 7411 and 9043) was the evaluation set; it was run "
                               "once, with select's worst regret 3.743 on ur5_several_drive_9043, and the sparse "
                               "torque terms' held position range was then developed on that case, so it counts as "
                               "development data from then on; the evaluation set is another (`--set evaluation`, "
                               "new seeds)",
            THIRD_EVALUATION: "development data: this set (seeds 3187 and 4729) was the evaluation set; it was run "
                              "once, with select's worst regret 1.844 on kuka_two_drive_3187 (two trajectories, each "
                              "left out whole), and select's default folds for two or three trajectories (`pooled`) "
                              "were then chosen on its two- and three-trajectory cases, so it counts as development "
                              "data from then on; the evaluation set is another (`--set evaluation`, new seeds)",
            EVALUATION: "evaluation data: run once, with rules fixed before, on seeds and cases no rule was tried on"}
#: the arms, by the name ``robot-log`` simulates (the KUKA by its shipped URDF)
ARMS = ("panda", "ur5", "kuka")
#: how fast the one-trajectory layout's test trajectory is against its training one
FASTER = 1.5
#: training trajectories of the ``several`` layout
SEVERAL = 4
LAYOUTS = ("one", "several")
#: the layouts of several trajectories each recorded twice, by their training trajectories
RECORDED_TWICE = {"two": 2, "three": 3}
#: training trajectories of each layout but ``long``
TRAJECTORIES = {"one": 1, "several": SEVERAL, **RECORDED_TWICE}
#: the geared arm, and the name of its effects (:mod:`bench.studies.geared_arm`): in the development set only,
#: in the ``two`` layout
GEARED = "geared"
#: the ``long`` layout (:mod:`bench.studies.long_log`): trajectories (the last the test) and the seconds of each,
#: 12 x 5,840 = 70,080 samples at :data:`RATE_HZ`
LONG, LONG_SECONDS = 12, 58.4
#: the ``seven`` layout: seven training trajectories of 2,000 samples and a test (a lab's identification
#: logs of a KUKA), for :mod:`bench.studies.long_log`
SEVEN, SEVEN_SECONDS = 7, 20.0
#: the layouts of one long log each: their trajectories (the test, the last, among them) and the seconds of each
LOGS = {"long": (LONG, LONG_SECONDS), "seven": (SEVEN + 1, SEVEN_SECONDS)}
#: seconds of each recording, and its rate
SECONDS, RATE_HZ, BASE_HZ = 10.0, 100.0, 0.1
#: the torque noise, a fraction of each joint's torque standard deviation
NOISE = 0.02
#: the protocols compared: ``time`` is what select did before it had others, ``auto`` its default until
#: ``pooled``, its default now (:func:`resolve`)
PROTOCOLS = ("time", "auto", "pooled", "regions", "knndm")
#: what each protocol's folds are, as a page says it
PROTOCOL_TEXT = {"time": "spans in time of one trajectory, whole trajectories of several (select's folds before it "
                         "had others)",
                 "auto": "regions of the states on one trajectory, whole trajectories on several (select's default "
                         "before `pooled`)",
                 "pooled": "select's default: regions of the states of one, two or three trajectories pooled, "
                           "whole trajectories of more",
                 "regions": "regions of the states of every training trajectory pooled",
                 "knndm": "of the folds of time and of regions, those whose held-out distances match the spread "
                          "between the training trajectories"}
#: the shipped real cases: ``bench select`` at its default on each split of the KUKA and of the DFKI pendulum
#: (declared as an arm, ``systems/data/dfki_double_pendulum_arm.toml``), their pages' JSON
REAL = {"kuka_lwr4 (default split)": "results/measured/select_default/select.json",
        "kuka_lwr4 (swapped split)": "results/measured/select_swapped/select.json",
        "dfki_double_pendulum (default split)": "results/measured/select_dfki_default/select.json",
        "dfki_double_pendulum (swapped split)": "results/measured/select_dfki_swapped/select.json"}
#: the candidates from the rigid body to the flexible residuals: the ``one_se`` rule's order
SIMPLICITY = ("standard", "feasible", "loop", "loop_feasible", "feasible+sparse_torque", "standard+gp", "feasible+gp",
              "loop+gp", "standard+mlp", "feasible+delan")
#: the candidates the study runs: select's own less DeLaN and the loop's two, whose fits take the longest
#: (the loop's step is a round, so every work budget gives it all its rounds)
CANDIDATES = ("standard", "feasible", "standard+gp", "feasible+gp", "standard+mlp", "feasible+sparse_torque")
RULES = ("lowest", "select", "one_se", "farther", "stack")
#: steps of each candidate's fits (a round of the loop's, a gradient step of the learners')
STEPS = 20


def _values(rng: np.random.Generator, dof: int, lo: float, hi: float) -> str:
    return ",".join(f"{v:.3g}" for v in rng.uniform(lo, hi, dof))


#: laws the rigid body lacks, each a function of the arm's joints and a generator of the values
EFFECT_SETS = {
    # friction the standard model holds, and a drive's cogging and a Stribeck dip it does not
    "drive": lambda dof, rng: [f"viscous_friction={_values(rng, dof, 0.2, 1.0)}",
                               f"coulomb_friction={_values(rng, dof, 0.3, 1.5)}",
                               f"periodic_torque=1:{rng.uniform(0.5, 1.5):.3g},6,{rng.uniform(0, 3):.3g}",
                               f"stribeck_friction=2:{rng.uniform(0.5, 1.0):.3g},{rng.uniform(1.5, 2.5):.3g},0.3,0.2"],
    # what a drive and a sensor add: motor inertia, a sensor's offsets and gains, a gear whose Coulomb level
    # grows with its load
    "sensor": lambda dof, rng: [f"viscous_friction={_values(rng, dof, 0.2, 1.0)}",
                                f"armature={_values(rng, dof, 0.05, 0.3)}", f"offset={_values(rng, dof, -0.5, 0.5)}",
                                f"torque_gain={_values(rng, dof, 0.93, 1.07)}",
                                f"load_friction={_values(rng, dof, 0.02, 0.1)}"],
    # a geared arm's drives: rotor inertia, heavy friction and a shoulder counterbalance (the geared arm only)
    "geared": geared_arm.effects,
}


@dataclass(frozen=True)
class Case:
    arm: str
    layout: str
    effects: str
    seed: int

    @property
    def name(self) -> str:
        return f"{self.arm}_{self.layout}_{self.effects}_{self.seed}"


def cases(which: str) -> list[Case]:
    """The set ``which``'s cases (:data:`SETS`): the former evaluation set's arms in the ``one`` and ``several``
    layouts, the other sets' in every layout and the geared arm's in ``two``."""
    seeds = {DEVELOPMENT: DEVELOPMENT_SEEDS, **FORMER_SETS, EVALUATION: EVALUATION_SEEDS}[which]
    shipped = [e for e in EFFECT_SETS if e != GEARED]  # the shipped arms' effects
    every = [Case(a, lay, e, s) for s in seeds for a in ARMS for lay in LAYOUTS for e in shipped]
    if which == FORMER_EVALUATION:
        return every
    return every + [Case(a, lay, e, s) for s in seeds for a in ARMS for lay in RECORDED_TWICE for e in shipped] + \
        [Case(GEARED, "two", GEARED, s) for s in seeds]


def _system(arm: str):
    if arm in ("kuka", GEARED):
        return get_system(register_by_file(f"urdf:{_urdf(arm)}"))
    return get_system(arm)


def _data() -> Path:
    return Path(__file__).resolve().parents[2] / "systems" / "data"


def _urdf(arm: str) -> Path:
    return _data() / {"panda": "panda.urdf.gz", "ur5": "ur5_robot.urdf.gz", "kuka": "kuka_lwr4.urdf.gz",
                      GEARED: geared_arm.URDF.name}[arm]


def recording(system, effects: list[str], trajectory_seed: int, noise_seed: int, base_hz: float,
              seconds: float = SECONDS, noise: float = NOISE) -> Dataset:
    """One recording of the Fourier trajectory of ``trajectory_seed`` (:func:`bench.tools.robot_log.simulate`),
    ``seconds`` long, its torque the arm's with ``effects`` and ``noise`` (a share of each joint's torque
    standard deviation) drawn with ``noise_seed``, with its time stamps."""
    time, data = simulate(system.name, seconds, RATE_HZ, base_hz, effects, noise, trajectory_seed,
                          noise_seed=noise_seed)
    return data.replace(L=None, time=time)


def make(case: Case, folder: Path) -> Path:
    """Write ``case``'s recordings and its measured-arm file into ``folder``; returns the file."""
    declared = folder / f"arm_{case.name}.toml"
    if declared.exists():
        return declared
    folder.mkdir(parents=True, exist_ok=True)
    system = _system(case.arm)
    rng = np.random.default_rng(zlib.crc32(case.name.encode()))
    effects = EFFECT_SETS[case.effects](system.dof, rng)
    noise = geared_arm.NOISE if case.arm == GEARED else NOISE
    base = 1000 * case.seed
    seconds = LOGS[case.layout][1] if case.layout in LOGS else SECONDS
    if case.layout == "one":
        plan = [("A", base + 1, base + 11, BASE_HZ), ("A", base + 1, base + 12, BASE_HZ),
                ("T", base + 2, base + 13, FASTER * BASE_HZ)]
    elif case.layout in RECORDED_TWICE:  # each trajectory twice, with noise of its own
        n = RECORDED_TWICE[case.layout]
        plan = [(f"A{k}", base + 1 + k, base + 11 + 2 * k + r, BASE_HZ) for k in range(n) for r in range(2)] + \
               [("T", base + 1 + n, base + 11 + 2 * n, BASE_HZ)]
    elif case.layout in LOGS:  # noise seeds apart from the trajectories'
        count = LOGS[case.layout][0]
        plan = [(f"A{k}", base + 1 + k, base + 101 + k, BASE_HZ) for k in range(count - 1)] + \
               [("T", base + count, base + 100 + count, BASE_HZ)]
    else:
        plan = [(f"A{k}", base + 1 + k, base + 11 + k, BASE_HZ) for k in range(SEVERAL)] + \
               [("T", base + 1 + SEVERAL, base + 11 + SEVERAL, BASE_HZ)]
    rows = []
    for k, (trajectory, t_seed, n_seed, hz) in enumerate(plan):
        name = f"rec{k}.csv"
        write_csv(recording(system, effects, t_seed, n_seed, hz, seconds, noise), folder / name)
        rows.append(f'rec{k} = {{ file = "{name}", trajectory = "{trajectory}" }}')
    dof = system.dof
    columns = ",".join(["time=time"] + [f"{k}_{j}={k}_{j}" for j in range(1, dof + 1) for k in ("q", "qd", "qdd", "tau")])
    text = (f"# {case.name}: simulated {case.arm}, effects {' '.join(effects)}, noise {noise:g}\n"
            f'urdf = "{_urdf(case.arm)}"\n' + ('joints = [' + ", ".join(f'"panda_joint{j}"' for j in range(1, 8))
                                                + ']\n' if case.arm == "panda" else "")
            + f'columns = "{columns}"\ntest = ["T"]\nas_recorded = true\n\n'
            f"[recordings]\n" + "\n".join(rows) + "\n")
    atomic_write(declared, lambda f: f.write(text))
    write_json(folder / "case.json", {"case": case.__dict__, "effects": effects})
    return declared


def resolve(protocol: str, layout: str) -> str | None:
    """The folds ``protocol`` gives on a case of ``layout`` (``bench select``'s ``auto``: whole trajectories
    where there are several, regions where there is one), or ``None`` where it gives none (kNNDM on one
    trajectory, with no target named)."""
    if protocol == "knndm" and layout == "one":
        return None
    return protocols.resolve(protocol, TRAJECTORIES[layout])


def run_case(case: Case, folder: Path, protocol: str, steps: int, candidates: tuple[str, ...], workers: int) -> dict:
    """``bench select`` on ``case`` under ``protocol``, ``workers`` candidates at a time; its ``select.json``."""
    declared = make(case, folder)
    out = folder / protocol
    command = [sys.executable, "-m", "bench", "select", "--system", f"measured:{declared}", "--steps", str(steps),
               "--candidates", ",".join(candidates), "--folds", protocol, "--no-rollout", "--workers", str(workers),
               "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True)
    result = out / "select.json"
    if not result.exists():
        return {"error": (done.stderr.strip().splitlines() or ["no select.json"])[-1]}
    return json.loads(result.read_text())


@dataclass(frozen=True)
class SelectCase(CaseJob):
    """One case under one fold protocol, as a job of the one scheduler (:func:`~bench.runner.schedule.run_jobs`):
    ``bench select`` on it (:func:`run_case`), ``workers`` candidates at a time, in ``where``; its result is
    the case's :func:`scores`. Bounded by work (``steps``), so it has no limit of its own: each candidate has
    select's ceiling."""

    arm: str
    layout: str
    effects: str
    seed: int
    folds: str
    steps: int
    candidates: tuple[str, ...]
    workers: int
    where: str

    def folder(self) -> Path:
        return Path(self.where)

    def run_limit(self) -> float:
        return math.inf

    def compute(self) -> dict:
        case = Case(self.arm, self.layout, self.effects, self.seed)
        return scores(run_case(case, Path(self.where), self.folds, self.steps, self.candidates, self.workers),
                      TRAJECTORIES[self.layout])

    def elsewhere(self, scratch: Path) -> "SelectCase":
        return dataclasses.replace(self, where=str(scratch / Path(self.where).name))


def choose(entries: list[dict], rule: str, stack: dict | None = None, trajectories: int | None = None,
           protocol: str | None = "time") -> dict | None:
    """The candidate ``rule`` chooses among those ``bench select`` may choose (:func:`bench.tools.select.usable`);
    ``lowest`` is ``bench select``'s own choice; ``farther`` falls back on it where no candidate has a figure on
    the farther half (a page made before they were kept); ``stack`` chooses the page's ``stack`` (named
    ``stack``) where its nested validation MSE is the lowest and it has a test figure."""
    best = selection.choose(entries)
    if rule == "select":
        return selection.choose(entries, trajectories, protocol)
    if rule == "stack":
        stack = stack or {}
        nested = stack.get("validation_mse")
        if nested is not None and stack.get("test_mse") is not None and \
                (best is None or nested < best["validation_mse"]):
            return {"name": "stack", "validation_mse": nested, "test_mse": stack["test_mse"]}
        return best
    far = [e for e in selection.usable(entries) if e.get("validation_far_mse") is not None]
    if rule == "farther" and far:
        return min(far, key=lambda e: e["validation_far_mse"])
    if best is None or rule in ("lowest", "farther"):
        return best
    bound = best["validation_mse"] + (best.get("validation_stderr") or 0.0)
    within = [e for e in selection.usable(entries) if e["validation_mse"] <= bound]
    return min(within, key=lambda e: SIMPLICITY.index(e["name"]) if e["name"] in SIMPLICITY else len(SIMPLICITY))


#: each candidate's figures a case keeps, so that a rule that reads only these can be tried on a page's JSON
#: without running its cases again
KEPT_FIGURES = ("validation_mse", "validation_far_mse", "validation_stderr", "fold_mse", "train_mse", "test_mse")


def scores(result: dict, trajectories: int | None = None) -> dict:
    """Per rule: the chosen candidate and its regret; the rank correlation of validation and test; and each
    candidate's :data:`KEPT_FIGURES`. ``trajectories``: the training trajectories (default as ``result`` says;
    the ``select`` rule depends on them)."""
    trajectories = result.get("training_trajectories") or trajectories
    from scipy.stats import spearmanr

    entries = result.get("candidates") or []
    ok = [e for e in entries if e.get("validation_mse") is not None and e.get("test_mse") is not None]
    if not ok:
        return {"error": result.get("error", "no candidate validated")}
    best = min(ok, key=lambda e: e["test_mse"])
    rho = float(spearmanr([e["validation_mse"] for e in ok], [e["test_mse"] for e in ok])[0]) if len(ok) > 2 else None
    out = {"best": best["name"], "best_test_mse": best["test_mse"], "spearman": rho, "rules": {},
           "candidates": {e["name"]: {k: e.get(k) for k in KEPT_FIGURES} for e in entries}}
    stack = result.get("stack")
    for rule in RULES:
        if rule == "stack" and (stack is None or ("weights" in stack and stack.get("test_mse") is None)):
            continue  # a page made before select stacked its candidates, or a stack without a test figure
        c = choose(entries, rule, stack, trajectories, result.get("folds_protocol") or "time")
        out["rules"][rule] = {"chosen": c["name"], "regret": c["test_mse"] / best["test_mse"]}
    return out


def summary(table: list[dict]) -> list[dict]:
    """Per protocol and rule: the median and worst regret, and how often the best was chosen."""
    rows = []
    for protocol in PROTOCOLS:
        for rule in RULES:
            regrets = [t["scores"]["rules"][rule]["regret"] for t in table
                       if t["protocol"] == protocol and rule in t["scores"].get("rules", {})]
            if not regrets:
                continue
            rows.append({"protocol": protocol, "rule": rule, "cases": len(regrets),
                         "median_regret": float(np.median(regrets)), "worst_regret": float(np.max(regrets)),
                         "best_chosen": int(sum(r <= 1.0 + 1e-12 for r in regrets))})
    return rows


#: what each rule chooses, as a page says it
RULE_TEXT = {"lowest": "the lowest validation MSE (select's before it had a rule for few trajectories)",
             "select": f"select's rule: {selection.LOWEST_RULE}, or {selection.FEW_RULE}",
             "one_se": "the first candidate, in the order " + " → ".join(SIMPLICITY) + ", whose validation MSE is "
                       "within one standard error (over the folds) of the lowest",
             "farther": "the lowest validation MSE on the farther half of each fold's scored samples (those at least "
                        "the fold's median distance from the states it is fitted on)",
             "stack": "the lowest validation MSE among the candidates and their stack (convex weights fitted "
                      "on the candidates' held-out predictions; its validation MSE nested, each fold scored with the "
                      "weights fitted on the others), which may beat the best candidate (a regret under 1)"}


def _protocols(result: dict) -> list[str]:
    """The protocols the page's case rows ran, in :data:`PROTOCOLS`' order."""
    had = {t["protocol"] for t in result["table"]}
    return [p for p in PROTOCOLS if p in had]


def _rules(result: dict) -> list[str]:
    """The rules any of the page's rows was scored by, in :data:`RULES`' order (rows made before a rule existed
    lack it, and show a dash)."""
    had = {r for t in result["table"] + result.get("real", []) for r in t["scores"].get("rules", {})}
    return [r for r in RULES if r in had] or list(RULES)


def set_of(result: dict) -> str:
    """The page's set (:data:`SETS`); a page made when a former evaluation set (:data:`FORMER_SETS`) was named
    ``evaluation`` (its cases have that set's seeds) is that set's."""
    which = result["set"]
    if which != EVALUATION:
        return which
    for former, seeds in FORMER_SETS.items():
        if any(name.endswith(tuple(f"_{s}" for s in seeds)) for name in result.get("cases", [])):
            return former
    return which


def page(result: dict) -> str:
    rules = _rules(result)
    lines = ["# How well each way of choosing a model chooses", "",
             f"Command: `{result['command']}`" + (f", at commit {result['commit']}" if result.get("commit") else "")
             + (f"; it ran the set then named `{result['set']}`, which is `--set {set_of(result)}` now"
                if set_of(result) != result["set"] else ""), "",
             *([f"Every rule scored again from the cases' select pages by `{result['rescored']['command']}`, at commit "
                f"{result['rescored']['commit']}.\n"] if result.get("rescored") else []),
             *[f"Run again, {', '.join(r['candidates'])} only, by `{r['command']}` at commit {r['commit']}: the other "
               "candidates' figures are as the command above made them; the rows run again have no stack, which needs "
               "every candidate's held-out predictions.\n" for r in result.get("reruns", [])],
             f"Set: {set_of(result)} ({SET_TEXT.get(set_of(result), 'as its command names it')}); "
             f"{len(result['cases'])} cases; candidates {', '.join(result['candidates'])}; "
             f"{result['steps']} steps a fit. Regret: the chosen candidate's test MSE over the best candidate's. "
             "The test trajectory is read only to score.", "",
             "Cases: the Panda, the UR5 and the KUKA's URDF, each with the laws of a drive (viscous and Coulomb "
             "friction, a cogging torque, a Stribeck dip) or of a drive and its sensor (armature, offsets, gains, "
             "load-dependent friction), drawn per seed; `one`: one training trajectory recorded twice, tested on "
             f"another {FASTER:g} times as fast; `two` and `three`: two or three training trajectories, each "
             f"recorded twice, tested on another; `several`: {SEVERAL} training trajectories, tested on another; "
             "the development set's `geared` arm is a large geared arm with rotor inertia, heavy friction and a "
             "shoulder counterbalance (bench/studies/geared_arm.py). "
             "Protocols: " + "; ".join(f"`{p}` {PROTOCOL_TEXT[p]}" for p in _protocols(result)) + ". "
             "Rules: " + "; ".join(f"`{r}` {RULE_TEXT[r]}" for r in rules) + ".", "",
             "| protocol | rule | cases | median regret | worst regret | chose the best |", "|---|---|---:|---:|---:|---:|"]
    for r in result["summary"]:
        lines.append(f"| {r['protocol']} | {r['rule']} | {r['cases']} | {r['median_regret']:.3f} | "
                     f"{r['worst_regret']:.3f} | {r['best_chosen']} of {r['cases']} |")
    lines += ["", "Each case under each protocol: the candidate each rule chose (its regret). A protocol that gives "
              "a case the folds of another (in brackets) shares its run.", ""] + _rows(result["table"], rules)
    if result.get("real"):
        lines += ["", "## The shipped real arms", "",
                  "`bench select` at its default (each candidate its own steps, its default folds) on each split of the KUKA "
                  "and of the DFKI pendulum (declared as an arm: `measured:systems/data/dfki_double_pendulum_arm.toml`), "
                  "read from the pages it wrote (`source`); they are not rerun here."
                  + (f" Read again by `{result['real_command']}`, at commit {result['real_commit']}; the cases above "
                     "are as their own command made them." if result.get("real_command") else ""), ""]
        lines += _rows(result["real"], rules)
        lines += [f"\n**Test-informed:** {r['case']} tests on {', '.join(r['test_informed'])}, "
                  + (f"read while these were chosen: {'; '.join(r['test_informed_by'])}." if r.get("test_informed_by")
                     else f"which the recordings' {CUTOFF_HZ:g} Hz low-pass cut-off was chosen on (`python -m bench "
                          f"study dfki-filter`, docs/choices.md).") for r in result["real"] if r.get("test_informed")]
    return "\n".join(lines) + "\n"


def _rows(table: list[dict], rules: list[str]) -> list[str]:
    lines = ["| case | protocol (folds) | best on the test | " + " | ".join(rules) + " | Spearman (validation, test) |",
             "|---|---|---|" + "---|" * len(rules) + "---:|"]
    for t in table:
        s, protocol = t["scores"], f"{t['protocol']} ({t.get('folds') or t['protocol']})"
        if "rules" not in s:
            lines.append(f"| {t['case']} | {protocol} | failed: {s['error']} |" + " |" * (len(rules) + 1))
            continue
        cells = [f"{s['rules'][r]['chosen']} ({s['rules'][r]['regret']:.3f})" if r in s["rules"] else "—"
                 for r in rules]
        rho = "—" if s["spearman"] is None else f"{s['spearman']:.2f}"
        lines.append(f"| {t['case']} | {protocol} | {s['best']} | " + " | ".join(cells) + f" | {rho} |")
    return lines



def add_arguments(parser) -> None:
    parser.add_argument("--set", choices=SETS, default=DEVELOPMENT,
                        help="the development cases (for trying rules), the former or the second evaluation set "
                             "(development data now) or the evaluation set (run once, with the rules fixed) "
                             "(default development)")
    parser.add_argument("--cases", nargs="+", default=None, help="only the cases whose names start with these")
    parser.add_argument("--protocols", nargs="+", choices=PROTOCOLS, default=["time", "pooled"],
                        help="the validation protocols to compare: time (spans in time of one trajectory, whole "
                             "trajectories of several), auto (regions of one trajectory, whole trajectories of "
                             "several), pooled (select's default: regions of the states of one, two or three "
                             "trajectories, whole trajectories of more), regions, knndm (only where there are several "
                             "training trajectories) (default time pooled)")
    parser.add_argument("--steps", type=positive_int, default=STEPS, help=f"steps a fit (default {STEPS})")
    parser.add_argument("--candidates", type=csv_list, default=list(CANDIDATES),
                        help=f"the candidates, any of select's ({', '.join(c.name for c in selection.CANDIDATES)}) "
                             f"(default {','.join(CANDIDATES)}: select's less the three whose fits take longest)")
    add_workers(parser, "candidates")
    parser.add_argument("--out", type=Path, default=Path("results/selection/benchmark.md"),
                        help="the page (default results/selection/benchmark.md); the cases' runs go beside it")
    parser.add_argument("--rescore", action="store_true",
                        help="score every rule again on the page already at --out from its cases' select.json files "
                             "beside it (their runs are not redone): for a rule added after the cases ran")
    parser.add_argument("--real-only", action="store_true",
                        help="read the shipped real arms' select pages again into the page already at --out, "
                             "keeping its cases' rows as they were made (their runs are not redone)")


def _said(s: dict) -> str:
    """A finished case in one line: what each rule chose, and its regret."""
    return s.get("error") or ", ".join(f"{r} chose {v['chosen']} (regret {v['regret']:.3g})"
                                       for r, v in s["rules"].items())


def real_rows() -> list[dict]:
    """The shipped real cases' rows, scored from the ``select.json`` each split's ``bench select`` wrote."""
    pages = {name: (path, json.loads(Path(path).read_text())) for name, path in REAL.items() if Path(path).exists()}
    return [{"case": name, "protocol": "auto", "folds": page.get("folds_protocol"), "source": path,
             "scores": scores(page), "test_informed": page.get("test_informed") or [],
             "test_informed_by": page.get("test_informed_by") or []}
            for name, (path, page) in pages.items()]


def publish(out: Path, result: dict) -> None:
    """Write ``result`` to the JSON beside ``out`` and its page to ``out``."""
    write_json(out.with_suffix(".json"), result)
    text = page(result)
    atomic_write(out, lambda f: f.write(text))
    print(f"wrote {out}")


def rescore(args) -> int:
    """The page at ``args.out`` with every rule scored again from its cases' ``select.json`` (in the cases'
    folder beside it, as the study left them), and the command and commit that scored them."""
    made = args.out.with_suffix(".json")
    if not made.exists():
        raise UserError(f"{made}: no page to score again; run the study first")
    result = json.loads(made.read_text())
    root = args.out.parent / f"cases_{result['set']}"
    layouts = {c.name: c.layout for c in cases(set_of(result))}
    table = []
    for t in result["table"]:
        page_json = root / t["case"] / (t.get("folds") or t["protocol"]) / "select.json"
        if not page_json.exists():
            raise UserError(f"{page_json}: missing; --rescore reads each case's select.json where the study wrote it")
        table.append(dict(t, scores=scores(json.loads(page_json.read_text()), TRAJECTORIES[layouts[t["case"]]])))
    result.update(table=table, summary=summary(table), rescored={"command": args.invocation,
                                                                  "commit": provenance().get("commit")})
    publish(args.out, result)
    return 0


def main(args) -> int:
    if args.real_only:
        made = args.out.with_suffix(".json")
        if not made.exists():
            raise UserError(f"{made}: no page to read the real arms into; run the study without --real-only first")
        result = json.loads(made.read_text())
        result.update(real=real_rows(), real_command=args.invocation, real_commit=provenance().get("commit"))
        publish(args.out, result)
        return 0
    if args.rescore:
        return rescore(args)
    candidates = named_candidates(args.candidates, at_least=2)
    chosen = [c for c in cases(args.set) if not args.cases or c.name.startswith(tuple(args.cases))]
    root = args.out.parent / f"cases_{args.set}"
    planned = [(case, protocol, folds) for case in chosen for protocol in args.protocols
               if (folds := resolve(protocol, case.layout)) is not None]
    # each folds' run once a case: auto is one of the others
    jobs = {f"{case.name} {folds}": SelectCase(case.arm, case.layout, case.effects, case.seed, folds, args.steps,
                                               candidates, args.workers, str(root / case.name))
            for case, _, folds in planned}
    ledger = Ledger(args.out)
    done = run_jobs(jobs, 1, _said, print_now, ledger, cluster=args.cluster)
    table = [{"case": case.name, "protocol": protocol, "folds": folds, "scores": done[f"{case.name} {folds}"]}
             for case, protocol, folds in planned]
    result = {"command": args.invocation, "commit": provenance().get("commit"), "set": args.set,
              "cases": [c.name for c in chosen], "candidates": list(candidates), "steps": args.steps,
              "table": table, "summary": summary(table), "real": real_rows()}
    publish(args.out, result)
    ledger.close()
    return 0
