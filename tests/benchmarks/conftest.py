"""Print, after the benchmark table, each benchmark's mean time as a ratio to the suite's own."""

from __future__ import annotations


def pytest_terminal_summary(terminalreporter, config):
    session = getattr(config, "_benchmarksession", None)
    if session is None or not session.benchmarks:
        return
    groups: dict[str, dict[str, float]] = {}
    for bench in session.benchmarks:
        if bench.stats is None:
            continue
        groups.setdefault(bench.group or "", {})[bench.name] = bench.stats.mean
    extra = [b for b in session.benchmarks if b.extra_info.get("steps_per_s")]
    if extra:
        terminalreporter.write_sep("-", "training steps per second")
        for bench in extra:
            info = bench.extra_info
            ratio = f"   {info['x_public']:5.1f}x the public implementation" if "x_public" in info else ""
            terminalreporter.write_line(f"{bench.name:<70} {info['steps_per_s']:7.1f} steps/s{ratio}")
    evals = [b for b in session.benchmarks if b.extra_info.get("evaluations_per_s")]
    if evals:
        terminalreporter.write_sep("-", "evaluations per second (trees x samples / s)")
        for bench in sorted(evals, key=lambda b: -b.extra_info["evaluations_per_s"]):
            info = bench.extra_info
            terminalreporter.write_line(f"{info['label']:<45} {info['evaluations_per_s']:12.3e}")
    rounds = [b for b in session.benchmarks if b.extra_info.get("round1_after_s")]
    if rounds:
        terminalreporter.write_sep("-", "a residual loop round on the long log, this tree against an earlier commit")
        for bench in rounds:
            info = bench.extra_info
            terminalreporter.write_line(f"round 1: before {info['round1_before_s']:.1f} s, after "
                                        f"{info['round1_after_s']:.1f} s: {info['ratio']:.2f}x cheaper")
    started = {b.extra_info["startup"]: b.stats.mean for b in session.benchmarks
               if b.extra_info.get("startup") and b.stats is not None}
    if "python -c pass" in started:
        terminalreporter.write_sep("-", "the command line's start-up: seconds more than python -c pass, in this run")
        for name, mean in started.items():
            if name != "python -c pass":
                terminalreporter.write_line(f"{name:<50} {mean - started['python -c pass']:+7.2f} s")
    for group, means in sorted(groups.items()):
        ours = [v for k, v in means.items() if "[ours" in k or k.endswith("ours")]
        if not ours:
            continue
        terminalreporter.write_sep("-", f"{group}: mean time relative to ours")
        for name, mean in sorted(means.items(), key=lambda kv: kv[1]):
            terminalreporter.write_line(f"{name:<70} {mean * 1e3:9.2f} ms   {mean / ours[0]:6.2f}x ours")
