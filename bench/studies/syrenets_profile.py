"""Where SyReNets' training step spends its time, and the heads' output layer in it.

Each selection head ends in a layer over the terms: ``W2`` of shape
(heads, terms, hidden units) applied to the hidden units
(``methods.syrenets.network.HeadsOutput``, forward and backward). torch.profiler
attributes a large and varying share of a step to it. This command times
the same step in one process, three ways, and reports each per step:

* ``plain``: the step with no instrumentation;
* ``profiler``: under ``torch.profiler`` (CPU, with input shapes); the
  product's figure is the CPU time of its forward and backward events,
  the operators they call included;
* ``timers``: wall-clock timers around the product's own forward and
  backward functions.

Each mode also counts the process's minor page faults per step. Each
product writes a temporary of ``W2``'s size (2.3 MB, 567 pages of 4 KB, in
the public configuration); when the allocator hands it freshly mapped
memory, every page faults on its first write.

A second table says where a plain step's time goes. Every ATen operator of
one step (forward, backward and the optimiser's update) is recorded at the
dispatcher, then each is called again alone, on copies of its own
arguments, and timed. The sum is what the step's arithmetic and memory
traffic cost with no Python, autograd or allocation between the operators:
a floor for any reordering of the same operators, and a generous one, since
each operator timed alone finds its inputs in the cache. The operators are
grouped into Adam's fused update, the heads' output layer (every operator
with a tensor of ``W2``'s shape among its arguments or results), the matrix
products (``mm``, ``addmm``, ``bmm``) and the rest.

Each mode runs a few untimed steps, then ``--steps`` timed ones, the three in turn, ``--rounds`` times,
and the operators are timed alone once per round; the tables give medians. Configuration: the authors' public
one (inputs ``(q, qd, qdd)``, 32 samples plus 16 replayed), the direct experiment, float64, one thread, inside
the garbage-collector context of the suite's fit loop. Usage::

    python -m bench study syrenets-profile [--steps 200] [--rounds 3] [--out results/syrenets/speed/syrenets_profile.md]

With ``--compiled`` it profiles the step with ``compile=True`` instead
(:func:`measure_compiled`, results/syrenets/speed/syrenets_profile_compiled.md): the
compiled pass runs inductor's generated C++ kernels and calls ATen for the
matrix products, so the operators cannot be called again alone. Each round
times ``--steps`` plain steps, then ``--steps`` steps under
``torch.profiler`` with each generated kernel recorded as an event of its
own (inductor's ``cpp.enable_kernel_profile``); the table gives the
profiled self time per step of Adam's update, the matrix products and the
generated kernels, and what is left of the plain step: Python, dispatch,
autograd and allocation. The compilation happens in untimed warm-up steps.
In some rounds, erratically, the generated kernels' events take two to six
times as long as in the others (an uncounted profiled session before the
first did not prevent it), with hundreds of minor page faults a step
where the plain steps have next to none: under the profiler, the weights'
gradients (2.3 MB each) are written to freshly mapped memory, as in the
eager profile above.
A profiler can only add to an event's time, so each part's figure is its
lowest over the rounds, and the plain step's the median; the table lists
each round's kernel time and page faults.

With 5 rounds of 200 steps it took about 6 min and 6 GB of memory, most
of both for the profiler's records of each operator call and its shapes.
"""

from __future__ import annotations

import re
import resource
import statistics
import time
from pathlib import Path

import torch
from torch.utils._python_dispatch import TorchDispatchMode

from bench.core.arguments import positive_int
from bench.core.data import generate
from bench.core.fileio import atomic_write, check_output
from bench.studies import syrenets_speed
from bench.runner.provenance import machine, made_at, provenance
from methods import METHODS
from methods.base import gc_frozen
from methods.syrenets.network import HeadsOutput
from systems import get_system

#: the authors' public configuration, as bench study syrenets-speed times it
CONFIG = syrenets_speed.CONFIGS["public"]
MODES = ("plain", "profiler", "timers")
#: untimed steps at the start of each mode
WARMUP = 3


def add_arguments(parser) -> None:
    parser.add_argument("--steps", type=positive_int, default=200, help="steps per mode and round (default 200)")
    parser.add_argument("--rounds", type=positive_int, default=3, help="rounds of the three modes (default 3)")
    parser.add_argument("--compiled", action="store_true",
                        help="profile the step with compile=True (torch.compile) instead: where its time goes")
    parser.add_argument("--out", type=Path, default=None,
                        help="the table to write (default results/syrenets/speed/syrenets_profile.md, "
                             "results/syrenets/speed/syrenets_profile_compiled.md with --compiled)")


