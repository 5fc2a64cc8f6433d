"""``python -m bench study NAME``: the project's own studies, each a
measurement that writes one of the project's published pages under
``results/`` by default (:mod:`bench.studies`). A study's module is imported
when it is parsed, as a command's is (:func:`bench.cli.parser.add_commands`)."""

from __future__ import annotations

from bench.cli.parser import Command, add_commands

#: its ``add_arguments`` is given the rest of the command line, to build only the study it names
NESTED = True

#: the studies, by name, each with its line in ``python -m bench study --help``
STUDIES = {
    "adaptation": Command("bench.studies.adaptation",
                          "measure how learners adapt when the system gains an undeclared effect "
                          "(results/residual/adaptation)"),
    "residual-acceptance": Command("bench.studies.residual_acceptance",
                                   "the residual loop's benchmark of undeclared effects: recall, precision, "
                                   "confusion (results/residual/acceptance.md)"),
    "residual-dfki": Command("bench.studies.residual_dfki",
                             "measure the residual loop on the DFKI recordings: the suite's split and leave one "
                             "recording out (results/residual/dfki.md)"),
    "overhead": Command("bench.studies.overhead",
                        "measure the harness's overhead and its speed-up from 1 to more workers "
                        "(results/harness/overhead.md)"),
    "dfki-filter": Command("bench.studies.dfki_filter",
                           "measure how the DFKI filter's cut-off changes the identified model "
                           "(results/measured/dfki_filter.md)"),
    "scaling": Command("bench.studies.scaling",
                       "measure how each method's time per step, memory and error grow with the degrees of freedom "
                       "(results/scaling)"),
    "syrenets-speed": Command("bench.studies.syrenets_speed",
                              "time SyReNets' training step in this tree and in an earlier commit, in turn "
                              "(results/syrenets/speed/syrenets_speed.md)"),
    "syrenets-profile": Command("bench.studies.syrenets_profile",
                                "where SyReNets' training step spends its time, and its heads' product with and "
                                "without torch.profiler (results/syrenets/speed/syrenets_profile.md)"),
    "stacking-speed": Command("bench.studies.stacking_speed",
                              "measure seeds trained stacked against one by one: steps/s per seed and seed-steps/s, "
                              "on a device"),
    "generalisation": Command("bench.studies.generalisation",
                              "where each learner stops generalising on a measured arm: test MSE against distance "
                              "from the training states"),
    "gpu": Command("bench.studies.gpu_figures",
                   "the GPU figures of stacked seeds, with ratios, in one run (runs on a bare GPU machine; --dry-"
                   "run, --prepare)"),
    "trajectories": Command("bench.studies.trajectories",
                            "how far a measured arm's test trajectory and its validation folds lie from the states "
                            "they were fitted on"),
    "selection": Command("bench.studies.selection_benchmark",
                         "how well each validation protocol and rule chooses a model, on simulated arms whose truth "
                         "is known"),
    "long-log": Command("bench.studies.long_log",
                        "bench select at its default on a generated long log (the Panda's 12 trajectories, 70,080 "
                        "samples; or, with --layout seven, the KUKA's 7 training trajectories of 2,000): every "
                        "candidate's status, the loop's rounds, the regret and the time "
                        "(results/selection/long_log.md)"),
    "selection-rerun": Command("bench.studies.selection_rerun",
                               "the selection benchmark's page with only some candidates run again, the others' "
                               "figures kept"),
    "standard-model": Command("bench.studies.standard_model",
                              "the measured arms' standard model, the field's beside friction alone, and the factor "
                              "for every page read against friction alone (results/measured/standard_model.md)"),
    "loop-speed": Command("bench.studies.loop_speed",
                          "time a round of the residual loop on the long log in this tree and in an earlier commit, "
                          "in turn (results/residual/loop_speed.md)"),
}


def add_arguments(parser, argv: list[str] | None = None) -> None:
    """Every study's arguments, or where ``argv`` is given only the one it names."""
    add_commands(parser, STUDIES, "study", argv)


def main(args) -> int:
    return STUDIES[args.study].load().main(args)
