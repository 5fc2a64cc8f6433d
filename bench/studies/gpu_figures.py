"""The GPU figures of seeds trained stacked (:mod:`methods.stacking`), in
one run on one machine, each beside what it is compared with:

1. SyReNets, indirect, on the double pendulum: training steps per second of
   one seed alone and of each of 10 seeds stacked, against the public
   code's 1.25 steps/s (:data:`PUBLIC_STEPS_PER_S`);
2. the MLP and DeLaN on the Panda: seed-steps per second with 1, 10 and 100
   seeds stacked on the device, beside one CPU core of the same machine
   training seeds one by one (its rate per seed does not depend on how many
   it trains, so it trains :attr:`Sizes.cpu_seeds` of them);
3. where the stacked SyReNets step's time goes on the device: torch's
   profiler over :attr:`Sizes.profile_steps` steps of the table's 10 seeds
   stacked (:mod:`bench.studies.device_profile`);
4. the paper's 10-seed indirect table in the closest stackable
   configuration to ``best-300s`` (``best-300s`` compiles one network's pass,
   so it trains alone: the same settings, not compiled), for the steps that
   300 s gave each seed of the published ``best-300s`` table on one core
   (:data:`TABLE_RECORDS`), timed, with its test MSE beside the published
   one's (a probe times the pace first; where the published steps would
   take longer than :attr:`Sizes.table_allowance_s`, it does the steps that
   fit, and the page says so, with the time the whole would take);

with the device's model and torch's and CUDA's versions::

    python -m bench study gpu [--device cuda] [--data DIR] [--out DIR]

It needs no Pinocchio: the Panda's samples are read from ``--data``
(``python -m bench study gpu --prepare DIR`` writes them on a machine that
has it), so that a bare GPU machine runs it from the project's files and the
wheels ``--dry-run`` lists (:data:`WHEELS`). ``--dry-run`` lists every file
it would carry to such a machine with its size. ``--tiny`` runs every part
at toy sizes (the tests run it on the CPU).

Each fit's time is its loop's, ``loop_seconds`` (after its one-time
compiling, to its loop's end, evaluations on its schedule included);
SyReNets runs without its refinement after training (``refine=False``),
which a step count does not bound. The parts run in the order ``--parts``
names them, and the page and JSON are written again after each, so that a
run stopped by its machine's limit keeps the parts it finished.
"""

from __future__ import annotations

import dataclasses
import json
import os
import statistics
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bench.core.data import Dataset, generate, mse
from bench.core.devices import CHOICES, describe, resolve
from bench.core.errors import UserError
from bench.core.fileio import atomic_write
from bench.runner.progress import print_now
from bench.runner.provenance import cpu_model
from bench.runner.spec import TEST_SEED_OFFSET
from bench.studies import device_profile
import systems
from methods import METHODS
from methods.stacking import fit_stacked
from bench.core.budget import Budget

ROOT = Path(__file__).resolve().parents[2]
#: the public code's training speed on the paper's GPU, steps/s (results/syrenets/speed.md)
PUBLIC_STEPS_PER_S = 1.25
#: the targets: each of 10 stacked SyReNets seeds at this multiple of the public code's speed; the MLP and
#: DeLaN with 100 stacked seeds at this multiple of one CPU core's seed-steps/s
TARGET_SYRENETS, TARGET_PANDA = 100.0, 30.0
#: the published best-300s table on one core, whose records give the steps 300 s gave each seed
TABLE_RECORDS = ROOT / "results" / "syrenets" / "studies" / "syrenets_300s_compiled_best" / "records"
#: the closest stackable configuration to best-300s: its settings, not compiled, no refinement after training
TABLE_CONFIG = {**METHODS["syrenets"].configurations["best-300s"].values, "compile": False, "refine": False}
#: what a bare machine lacks that the suite imports, as pip pins, with what they need that the machine's image
#: lacks (deap imports moocore, which needs cffi, pycparser and platformdirs); fetched here into ``.whl``
WHEELS = ("deap==1.4.4", "moocore==0.3.2", "cffi==2.1.1", "pycparser==3.12", "platformdirs==4.14.8")
#: the parts, in their default order
PARTS = ("syrenets", "panda", "profile", "table")
#: the prepared Panda samples, in ``--data``
PANDA_FILE = "panda.npz"
#: what may travel to a device machine, MiB
CARRY_LIMIT_MIB = 64


