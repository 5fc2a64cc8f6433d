"""A round of the residual loop on the long log (``python -m bench study loop-speed``'s measurement), this
tree against the commit before the loop's round was made cheaper (:data:`AGAINST`), in one run: each in a
process of its own, one BLAS thread, in turn. Run with ``make benchmark``; the line after the table gives
round 1's seconds in each and their ratio. It takes minutes: each tree's round 1 on 64,240 samples."""

from __future__ import annotations

import pytest

from bench.studies import loop_speed

pytestmark = pytest.mark.benchmark

#: the commit the round is timed against
AGAINST = "b797ba3"


def test_a_loop_round_on_the_long_log_against_the_earlier_commit(benchmark, tmp_path):
    benchmark.group = "loop-round"
    result = benchmark.pedantic(loop_speed.compare, args=(AGAINST, 1, tmp_path),
                                kwargs={"report": lambda line: None, "with_thinning": False},
                                rounds=1, iterations=1)
    benchmark.extra_info.update(round1_before_s=result["round1_s"]["before"], round1_after_s=result["round1_s"]["after"],
                                ratio=result["ratio"])
    print(f"\nloop round 1 on the long log: before {result['round1_s']['before']:.1f} s, after "
          f"{result['round1_s']['after']:.1f} s: {result['ratio']:.2f}x cheaper")
