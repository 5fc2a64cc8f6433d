"""``python -m bench rerun RECORD``: replay a recorded run with the work it
did and compare its errors with the record's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from bench.cli.fit import run_in_scratch, summary_line
from bench.cli.options import add_device, device, number
from bench.core.arguments import positive
from bench.core.fileio import check_output, write_json
from bench.runner.plugins import import_plugins
from bench.runner.records import read_record
from bench.runner.replay import check_plugins, compare, replay_spec, tolerance


def add_arguments(rr) -> None:
    rr.add_argument("record", type=Path, help="a run's record (OUT/records/<run id>.json, or a fit's --json)")
    rr.add_argument("--budget", type=positive, default=None,
                    help="a ceiling in seconds past which the replay is killed (default: none; a slower machine "
                         "takes longer than the recorded budget to do the same work)")
    rr.add_argument("--json", type=Path, default=None, help="write the replay's record here")
    add_device(rr, default=None)
    rr.add_argument("--plugin", action="append", default=[],
                    help="a plugin the record's run imported (repeatable): a rerun imports the record's plugins that "
                         "run code only where --plugin names each, the same file as the run's (its sha256)")


def main(args) -> int:
    if args.json:
        check_output(args.json)
    recorded = read_record(args.record)
    spec = replay_spec(recorded, str(args.record), ceiling_s=args.budget)
    check_plugins(recorded, args.plugin, str(args.record))
    import_plugins(spec.plugins)
    # the recorded run's device unless another is asked for; numbers computed on another device
    # differ in their rounding, which the comparison below shows
    spec = dataclasses.replace(spec, device=device(args.device or spec.device, [spec.method]))
    print(f"replaying {recorded.run_id}: {spec.budget.describe()} (recorded under {recorded.describe_budget()}, "
          f"stopped by {recorded.stop_reason})", flush=True)
    replayed, log = run_in_scratch(spec)
    if args.json:
        write_json(args.json, replayed.to_json())
    if replayed.status != "ok":
        print(summary_line(replayed, log))
        return 1
    rows = compare(recorded, replayed)
    print(f"{'':10} {'recorded':>24} {'replayed':>24} {'relative difference':>20}")
    for name, a, b, diff in rows:
        print(f"{name:10} {number(a, '.17g'):>24} {number(b, '.17g'):>24} {diff:>20.3g}")
    limit = tolerance(recorded)
    same = all(diff <= limit for *_, diff in rows)
    stacked = (recorded.details or {}).get("stacked")
    why = f", as the record trained stacked with {stacked} seeds and the replay alone" if stacked else ""
    print(f"{'the same' if same else 'DIFFERENT'} up to a relative {limit:g}{why} "
          f"({replayed.steps} steps; recorded {recorded.steps})")
    return 0 if same else 1