@dataclass(frozen=True)
class Sizes:
    """How much work each part does."""

    syrenets_steps: int = 300
    syrenets_seeds: tuple[int, ...] = (1, 10)
    panda_steps: int = 100
    panda_seeds: tuple[int, ...] = (1, 10, 100)
    cpu_seeds: int = 2
    cpu_steps: int = 20
    n_train: int = 2048
    table_seeds: int = 10
    #: ``None``: the published table's median steps (:data:`TABLE_RECORDS`)
    table_steps: int | None = None
    #: the steps that time the table's pace first
    table_probe_steps: int = 300
    #: the most seconds the table may take: where the published steps would take longer, it does what fits
    table_allowance_s: float = 200.0
    table_n_train: int = 32000
    table_n_test: int = 10000
    #: the profiled steps of the table's seeds stacked
    profile_steps: int = 40
    #: each method's configuration starts from its smoke configuration (toy networks, nothing compiled)
    smoke: bool = False

    def config(self, method: str, **values) -> dict:
        """``method``'s configuration here: its defaults (or smoke configuration) with ``values``."""
        return {**(METHODS[method].smoke_config() if self.smoke else {}), **values}


FULL = Sizes()
TINY = Sizes(syrenets_steps=3, syrenets_seeds=(1, 2), panda_steps=3, panda_seeds=(1, 2), cpu_seeds=1, cpu_steps=2,
             n_train=64, table_seeds=2, table_steps=4, profile_steps=2, table_probe_steps=2, table_allowance_s=120.0, table_n_train=96, table_n_test=48, smoke=True)


def published_table() -> dict:
    """The published best-300s table's seeds: their steps in 300 s on one core, and test MSEs."""
    records = [json.loads(p.read_text()) for p in sorted(TABLE_RECORDS.glob("*.json"))]
    records = [r for r in records if r.get("status") == "ok" and r.get("steps")]
    if not records:
        raise UserError(f"{TABLE_RECORDS}: no records of the published best-300s table to take its steps from")
    tests = [r["test_mse"] for r in records]
    return {"steps": int(statistics.median(r["steps"] for r in records)), "seeds": len(records),
            "test_mse_mean": float(np.mean(tests)), "test_mse_std": float(np.std(tests, ddof=1)) if len(tests) > 1 else 0.0}


# -- the Panda's samples, prepared where Pinocchio is --------------------------------------------------------------

def prepare(folder: Path, n: int) -> Path:
    """Write ``n`` of the Panda's generated samples (seed 0) to ``folder``; needs Pinocchio."""
    if systems.WITHOUT_ARMS:
        raise UserError(f"--prepare: {systems.WITHOUT_ARMS}")
    data = generate(systems.SYSTEMS["panda"](), n, 0)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / PANDA_FILE
    atomic_write(path, lambda f: np.savez_compressed(f, q=data.q, qd=data.qd, qdd=data.qdd, tau=data.tau), binary=True)
    return path


def panda_samples(folder: Path | None, n: int) -> Dataset:
    """The Panda's samples: from ``folder`` where prepared, else generated (which needs Pinocchio)."""
    path = None if folder is None else folder / PANDA_FILE
    if path is not None and path.is_file():
        with np.load(path) as f:
            arrays = {k: f[k] for k in ("q", "qd", "qdd", "tau")}
        if len(arrays["q"]) < n:
            raise UserError(f"{path}: {len(arrays['q'])} samples, fewer than the {n} asked for (--prepare again)")
        return Dataset(*(arrays[k][:n] for k in ("q", "qd", "qdd", "tau")), None, "panda", f"{path} (prepared)")
    if systems.WITHOUT_ARMS:
        raise UserError(f"no {PANDA_FILE} in --data {folder}, and generating it here fails: {systems.WITHOUT_ARMS}")
    return generate(systems.SYSTEMS["panda"](), n, 0)


# -- the measurements ---------------------------------------------------------------------------------------------

def _fresh(method: str, config: dict, device: str):
    return METHODS[method](**config).use_device(device)


