"""Each worker's time in a suite run made with ``BENCH_TIMELINE=FILE`` (tests/conftest.py): busy (CPU used by its
tests and the processes they waited for), waiting (in a test, not computing), idle (between tests and after its
last), the slowest tests and those that waited longest.

    BENCH_TIMELINE=/tmp/tl python -m pytest -n 2 --dist loadgroup && python tests/timeline.py /tmp/tl.jsonl
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict


def main(path: str, top: int = 25) -> None:
    rows = [json.loads(line) for line in open(path)]
    begin, end = min(r["start"] for r in rows), max(r["end"] for r in rows)
    by_worker = defaultdict(list)
    for r in rows:
        by_worker[r["worker"]].append(r)
    print(f"{len(rows)} tests, {end - begin:.0f} s from the first test's start to the last one's end")
    for worker, tests in sorted(by_worker.items()):
        wall = sum(r["end"] - r["start"] for r in tests)
        cpu = sum(r["cpu"] for r in tests)
        last = max(r["end"] for r in tests)
        print(f"{worker}: {len(tests)} tests; in tests {wall:.0f} s (CPU {cpu:.0f} s, waiting {wall - cpu:.0f} s); "
              f"between tests {last - min(r['start'] for r in tests) - wall:.0f} s; done {end - last:.0f} s "
              f"before the end")
    print(f"\nthe {top} slowest tests (wall, s):")
    for r in sorted(rows, key=lambda r: r["start"] - r["end"])[:top]:
        print(f"  {r['end'] - r['start']:6.1f}  {r['test']}")
    print(f"\nthe {top} tests that waited longest (wall - CPU, s):")
    for r in sorted(rows, key=lambda r: r["cpu"] - (r["end"] - r["start"]))[:top]:
        print(f"  {r['end'] - r['start'] - r['cpu']:6.1f}  wall {r['end'] - r['start']:6.1f}  {r['test']}")


if __name__ == "__main__":
    main(sys.argv[1])
