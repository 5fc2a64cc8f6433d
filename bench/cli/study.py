"""``python -m bench study NAME``: the project's own studies, each a
measurement that writes one of the project's published pages under
``results/`` by default (:mod:`bench.studies`)."""

from __future__ import annotations

from bench.cli.options import Parser
from bench.studies import (adaptation, dfki_filter, generalisation, gpu_figures, long_log, loop_speed, overhead,
                           residual_acceptance, residual_dfki, scaling, selection_benchmark, selection_rerun, stacking_speed,
                           standard_model, syrenets_profile, syrenets_speed, trajectories)

HELP = "the project's studies: measurements that write its published pages (python -m bench study --help lists them)"

#: the studies, by name
STUDIES = {
    "adaptation": adaptation, "residual-acceptance": residual_acceptance, "residual-dfki": residual_dfki,
    "overhead": overhead, "dfki-filter": dfki_filter, "scaling": scaling, "syrenets-speed": syrenets_speed,
    "syrenets-profile": syrenets_profile, "stacking-speed": stacking_speed, "generalisation": generalisation,
    "gpu": gpu_figures, "trajectories": trajectories, "selection": selection_benchmark, "long-log": long_log,
    "selection-rerun": selection_rerun, "standard-model": standard_model, "loop-speed": loop_speed,
}


def add_arguments(parser) -> None:
    sub = parser.add_subparsers(dest="study", required=True, metavar="NAME", parser_class=Parser)
    for name, module in STUDIES.items():
        module.add_arguments(sub.add_parser(name, help=module.HELP))


def main(args) -> int:
    return STUDIES[args.study].main(args)