def _fit_stack(method: str, config: dict, datasets: list[Dataset], steps: int, device: str, system=None) -> list:
    """``method`` fitted on each of ``datasets`` (seeds 0, 1, …) stacked on ``device``, ``steps`` each."""
    return fit_stacked([_fresh(method, config, device) for _ in datasets], datasets, "indirect",
                       list(range(len(datasets))), budget=Budget(steps=steps), system=system)


def stacked(method: str, config: dict, datasets: list[Dataset], steps: int, device: str, system=None) -> dict:
    """The seeds of ``datasets`` trained stacked on ``device`` for ``steps`` each."""
    fitted = _fit_stack(method, config, datasets, steps, device, system)
    loop = fitted[0].fit_info["loop_seconds"]  # the first seed's clock starts first and its loop ends with all
    return {"seeds": len(datasets), "steps": steps, "loop_s": loop, "steps_per_s": steps / loop,
            "seed_steps_per_s": len(datasets) * steps / loop}


def alone(method: str, config: dict, datasets: list[Dataset], steps: int, device: str, system=None) -> dict:
    """The seeds of ``datasets`` trained one by one on ``device`` for ``steps`` each."""
    loop = sum(_fresh(method, config, device).fit(d, "indirect", k, Budget(steps=steps), system=system)
               .fit_info["loop_seconds"]
               for k, d in enumerate(datasets))
    return {"seeds": len(datasets), "steps": steps, "loop_s": loop, "steps_per_s": len(datasets) * steps / loop,
            "seed_steps_per_s": len(datasets) * steps / loop}


def warm(method: str, config: dict, data: Dataset, device: str, system=None) -> None:
    """The process's one-time work for ``method`` on ``device`` (imports, kernels, compiling), alone and stacked."""
    _fresh(method, config, device).fit(data, "indirect", 0, budget=Budget(steps=1), system=system)
    fit_stacked([_fresh(method, config, device) for _ in range(2)], [data, data], "indirect", [0, 1], Budget(steps=1),
                system=system)


def syrenets_part(sizes: Sizes, device: str, report) -> dict:
    system = systems.get_system("double_pendulum")
    config = sizes.config("syrenets", refine=False)
    data = [generate(system, sizes.n_train, k) for k in range(max(sizes.syrenets_seeds))]
    warm("syrenets", config, data[0], device, system)
    one = alone("syrenets", config, data[:1], sizes.syrenets_steps, device, system)
    report(f"syrenets alone on {device}: {one['steps_per_s']:.4g} steps/s")
    rows = []
    for s in sizes.syrenets_seeds:
        row = stacked("syrenets", config, data[:s], sizes.syrenets_steps, device, system)
        row["x_public"] = row["steps_per_s"] / PUBLIC_STEPS_PER_S
        rows.append(row)
        report(f"syrenets, {s} stacked on {device}: {row['steps_per_s']:.4g} steps/s each "
               f"({row['x_public']:.3g}x the public code's {PUBLIC_STEPS_PER_S})")
    return {"alone": one, "stacked": rows}


def panda_part(method: str, sizes: Sizes, device: str, data: Dataset, report) -> dict:
    config = sizes.config(method)
    datasets = [data] * max(sizes.panda_seeds)  # one set of samples for every seed: a step's work does not depend on its values
    warm(method, config, data, "cpu")
    cpu = alone(method, config, datasets[:sizes.cpu_seeds], sizes.cpu_steps, "cpu")
    report(f"{method} on the Panda, one CPU core one by one: {cpu['seed_steps_per_s']:.4g} seed-steps/s")
    if device != "cpu":
        warm(method, config, data, device)
    rows = []
    for s in sizes.panda_seeds:
        row = stacked(method, config, datasets[:s], sizes.panda_steps, device)
        row["x_cpu_core"] = row["seed_steps_per_s"] / cpu["seed_steps_per_s"]
        rows.append(row)
        report(f"{method} on the Panda, {s} stacked on {device}: {row['seed_steps_per_s']:.4g} seed-steps/s "
               f"({row['x_cpu_core']:.3g}x one CPU core)")
    return {"cpu_core": cpu, "stacked": rows}


