"""The heads' product in SyReNets' training step, timed with and without torch.profiler.

Each selection head ends in a layer over the candidates: ``W2`` of shape
(heads, candidates, hidden units) multiplied by the hidden units and summed.
torch.profiler attributes most of a step to these products (the ``aten::mul``
calls on tensors of ``W2``'s shape, forward and backward). This command times
the same calls in one process, three ways, and reports each per step:

* ``plain``: the step with no instrumentation;
* ``profiler``: under ``torch.profiler`` (CPU, with input shapes); the
  product's figure is the self time of those ``aten::mul`` events;
* ``timers``: wall-clock timers around the same calls, the forward product
  caught by a ``TorchFunctionMode`` and the backward by hooks on the
  product's autograd node. The node's time includes the reduction of the
  hidden units' gradient, which the profiler's figure leaves out, so this
  figure is an upper bound on the product's own time.

Each mode also counts the process's minor page faults per step. Each
product writes a temporary of ``W2``'s size (2.3 MB, 567 pages of 4 KB, in
the public configuration); when the allocator hands it freshly mapped
memory, every page faults on its first write.

Each mode runs a few untimed steps, then ``--steps`` timed ones, the three in turn, ``--rounds`` times; the
table gives medians. Configuration: the authors' public one (inputs
``(q, qd, qdd)``, 32 samples plus 16 replayed), the direct experiment,
float64, one thread, inside the garbage-collector context of the suite's fit
loop. Usage::

    python -m bench syrenets-profile [--steps 200] [--rounds 3] [--out results/syrenets_profile.md]

With 5 rounds of 200 steps it took 6 min 18 s and 6.3 GB of memory, most
of both for the profiler's records of each operator call and its shapes.
"""

from __future__ import annotations

import resource
import statistics
import time
from pathlib import Path

import torch

from bench.core.arguments import positive_int
from bench.core.data import generate
from bench.core.fileio import atomic_write, check_output
from bench.experiments import syrenets_speed
from bench.runner.provenance import provenance
from methods import METHODS
from methods.base import gc_frozen
from systems import get_system

HELP = "time the SyReNets heads' product with and without torch.profiler (results/syrenets_profile.md)"

#: the authors' public configuration, as bench syrenets-speed times it
CONFIG = syrenets_speed.CONFIGS["public"]
MODES = ("plain", "profiler", "timers")
#: untimed steps at the start of each mode
WARMUP = 3


def add_arguments(parser) -> None:
    parser.add_argument("--steps", type=positive_int, default=200, help="steps per mode and round (default 200)")
    parser.add_argument("--rounds", type=positive_int, default=3, help="rounds of the three modes (default 3)")
    parser.add_argument("--out", type=Path, default=Path("results/syrenets_profile.md"),
                        help="the table to write (default results/syrenets_profile.md)")


class _ProductTimer(torch.overrides.TorchFunctionMode):
    """Wall-clock time of every multiplication with an operand of ``shape``, forward and backward."""

    def __init__(self, shape: torch.Size):
        super().__init__()
        self.shape = shape
        self.reset()

    def reset(self) -> None:
        self.forward = self.backward = 0.0

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func not in (torch.Tensor.mul, torch.Tensor.__mul__, torch.Tensor.__rmul__, torch.mul) or not any(
            isinstance(a, torch.Tensor) and a.shape == self.shape for a in args
        ):
            return func(*args, **kwargs)
        t0 = time.perf_counter()
        out = func(*args, **kwargs)
        self.forward += time.perf_counter() - t0
        if out.grad_fn is not None:
            started = []
            out.grad_fn.register_prehook(lambda grads: started.append(time.perf_counter()))
            out.grad_fn.register_hook(lambda inputs, outputs: self._add_backward(started))
        return out

    def _add_backward(self, started: list) -> None:
        self.backward += time.perf_counter() - started[-1]


def _setup():
    torch.set_num_threads(1)
    train = generate(get_system("double_pendulum"), 256, 0, cache=False)
    m = METHODS["syrenets"](**CONFIG["hyperparameters"])
    m.seed, m.dof = 0, train.dof
    m._setup(train)
    t = train.tensors()
    return m, {k: v[:CONFIG["batch"]] for k, v in t.items()}


def _product_events_ms(prof, shape: list[int]) -> float:
    """Self CPU time (ms) of the ``aten::mul`` events with an input of ``shape``."""
    return sum(e.self_cpu_time_total for e in prof.key_averages(group_by_input_shape=True)
               if e.key == "aten::mul" and shape in list(e.input_shapes)) / 1e3