class _ProductTimer:
    """Wall-clock time of the heads' output layer, forward and backward, while entered.

    It wraps :class:`methods.syrenets.network.HeadsOutput`'s two functions and puts
    them back on exit.
    """

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.forward = self.backward = 0.0

    def _timed(self, fn, field: str):
        def timed(*args):
            start = time.perf_counter()
            out = fn(*args)
            setattr(self, field, getattr(self, field) + time.perf_counter() - start)
            return out
        return staticmethod(timed)

    def __enter__(self):
        self._saved = HeadsOutput.__dict__["forward"], HeadsOutput.__dict__["backward"]
        HeadsOutput.forward = self._timed(HeadsOutput.forward, "forward")
        HeadsOutput.backward = self._timed(HeadsOutput.backward, "backward")
        return self

    def __exit__(self, *exc) -> None:
        HeadsOutput.forward, HeadsOutput.backward = self._saved


class _Recorder(TorchDispatchMode):
    """Every ATen operator called while entered: copies of its arguments, taken
    before the call, and the shapes of its results.

    It keeps no reference to the step's own tensors: autograd hands a
    parameter's gradient over without a copy only when nothing else holds it.
    """

    def __init__(self):
        super().__init__()
        self.calls = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        copies = _copy(args), _copy(kwargs)
        out = func(*args, **kwargs)
        self.calls.append((func, *copies, [t.shape for t in _tensors(out)]))
        return out


def _copy(a):
    if isinstance(a, torch.Tensor):
        return a.detach().clone()
    if isinstance(a, (list, tuple)):
        return type(a)(_copy(x) for x in a)
    if isinstance(a, dict):
        return {k: _copy(v) for k, v in a.items()}
    return a


def _tensors(a):
    if isinstance(a, torch.Tensor):
        yield a
    elif isinstance(a, (list, tuple)):
        for x in a:
            yield from _tensors(x)
    elif isinstance(a, dict):
        for x in a.values():
            yield from _tensors(x)


#: the groups of the operators timed alone, in the table's order
PARTS = ("Adam's fused update", "heads' output layer", "matrix products", "other operators")


def _part(func, args, kwargs, out_shapes: list[torch.Size], shape: torch.Size) -> str:
    if func.overloadpacket is torch.ops.aten._fused_adam_:
        return PARTS[0]
    if shape in out_shapes or any(t.shape == shape for t in _tensors((args, kwargs))):
        return PARTS[1]
    if func.overloadpacket in (torch.ops.aten.mm, torch.ops.aten.addmm, torch.ops.aten.bmm):
        return PARTS[2]
    return PARTS[3]


def operators_alone(m, batch, repeat: int = 10) -> dict[str, tuple[float, int]]:
    """One step's operators, each called ``repeat`` times alone on copies of
    its arguments: per group of :data:`PARTS`, (ms per step, operator calls)."""
    shape = m.model.W2[0].shape
    recorder = _Recorder()
    with recorder:
        m.train_step(batch, "direct")
    took = {part: [0.0, 0] for part in PARTS}
    for func, args, kwargs, out_shapes in recorder.calls:
        func(*args, **kwargs)  # a first call, untimed
        start = time.perf_counter()
        for _ in range(repeat):
            func(*args, **kwargs)
        part = took[_part(func, args, kwargs, out_shapes, shape)]
        part[0] += (time.perf_counter() - start) * 1e3 / repeat
        part[1] += 1
    return {part: (ms, n) for part, (ms, n) in took.items()}


def _setup(**extra):
    torch.set_num_threads(1)
    train = generate(get_system("double_pendulum"), 256, 0, cache=False)
    m = METHODS["syrenets"](**CONFIG["hyperparameters"], **extra)
    m.seed, m.dof = 0, train.dof
    m._setup(train)
    t = train.tensors()
    return m, {k: v[:CONFIG["batch"]] for k, v in t.items()}


def _product_events_ms(prof) -> float:
    """CPU time (ms) of the heads' output layer's forward and backward events, their operators included."""
    return sum(e.cpu_time_total for e in prof.key_averages()
               if e.key in ("HeadsOutput", "HeadsOutputBackward")) / 1e3


def measure(steps: int, rounds: int, report=print) -> dict[str, dict[str, list[float]]]:
    """Per mode: the step's and the product's milliseconds and the minor page faults per step, one figure per
    round; under ``"alone"``, per round, :func:`operators_alone`."""
    m, batch = _setup()
    out = {mode: {"step_ms": [], "product_ms": [], "page_faults": []} for mode in MODES}
    out["alone"] = []

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
            out["profiler"]["product_ms"].append(_product_events_ms(prof) / steps)
            timer = _ProductTimer()
            with timer:
                record("timers", run(before_timing=timer.reset))
            out["timers"]["product_ms"].append((timer.forward + timer.backward) * 1e3 / steps)
            out["alone"].append(operators_alone(m, batch))
            steps_ms = ", ".join(f"{mode} step {out[mode]['step_ms'][-1]:.2f} ms "
                                 f"({out[mode]['page_faults'][-1]:.0f} page faults)" for mode in MODES)
            report(f"round {k + 1}/{rounds}: {steps_ms}; product: profiler {out['profiler']['product_ms'][-1]:.2f} ms, "
                   f"timers {out['timers']['product_ms'][-1]:.2f} ms; operators alone "
                   f"{sum(ms for ms, _ in out['alone'][-1].values()):.2f} ms")
    return out