def profile_part(sizes: Sizes, device: str, report) -> dict:
    """Torch's profiler over :attr:`Sizes.profile_steps` steps of the table's seeds stacked, after two
    unprofiled steps that do the one-time work."""
    system = systems.get_system("double_pendulum")
    seeds = list(range(sizes.table_seeds))
    train = [generate(system, sizes.n_train, k) for k in seeds]
    config = sizes.config("syrenets", **TABLE_CONFIG)

    _fit_stack("syrenets", config, train, 2, device, system)
    out = {"seeds": len(seeds), "config": config,
           **device_profile.profile_call(lambda: _fit_stack("syrenets", config, train, sizes.profile_steps, device, system),
                                         device, sizes.profile_steps)}
    report(f"profile: {len(seeds)} stacked syrenets seeds, {out['ms_per_step']:.3g} ms a step profiled; device busy "
           f"{100 * out['device_busy']:.3g} %, {out['kernels_per_step']:.4g} kernels a step, operators "
           f"{100 * out['operators_cpu_share']:.3g} % of the wall on the CPU")
    return out


def table_part(sizes: Sizes, device: str, report) -> dict:
    """The 10-seed table stacked: a probe of :attr:`Sizes.table_probe_steps` times the pace, then the
    published steps where that pace does them within :attr:`Sizes.table_allowance_s`, else the steps it
    does in that time (a work budget either way, so the fits are those of their seeds and steps)."""
    system = systems.get_system("double_pendulum")
    published = published_table()
    wanted = sizes.table_steps or published["steps"]
    seeds = list(range(sizes.table_seeds))
    train = [generate(system, sizes.table_n_train, k) for k in seeds]
    test = [generate(system, sizes.table_n_test, k + TEST_SEED_OFFSET) for k in seeds]
    config = sizes.config("syrenets", **TABLE_CONFIG)

    def stack(steps: int):
        start = time.perf_counter()
        fitted = _fit_stack("syrenets", config, train, steps, device, system)
        return fitted, time.perf_counter() - start

    probe, _ = stack(sizes.table_probe_steps)
    pace = sizes.table_probe_steps / probe[0].fit_info["loop_seconds"]  # steps/s of each seed, stacked
    projected = wanted / pace
    steps = wanted if projected <= sizes.table_allowance_s else max(1, int(pace * sizes.table_allowance_s))
    report(f"the 10-seed table: {len(seeds)} seeds stacked at {pace:.4g} steps/s each; the published {wanted} steps "
           f"would take {projected:.4g} s; doing {steps}")
    fitted, wall = stack(steps)
    tests = [mse(m.predict_torque(t), t.tau) for m, t in zip(fitted, test)]
    out = {"steps_wanted": wanted, "steps": steps, "seeds": len(seeds), "probe_steps_per_s": pace,
           "projected_s": projected, "wall_s": wall, "loop_s": fitted[0].fit_info["loop_seconds"],
           "test_mse": tests, "test_mse_mean": float(np.mean(tests)),
           "test_mse_std": float(np.std(tests, ddof=1)) if len(tests) > 1 else 0.0, "published": published,
           "config": config}
    report(f"the table: {steps} steps in {wall:.4g} s; test MSE {out['test_mse_mean']:.3g} (± {out['test_mse_std']:.2g}); "
           f"published on one core {published['test_mse_mean']:.3g}")
    return out


def versions(device: str) -> dict:
    where = describe(device)
    return {"device": where.get("name") or cpu_model(), "device_type": where["type"], "torch": torch.__version__,
            "cuda": torch.version.cuda, "cpu": cpu_model()}


# -- what travels -------------------------------------------------------------------------------------------------

def _tree_files() -> list[Path]:
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         capture_output=True, check=True).stdout.decode().split("\0")
    return [ROOT / p for p in out if p and (ROOT / p).is_file()]


def _shown(path: Path) -> str:
    return os.path.relpath(path)


def carried(data: Path | None, wheels: Path) -> tuple[list[tuple[str, int]], list[str]]:
    """What travels to a bare machine, ``(name, bytes)`` each: the working tree, the prepared data,
    the wheels; and the wheels still to fetch."""
    tree = sum(p.stat().st_size for p in _tree_files())
    rows = [("the project's working tree (tracked and untracked, not ignored)", tree)]
    if data is not None:
        rows += [(_shown(p), p.stat().st_size) for p in sorted(data.glob("*")) if p.is_file()]
    have = sorted(wheels.glob("*.whl")) if wheels.is_dir() else []
    rows += [(_shown(p), p.stat().st_size) for p in have]
    names = {p.name.split("-")[0].lower() for p in have}
    missing = [w for w in WHEELS if w.split("==")[0].replace("-", "_").lower() not in names]
    return rows, missing