def measure(steps: int, rounds: int, report=print) -> dict[str, dict[str, list[float]]]:
    """Per mode: the step's and the product's milliseconds and the minor page faults per step, one figure per round."""
    m, batch = _setup()
    shape = m.model.W2[0].shape
    out = {mode: {"step_ms": [], "product_ms": [], "page_faults": []} for mode in MODES}

    def record(mode, timed):
        out[mode]["step_ms"].append(timed[0])
        out[mode]["page_faults"].append(timed[1])

    def run(after_step=lambda: None, before_timing=lambda: None):
        for _ in range(WARMUP):
            m.train_step(batch, "direct")
            after_step()
        before_timing()
        took, faults = 0.0, resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        for _ in range(steps):
            start = time.perf_counter()
            m.train_step(batch, "direct")
            took += time.perf_counter() - start
            after_step()  # the profiler's bookkeeping between steps is not timed
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
        return took * 1e3 / steps, faults / steps

    with gc_frozen():
        for _ in range(20):
            m.train_step(batch, "direct")
        for k in range(rounds):
            record("plain", run())
            out["plain"]["product_ms"].append(float("nan"))
            # the profiler records only the timed steps, after WARMUP steps of its own
            schedule = torch.profiler.schedule(wait=0, warmup=WARMUP, active=steps)
            with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU], record_shapes=True,
                                        schedule=schedule, acc_events=True) as prof:
                record("profiler", run(after_step=prof.step))
            out["profiler"]["product_ms"].append(_product_events_ms(prof, list(shape)) / steps)
            timer = _ProductTimer(shape)
            with timer:
                record("timers", run(before_timing=timer.reset))
            out["timers"]["product_ms"].append((timer.forward + timer.backward) * 1e3 / steps)
            steps_ms = ", ".join(f"{mode} step {out[mode]['step_ms'][-1]:.2f} ms "
                                 f"({out[mode]['page_faults'][-1]:.0f} page faults)" for mode in MODES)
            report(f"round {k + 1}/{rounds}: {steps_ms}; product: profiler {out['profiler']['product_ms'][-1]:.2f} ms, "
                   f"timers {out['timers']['product_ms'][-1]:.2f} ms")
    return out


def main(args) -> int:
    check_output(args.out)
    figures = measure(args.steps, args.rounds)
    med = {mode: {k: statistics.median(v) for k, v in f.items()} for mode, f in figures.items()}
    prov = provenance()
    lines = [
        "# The heads' product in SyReNets' training step, with and without torch.profiler",
        "",
        f"Generated by `{args.invocation}` at commit {prov.get('commit', '?')[:10]}"
        f"{' (dirty tree)' if prov.get('dirty') else ''}: the public configuration (inputs (q, qd, qdd), "
        f"{CONFIG['batch']} samples), direct, float64, one thread; medians of {args.rounds} rounds of {args.steps} steps per mode, "
        f"the modes in turn. Machine: {prov.get('cpu')} ({prov.get('cpu_count')} cores), torch "
        f"{prov.get('packages', {}).get('torch')}; {prov.get('utc', '')[:10]}.",
        "",
        "The product is `W2 * hidden` with `W2` of shape "
        "(heads, candidates, hidden units), forward and backward, all layers.",
        "",
        "| mode | step (ms) | heads' product (ms per step) | product's share of the step | minor page faults per step |",
        "|---|---:|---:|---:|---:|",
    ]
    for mode in MODES:
        step, product = med[mode]["step_ms"], med[mode]["product_ms"]
        share = "" if product != product else f"{product / step:.0%}"
        lines.append(f"| {mode} | {step:.2f} | {'' if product != product else f'{product:.2f}'} | {share} | "
                     f"{med[mode]['page_faults']:.0f} |")
    lines += [
        "",
        "Minor page faults are first writes to freshly mapped memory (`getrusage`). Each round:",
        "",
        "| round | " + " | ".join(f"{mode}: step (ms), product (ms), page faults" for mode in MODES) + " |",
        "|---:|" + "---|" * len(MODES),
    ]
    for k in range(args.rounds):
        cells = []
        for mode in MODES:
            f = figures[mode]
            product = "–" if f["product_ms"][k] != f["product_ms"][k] else f"{f['product_ms'][k]:.2f}"
            cells.append(f"{f['step_ms'][k]:.2f}, {product}, {f['page_faults'][k]:.0f}")
        lines.append(f"| {k + 1} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0
