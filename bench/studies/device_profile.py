"""Where a fit's time goes on its device: torch's profiler
(:mod:`torch.profiler`) over a call that trains, summarised as

* the wall time of the call under the profiler and its steps;
* the share of that wall during which the device ran kernels (the sum of
  the kernels' own times over the wall; on a CPU there are none);
* the kernels launched per step;
* the share of the wall spent inside torch's operators on the CPU (their
  self times summed): the rest is Python and the framework between them;
* the operators with the most CPU self time and the kernels with the most
  device time, each per step.

Ranges the code names (``record_function``, such as the optimiser's step)
are left out of both: they span work, they are not work.

The profiler's own bookkeeping slows the call, so the wall here is longer
than the same call's unprofiled; the shares are of the profiled wall.
"""

from __future__ import annotations

import time
from typing import Callable

import torch
from torch.autograd import DeviceType
from torch.profiler import ProfilerActivity, profile

#: rows kept of each list
TOP = 10


def _row(event, steps: int, seconds) -> dict:
    return {"name": event.key, "calls_per_step": event.count / steps, "ms_per_step": seconds(event) / 1e3 / steps}


def profile_call(train: Callable[[], object], device: str, steps: int, top: int = TOP) -> dict:
    """Profile ``train()`` (which does ``steps`` training steps on ``device``)."""
    on_cuda = torch.device(device).type == "cuda"
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if on_cuda else [])
    with profile(activities=activities) as prof:
        began = time.perf_counter()
        train()
        if on_cuda:
            torch.cuda.synchronize()
        wall = time.perf_counter() - began
    averages = [e for e in prof.key_averages() if not getattr(e, "is_user_annotation", False)]  # ranges, not work
    kernels = [e for e in averages if e.device_type == DeviceType.CUDA]
    operators = [e for e in averages if e.device_type == DeviceType.CPU]
    kernel_us = sum(e.self_device_time_total for e in kernels)
    operator_us = sum(e.self_cpu_time_total for e in operators)
    return {
        "device": device, "steps": steps, "wall_s": wall, "ms_per_step": wall * 1e3 / steps,
        "device_busy": kernel_us / 1e6 / wall, "kernels_per_step": sum(e.count for e in kernels) / steps,
        "operators_cpu_share": operator_us / 1e6 / wall,
        "operators": [_row(e, steps, lambda e: e.self_cpu_time_total)
                      for e in sorted(operators, key=lambda e: -e.self_cpu_time_total)[:top]],
        "kernels": [_row(e, steps, lambda e: e.self_device_time_total)
                    for e in sorted(kernels, key=lambda e: -e.self_device_time_total)[:top]],
    }


def page_lines(p: dict) -> list[str]:
    """A profile's summary and its two lists as Markdown lines."""
    lines = [f"{p['steps']} steps in {p['wall_s']:.3g} s under the profiler ({p['ms_per_step']:.3g} ms a step); "
             f"the device ran kernels {100 * p['device_busy']:.3g} % of that wall, "
             f"{p['kernels_per_step']:.4g} kernels a step; torch's operators took "
             f"{100 * p['operators_cpu_share']:.3g} % of it on the CPU, the rest is Python and the framework "
             f"between them.", ""]
    for title, rows in (("operators, by CPU self time", p["operators"]), ("kernels, by device time", p["kernels"])):
        if not rows:
            continue
        lines += [f"| {title} | calls a step | ms a step |", "|---|---:|---:|"]
        lines += [f"| `{r['name'][:80]}` | {r['calls_per_step']:.4g} | {r['ms_per_step']:.3g} |" for r in rows]
        lines.append("")
    return lines