def dry_run(data: Path | None, wheels: Path) -> int:
    rows, missing = carried(data, wheels)
    total = sum(size for _, size in rows)
    for name, size in rows:
        print(f"{size / 2**20:10.2f} MiB  {name}")
    print(f"{total / 2**20:10.2f} MiB  in all (at most {CARRY_LIMIT_MIB} MiB travel)")
    if data is None or not (data / PANDA_FILE).is_file():
        print(f"to prepare: python -m bench study gpu --prepare {data or 'DIR'}  (the Panda's samples; needs Pinocchio)")
    for w in missing:
        print(f"to fetch: python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp "
              f"--platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d {_shown(wheels)} {w}")
    print(f"then, there, from the project's root: python3 -m pip install -q --no-index --no-deps --target /tmp/site "
          f"{_shown(wheels)}/*.whl && PYTHONPATH=/tmp/site python3 -m bench study gpu --device cuda "
          f"--data {_shown(data) if data else 'DIR'} --out OUT")
    return 0 if total <= CARRY_LIMIT_MIB * 2**20 else 1


# -- the command --------------------------------------------------------------------------------------------------

def add_arguments(parser) -> None:
    parser.add_argument("--device", choices=CHOICES, default="cuda", help="where the stacked fits train (default cuda)")
    parser.add_argument("--data", type=Path, default=None, help=f"a folder holding the prepared {PANDA_FILE}")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "harness" / "gpu",
                        help="the folder its page and JSON go to (default results/harness/gpu)")
    parser.add_argument("--tiny", action="store_true", help="every part at toy sizes (a check that the path runs)")
    parser.add_argument("--prepare", type=Path, default=None, metavar="DIR",
                        help=f"write the Panda's samples to DIR/{PANDA_FILE} (needs Pinocchio) and stop")
    parser.add_argument("--dry-run", action="store_true", help="list what would travel to a bare machine, with sizes")
    parser.add_argument("--wheels", type=Path, default=ROOT / ".whl", help="the folder of wheels that travel (default .whl)")
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS),
                        help="which parts to run, in this order (default all)")


def main(args) -> int:
    sizes = TINY if args.tiny else FULL
    if args.prepare is not None:
        path = prepare(args.prepare, max(FULL.n_train, sizes.n_train))
        print(f"wrote {path} ({path.stat().st_size / 2**20:.2f} MiB)")
        return 0
    if args.dry_run:
        return dry_run(args.data, args.wheels)
    device = resolve(args.device)
    torch.set_num_threads(1)
    began = time.perf_counter()
    info = versions(device)
    print_now(f"on {info['device']} (torch {info['torch']}, CUDA {info['cuda']}); CPU {info['cpu']}, one thread")
    out = {"versions": info, "sizes": dataclasses.asdict(sizes), "command": args.invocation}
    panda = panda_samples(args.data, sizes.n_train) if "panda" in args.parts else None  # before any long work
    runs = {"syrenets": lambda: attempt("syrenets", lambda: syrenets_part(sizes, device, print_now)),
            "panda": lambda: {m: attempt(m, lambda m=m: panda_part(m, sizes, device, panda, print_now))
                              for m in ("mlp", "delan")},
            "profile": lambda: attempt("the profile", lambda: profile_part(sizes, device, print_now)),
            "table": lambda: attempt("the table", lambda: table_part(sizes, device, print_now))}
    args.out.mkdir(parents=True, exist_ok=True)
    for part in dict.fromkeys(args.parts):
        out[part] = runs[part]()
        out["seconds"] = time.perf_counter() - began
        text = page(out)
        atomic_write(args.out / "gpu_figures.json", lambda f: f.write(json.dumps(out, indent=1)))
        atomic_write(args.out / "gpu_figures.md", lambda f: f.write(text))
    print(text)
    return 1 if "Failed here:" in text else 0