#: the groups of the compiled step's profiled time, in the table's order; the rest of the plain step follows them
COMPILED_PARTS = ("Adam's fused update", "matrix products", "generated kernels")
#: inductor's name for the profiler event of one of its generated C++ kernels
_KERNEL = re.compile(r"graph_\d+_cpp_")


def _compiled_part(key: str) -> str | None:
    """The :data:`COMPILED_PARTS` group of a profiler event's name, or ``None``."""
    if key == "aten::_fused_adam_":
        return COMPILED_PARTS[0]
    if key in ("aten::mm", "aten::addmm", "aten::bmm"):
        return COMPILED_PARTS[1]
    if _KERNEL.match(key):
        return COMPILED_PARTS[2]
    return None


def compiled_parts(events, steps: int) -> tuple[dict[str, tuple[float, int]], list[tuple[float, int, str]], float]:
    """From the profiler's averaged ``events`` of ``steps`` steps: per group of
    :data:`COMPILED_PARTS`, (self ms per step, calls per step); and the
    generated kernels as (ms per step, calls per step, name), slowest first;
    and the matrix products' floating-point operations per step (where the
    profiler counted them, ``with_flops``)."""
    parts = {part: [0.0, 0] for part in COMPILED_PARTS}
    kernels, flops = [], 0
    for e in events:
        part = _compiled_part(e.key)
        if part is None:
            continue
        if part == COMPILED_PARTS[1]:
            flops += getattr(e, "flops", 0) or 0
        ms = e.self_cpu_time_total / 1e3 / steps
        parts[part][0] += ms
        parts[part][1] += e.count
        if part == COMPILED_PARTS[2]:
            kernels.append((ms, e.count / steps, e.key))
    return {part: (ms, n / steps) for part, (ms, n) in parts.items()}, sorted(kernels, reverse=True), flops / steps


