"""``python -m bench select``: one model of a measured arm, chosen by validation
on the training data alone (:mod:`bench.tools.select`)."""

from __future__ import annotations

import argparse
import math

from pathlib import Path

from bench.cli.parser import UsageError
from bench.cli.options import add_plugin, add_split, check_names, check_split, load_plugins
from bench.core.arguments import add_workers, csv_list, positive, positive_int, seed
from bench.core.csv_format import read_csv
from bench.core.protocols import NAMES
from bench.core.fileio import check_output
from bench.runner.plugins import file_prefix
from bench.tools.candidates import CANDIDATES, named_candidates

#: the seconds past which a candidate is killed (``--budget``) on up to :data:`CEILING_SAMPLES` training samples:
#: a ceiling, not its work, which is steps (bench.tools.select.Candidate.work); five times the 180 s a candidate
#: had when its work was seconds
SELECT_CEILING_S = 900.0
#: the training samples past which the default ceiling grows in proportion to them, as the candidates' work does
#: (a GP's steps, the regressors, the loop's rounds): on the long-log study's two logs with one core busy beside
#: them, the longest candidate then takes 642 s of 5,782 (64,240 samples) and 391 s of 1,260 (14,000), so a machine
#: three times slower still finishes within it (results/selection/long_log.md, seven_trajectories.md)
CEILING_SAMPLES = 10_000


def ceiling(samples: int) -> float:
    """select's default ceiling a candidate on ``samples`` training samples: :data:`SELECT_CEILING_S`, and in
    proportion to the samples past :data:`CEILING_SAMPLES`, rounded up to a whole second."""
    return float(math.ceil(SELECT_CEILING_S * max(1.0, samples / CEILING_SAMPLES)))


def add_arguments(p) -> None:
    p.add_argument("--system", required=True, help="a measured arm (kuka_lwr4, measured:PATH)")
    p.add_argument("--out", type=Path, required=True,
                   help="output folder: select.md, select.json, model.npz, and the candidates' runs (a rerun resumes)")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="give every candidate N steps of its method's work (gradient steps, GP steps, solves, the "
                        "loop's rounds) instead of its own (default: each candidate's own steps, the page's work "
                        "column); either way the same numbers on any machine")
    p.add_argument("--budget", type=positive, default=None, metavar="SECONDS",
                   help="a candidate still running after SECONDS is killed and recorded as timeout (default "
                        f"{SELECT_CEILING_S:g}, and in proportion to the training samples past "
                        f"{CEILING_SAMPLES:,}); a ceiling only, the candidates' work being steps")
    add_split(p)
    p.add_argument("--seed", type=seed, default=0, help="the candidates' seed (default 0)")
    add_workers(p, "candidates", None)
    p.add_argument("--candidates", type=csv_list, default=None,
                   help=f"only these candidates (default: all of {', '.join(c.name for c in CANDIDATES)})")
    p.add_argument("--rollout", action=argparse.BooleanOptionalAction, default=False,
                   help="also score each candidate by driven rollouts of the test recordings, kept in its record "
                        "(the page and the choice do not use them; default --no-rollout)")
    p.add_argument("--target-states", type=Path, default=None, metavar="LOG",
                   help="a CSV in the suite's format of the states the model will be asked (q, qd and qdd; its "
                        "torque columns, if any, are not read): the page says whether validation reached as far "
                        "from the training states as they lie (default: the spread between the training "
                        "trajectories, where there are several)")
    p.add_argument("--folds", choices=NAMES, default="pooled",
                   help="the validation folds: time (whole trajectories, or spans in time of one), regions "
                        "(leave-region-out: k-means regions of the states), knndm (the folds of time or of "
                        "regions whose held-out distances match the target's: --target-states, else the spread "
                        "between the training trajectories), auto (whole trajectories where there are several, "
                        "regions where there is one) or pooled: auto, but the states of two or three trajectories "
                        "pooled into regions, so that each fold is fitted on part of every one (default pooled)")
    p.add_argument("--page-only", action="store_true",
                   help="write select.md again from the select.json already in --out, its test-informed flags read "
                        "again from the arm's declaration; nothing is run and no figure changes")
    add_plugin(p)


def main(args) -> int:
    if args.page_only:
        load_plugins(args, [args.system])
        from bench.tools.select import repage

        repage(args.out, args.invocation)
        print(f"wrote {args.out / 'select.md'} again from {args.out / 'select.json'}")
        return 0
    check_output(args.out, folder=True)
    known = {c.name: c for c in CANDIDATES}
    candidates = [known[n] for n in named_candidates(args.candidates)] if args.candidates else list(CANDIDATES)
    names = sorted({c.method for c in candidates})
    (name,), plugins = load_plugins(args, [args.system], names)  # a bad file: one line, nothing imported
    from bench.evaluation.domain import sentences
    from bench.runner.run import given_data
    from bench.tools.select import select
    from systems import SYSTEMS

    check_names(args, [name])
    check_split(args.split, [name])
    arm = SYSTEMS[name](split=args.split)  # the command's one build of it
    if arm.simulated or arm.linear_form() is None:
        raise UsageError(f"{name}: bench select chooses among models of a measured arm (its recordings and its "
                         f"URDF's rigid body); {name} is {'simulated' if arm.simulated else 'not an arm'}"
                         + (f" (as an arm: --system {arm.as_arm})" if arm.as_arm else ""))
    check_names(args, [name], names, built={name: arm})
    data = given_data(arm, None, None)
    target = None if args.target_states is None else read_csv(args.target_states, dof=arm.dof, system=name,
                                                               states_only=True)
    protocol = args.folds
    if protocol == "knndm" and args.target_states is not None:
        protocol = f"knndm:{args.target_states.resolve()}"
    elif protocol == "knndm" and len(data[0].trajectories()) < 2:
        raise UsageError("--folds knndm: the training data hold one trajectory; name the states the model will be "
                         "asked with --target-states LOG")
    budget = args.budget if args.budget is not None else ceiling(len(data[0]))
    result = select(name, args.out, split=args.split, budget_s=budget, steps=args.steps, seed=args.seed,
                    workers=args.workers, cluster=args.cluster, plugins=plugins, command=args.invocation,
                    candidates=candidates,
                    rollout=args.rollout, data=data, target=target, protocol=protocol,
                    declared=args.system if file_prefix(args.system) else None)
    chosen = result["chosen"]
    if chosen is None:
        print(f"nothing chosen: no candidate ran and validated (see {args.out / 'select.md'})")
        return 1
    print(f"chosen: {chosen['name']} (validation MSE {chosen['validation_mse']:.4g}, test MSE {chosen['test_mse']:.4g}); "
          f"model in {args.out / 'model.npz'}, page in {args.out / 'select.md'}")
    print(sentences(result["domain"]).replace("**", ""))
    return 0