def attempt(name: str, part) -> dict:
    """``part()``, or where it raises, ``{"error": its line}``: on a machine lent for minutes, one part
    that fails (a compiler missing there, say) must not take the others' figures with it."""
    try:
        return part()
    except Exception as exc:  # noqa: BLE001 -- reported on the page and in the JSON, the next part runs
        line = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"
        print_now(f"{name}: failed: {line}")
        return {"error": line}


def page(out: dict) -> str:
    """The page of a run's figures, against the targets."""
    v = out["versions"]
    lines = ["# Stacked seeds on a device", "",
             f"Measured by `{out['command']}` on {v['device']} ({v['device_type']}; torch {v['torch']}, CUDA {v['cuda']}), "
             f"beside one core of its CPU ({v['cpu']}), one thread; {out['seconds']:.0f} s in all.", ""]
    failed = [f"{name}: {part['error']}" for name, part in
              [("syrenets", out.get("syrenets", {})), ("profile", out.get("profile", {})), ("table", out.get("table", {})),
               *((m, p) for m, p in out.get("panda", {}).items())] if "error" in part]
    if failed:
        lines += ["Failed here: " + "; ".join(failed) + ".", ""]
    if "syrenets" in out and "error" not in out["syrenets"]:
        s = out["syrenets"]
        lines += ["## SyReNets, indirect, double pendulum", "",
                  f"Target: each of 10 stacked seeds at ≥ {TARGET_SYRENETS:g}× the public code's {PUBLIC_STEPS_PER_S} steps/s.", "",
                  "| seeds | steps/s (each seed) | × public code |", "|---:|---:|---:|",
                  f"| 1, alone | {s['alone']['steps_per_s']:.4g} | {s['alone']['steps_per_s'] / PUBLIC_STEPS_PER_S:.3g} |"]
        lines += [f"| {r['seeds']}, stacked | {r['steps_per_s']:.4g} | {r['x_public']:.3g} |" for r in s["stacked"]]
        lines.append("")
    if "panda" in out:
        lines += ["## The MLP and DeLaN, indirect, Panda", "",
                  f"Target: 100 stacked seeds at ≥ {TARGET_PANDA:g}× one CPU core's seed-steps/s (the core trains "
                  f"seeds one by one).", "",
                  "| method | seeds | stacked seed-steps/s | one CPU core seed-steps/s | × one core |", "|---|---:|---:|---:|---:|"]
        for m, p in ((m, p) for m, p in out["panda"].items() if "error" not in p):
            lines += [f"| {m} | {r['seeds']} | {r['seed_steps_per_s']:.4g} | {p['cpu_core']['seed_steps_per_s']:.4g} "
                      f"| {r['x_cpu_core']:.3g} |" for r in p["stacked"]]
        lines.append("")
    if "profile" in out and "error" not in out["profile"]:
        p = out["profile"]
        lines += ["## Where the stacked SyReNets step's time goes", "",
                  f"Torch's profiler over the table's configuration, {p['seeds']} seeds stacked on {p['device']}.", "",
                  *device_profile.page_lines(p)]
    if "table" in out and "error" not in out["table"]:
        t = out["table"]
        pub = t["published"]
        full = t["steps"] == t["steps_wanted"]
        lines += ["## The paper's 10-seed indirect table", "",
                  f"SyReNets in best-300s's settings without compiling ({', '.join(f'{k}={v}' for k, v in t['config'].items())}), "
                  f"{t['seeds']} seeds stacked. Wanted: {t['steps_wanted']} steps each (the median steps 300 s gave a "
                  f"seed of the published best-300s table on one core: {pub['steps']}); at the pace a probe measured, "
                  f"{t['probe_steps_per_s']:.4g} steps/s each, they take {t['projected_s']:.4g} s"
                  + ("." if full else f", past the {out['sizes']['table_allowance_s']:g} s allowed: the table did "
                                      f"the {t['steps']} steps that fit."), "",
                  "| | steps | time | test MSE, all seeds (mean ± sd) |", "|---|---:|---:|---:|",
                  f"| stacked on the device | {t['steps']} | {t['wall_s']:.1f} s | {t['test_mse_mean']:.3g} ± "
                  f"{t['test_mse_std']:.2g} |",
                  f"| published, one core each | {pub['steps']} (median) | 300 s a seed | {pub['test_mse_mean']:.3g} "
                  f"± {pub['test_mse_std']:.2g} |", ""]
    return "\n".join(lines) + "\n"