def measure_compiled(steps: int, rounds: int, report=print) -> dict:
    """Per round: the plain compiled step's milliseconds, and :func:`compiled_parts` of as many profiled steps."""
    import torch._inductor.config as inductor

    out = {"step_ms": [], "parts": [], "kernels": [], "flops": [], "faults": [], "plain_faults": [], "warmup_s": None}
    with inductor.patch({"cpp.enable_kernel_profile": True}):
        m, batch = _setup(compile=True)
        with gc_frozen():
            start = time.perf_counter()
            for _ in range(5):  # the first compiles
                m.train_step(batch, "direct")
            out["warmup_s"] = time.perf_counter() - start
            for k in range(rounds):
                faults, start = resource.getrusage(resource.RUSAGE_SELF).ru_minflt, time.perf_counter()
                for _ in range(steps):
                    m.train_step(batch, "direct")
                out["step_ms"].append((time.perf_counter() - start) * 1e3 / steps)
                out["plain_faults"].append((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / steps)
                schedule = torch.profiler.schedule(wait=0, warmup=WARMUP, active=steps)
                faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
                with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU], schedule=schedule,
                                            acc_events=True, with_flops=True) as prof:
                    for _ in range(WARMUP + steps):
                        m.train_step(batch, "direct")
                        prof.step()
                out["faults"].append((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / (WARMUP + steps))
                parts, kernels, flops = compiled_parts(prof.key_averages(), steps)
                out["parts"].append(parts)
                out["kernels"].append(kernels)
                out["flops"].append(flops)
                report(f"round {k + 1}/{rounds}: step {out['step_ms'][-1]:.2f} ms; "
                       + ", ".join(f"{part} {ms:.2f} ms" for part, (ms, _) in parts.items()))
    return out


def _header(args, what: str) -> list[str]:
    prov = provenance()
    return [
        f"Generated by `{args.invocation}` at {made_at(prov, 10)}: the public configuration (inputs (q, qd, qdd), "
        f"{CONFIG['batch']} samples), direct, float64, one thread; {what}. Machine: {machine(prov)}, "
        f"torch {prov.get('packages', {}).get('torch')}; {prov.get('utc', '')[:10]}.",
    ]


def main_compiled(args) -> int:
    figures = measure_compiled(args.steps, args.rounds)
    step = statistics.median(figures["step_ms"])
    lines = [
        "# Where SyReNets' compiled training step spends its time",
        "",
        *_header(args, f"`compile=True`; {args.rounds} rounds of {args.steps} steps"),
        "",
        "Each generated kernel is a profiler event of its own. The first three rows are the profiled self time per "
        "step, each the lowest of the rounds (in some rounds the profiled steps write the weights' gradients to "
        "freshly mapped memory, and the page faults inflate the generated kernels' events); the plain "
        "(unprofiled) step is the median of the rounds, and everything else is what is left of it: Python, "
        "dispatch, autograd and allocation between them. The five warm-up steps, which compile, "
        f"took {figures['warmup_s']:.1f} s. Each round's generated kernels, profiled (minor page faults a step): "
        + ", ".join(f"{r[COMPILED_PARTS[2]][0]:.2f} ms ({f:.0f})" for r, f in zip(figures["parts"], figures["faults"]))
        + "; the plain steps' minor page faults a step: "
        + ", ".join(f"{f:.1f}" for f in figures["plain_faults"]) + ".",
        "",
        "| part | calls per step | ms per step | share of the plain step |",
        "|---|---:|---:|---:|",
    ]
    total = 0.0
    for part in COMPILED_PARTS:
        ms = min(r[part][0] for r in figures["parts"])
        total += ms
        lines.append(f"| {part} | {figures['parts'][0][part][1]:.0f} | {ms:.2f} | {ms / step:.0%} |")
    lines += [
        f"| everything else | | {step - total:.2f} | {(step - total) / step:.0%} |",
        f"| plain step | | {step:.2f} | 100% |",
        "",
        f"The matrix products do {statistics.median(figures['flops']) / 1e6:.0f} MFLOP a step (the profiler's count), "
        f"{statistics.median(f / r[COMPILED_PARTS[1]][0] / 1e6 for f, r in zip(figures['flops'], figures['parts'])):.1f} "
        "GFLOP/s in the median round.",
        "",
        "The slowest generated kernels (in the round where the generated kernels took least; inductor names a "
        "kernel after the operators it fuses):",
        "",
        "| ms per step | calls per step | kernel |",
        "|---:|---:|---|",
    ]
    quickest = min(range(len(figures["parts"])), key=lambda k: figures["parts"][k][COMPILED_PARTS[2]][0])
    for ms, calls, name in figures["kernels"][quickest][:8]:
        lines.append(f"| {ms:.3f} | {calls:g} | `{name[:120]}{'…' if len(name) > 120 else ''}` |")
    text = "\n".join(lines) + "\n"
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0


def main(args) -> int:
    if args.out is None:
        args.out = Path("results/syrenets/speed/syrenets_profile_compiled.md" if args.compiled else "results/syrenets/speed/syrenets_profile.md")
    check_output(args.out)
    if args.compiled:
        return main_compiled(args)
    figures = measure(args.steps, args.rounds)
    alone = figures.pop("alone")
    med = {mode: {k: statistics.median(v) for k, v in f.items()} for mode, f in figures.items()}
    lines = [
        "# Where SyReNets' training step spends its time, and the heads' product in it",
        "",
        *_header(args, f"medians of {args.rounds} rounds of {args.steps} steps per mode, the modes in turn"),
        "",
        "The product is the heads' output layer, `W2` of shape (heads, terms, hidden units) applied to the "
        "hidden units, forward and backward, all layers.",
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
    step = med["plain"]["step_ms"]
    total = statistics.median(sum(ms for ms, _ in r.values()) for r in alone)
    lines += [
        "",
        "## Where a plain step's time goes",
        "",
        "Every ATen operator of one step (forward, backward, Adam's update), each called again alone on copies "
        "of its arguments and timed; medians of the rounds. Each operator alone finds its inputs in the cache, so "
        "the sum is a floor for what the same operators cost in any order. The rest of the plain step is the time "
        "between the operators: Python, autograd's bookkeeping and memory allocation.",
        "",
        "| part | operator calls | ms per step | share of the plain step |",
        "|---|---:|---:|---:|",
    ]
    for part in PARTS:
        ms = statistics.median(r[part][0] for r in alone)
        lines.append(f"| {part} | {alone[0][part][1]} | {ms:.2f} | {ms / step:.0%} |")
    lines += [
        f"| all operators, each alone | {sum(n for _, n in alone[0].values())} | {total:.2f} | {total / step:.0%} |",
        f"| between the operators | | {step - total:.2f} | {(step - total) / step:.0%} |",
        f"| plain step | | {step:.2f} | 100% |",
    ]
    text = "\n".join(lines) + "\n"
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0
