"""The harness: systems x methods x experiments x seeds under a wall-clock budget.

* :func:`execute` runs one :class:`RunSpec` in the current process and
  returns its record; it never raises for a failing method.
* :func:`run_isolated` runs one spec in its own process (forked from a server
  that has imported torch and the suite once), with torch and BLAS threads
  pinned, and kills it at 1.5 x its budget (status ``timeout``). A
  crash or a non-finite result gives status ``failed`` with the reason.
* :func:`run_matrix` runs many specs on a pool of worker processes, writes
  one record per run atomically, and skips runs that already have a record,
  so a killed matrix loses no finished run and re-running it resumes.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import json
import math
import os
import signal
import subprocess
import sys
import time
import traceback
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

from bench import records as rec
from bench.errors import ConfigError, UserError
from bench.fileio import write_json
from bench.worker import THREAD_VARS

#: The ten seeds of every table, written once.
SEEDS: tuple[int, ...] = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9)
#: Test data for seed ``s`` is generated with seed ``s + TEST_SEED_OFFSET``.
TEST_SEED_OFFSET = 1000
#: The paper's data sizes.
N_TRAIN, N_TEST = 32000, 10000
#: A run is killed at this multiple of its budget.
KILL_FACTOR = 1.5
#: Seconds a worker may take to import and load data before its fit starts.
STARTUP_TIMEOUT_S = 300.0
#: Seconds a worker may take, after its fit, to evaluate the model on the full data.
EVALUATION_TIMEOUT_S = 900.0


@dataclass(frozen=True)
class RunSpec:
    """Everything that defines one run.

    Attributes
    ----------
    profile
        ``"default"`` (the method's real configuration) or ``"smoke"`` (its
        tiny CI configuration).
    hyperparameters
        Overrides on top of the profile.
    train_path, test_path
        CSV files in the suite's format; when ``train_path`` is ``None`` the
        data is generated with ``n_train`` samples from ``seed`` and
        ``n_test`` samples from ``seed + TEST_SEED_OFFSET``.
    domain_half_width
        Sample q, qd, qdd from U(-w, w) instead of the system's default.
    noise
        Gaussian noise added to the training targets, as a fraction of each
        target column's standard deviation (:func:`bench.data.add_noise`);
        the test targets stay clean.
    rollout
        Measure the rollout error (:mod:`bench.rollout`) of simulated systems.
    plugins
        Python files or modules to import before resolving names, for methods
        and systems registered outside the suite.
    """

    system: str
    method: str
    experiment: str
    seed: int
    budget_s: float
    profile: str = "default"
    hyperparameters: dict = field(default_factory=dict)
    n_train: int = N_TRAIN
    n_test: int = N_TEST
    train_path: str | None = None
    test_path: str | None = None
    domain_half_width: float | None = None
    plugins: tuple[str, ...] = ()
    threads: int = 1
    rollout: bool = True
    noise: float = 0.0

    @property
    def run_id(self) -> str:
        return rec.run_id(self.system, self.method, self.experiment, self.seed, self.noise)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["plugins"] = list(self.plugins)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "RunSpec":
        d = dict(d)
        d["plugins"] = tuple(d.get("plugins", ()))
        return cls(**d)


def import_plugins(plugins: Iterable[str]) -> None:
    """Import each plugin once: a ``.py`` path or a module name."""
    for plugin in plugins:
        try:
            _import_plugin(plugin)
        except UserError:
            raise
        except Exception as exc:
            raise UserError(f"plugin {plugin}: {type(exc).__name__}: {exc}") from exc


def _import_plugin(plugin: str) -> None:
    if not plugin.endswith(".py"):
        importlib.import_module(plugin)
        return
    path = Path(plugin).resolve()
    if not path.is_file():
        raise UserError(f"plugin {plugin}: no such file")
    if any(getattr(m, "__file__", None) and Path(m.__file__).resolve() == path for m in list(sys.modules.values())):
        return  # already imported (for instance by a test runner): do not register twice
    name = f"_bench_plugin_{path.stem}_{zlib.crc32(str(path).encode()):08x}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise UserError(f"plugin {plugin}: not an importable Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise


def method_config(spec: RunSpec) -> dict:
    from methods import METHODS

    cls = METHODS[spec.method]
    config = cls.smoke_config() if spec.profile == "smoke" else {}
    if spec.profile not in ("default", "smoke"):
        raise ConfigError(f"unknown profile {spec.profile!r}; choose default or smoke")
    config.update(spec.hyperparameters)
    return config


def load_data(spec: RunSpec, system):
    """Train and test data for ``spec`` (test is ``None`` when unavailable);
    the training targets carry ``spec.noise``."""
    from bench.data import add_noise

    train, test = _clean_data(spec, system)
    if spec.noise:
        train = add_noise(train, spec.experiment, spec.noise, spec.seed)
    return train, test


def _clean_data(spec: RunSpec, system):
    from bench.data import generate, read_csv

    if spec.train_path:
        train = read_csv(spec.train_path, dof=system.dof, system=system.name)
        test = read_csv(spec.test_path, dof=system.dof, system=system.name) if spec.test_path else None
        return train, test
    if not system.simulated:
        return system.load("train"), system.load("test")
    train = generate(system, spec.n_train, spec.seed)
    test = generate(system, spec.n_test, spec.seed + TEST_SEED_OFFSET)
    return train, test


def make_system(spec: RunSpec):
    from systems import SYSTEMS

    system = SYSTEMS[spec.system]()
    if spec.domain_half_width and system.simulated:
        system = SYSTEMS[spec.system](domain=system.scaled_domain(spec.domain_half_width))
    return system


def preflight(spec: RunSpec) -> dict | None:
    """A record for a run that cannot start (unavailable or not applicable), else ``None``."""
    from methods import METHODS

    from systems import SYSTEMS

    d = spec.to_dict()
    entry = METHODS.entry(spec.method)
    reason = entry.unavailable_reason()
    if reason:
        return rec.new_record(d, "unavailable", error=reason)
    reason = entry.obj.not_applicable_reason(spec.experiment)
    if reason:
        return rec.new_record(d, "not_applicable", error=reason)
    system = SYSTEMS[spec.system]
    if spec.experiment not in system.experiments and not spec.train_path:
        reason = system.not_applicable or f"{spec.system} has no data for the {spec.experiment} experiment"
        return rec.new_record(d, "not_applicable", error=reason)
    return None


def execute(spec: RunSpec, on_phase: Callable[[str], None] | None = None, data: tuple | None = None) -> dict:
    """Run ``spec`` in this process and return its record (never raises for the method's faults).

    Variants a method derives from its fit (:meth:`methods.base.Method.variants`)
    are scored on the same data and stored under ``details["variants"]``.

    ``on_phase`` is called with ``"fit"`` when the fit starts and with
    ``"evaluate"`` when it has ended (the budget covers the fit only).
    ``data`` is an already loaded ``(train, test)`` pair, else it is loaded
    from the spec.
    """
    d = spec.to_dict()
    try:
        import_plugins(spec.plugins)
        early = preflight(spec)
        if early:
            return early
        from methods import METHODS

        clock = time.perf_counter()
        system = make_system(spec)
        train, test = data if data is not None else load_data(spec, system)
        method = METHODS[spec.method](**method_config(spec))
        warm_up_torch()
        timing = {"load_s": time.perf_counter() - clock}
        if on_phase:
            on_phase("fit")
        method.fit(train, spec.experiment, spec.seed, spec.budget_s)
        if on_phase:
            on_phase("evaluate")
        clock = time.perf_counter()
        truth = system.lagrangian_sympy if system.simulated else None
        scores = _scores(method, spec.experiment, train, test, truth, system)
        info = method.fit_info
        variants = {
            name: {"status": "failed", "error": model} if isinstance(model, str)
            else {"status": "ok", **_scores(model, spec.experiment, train, test, truth, system)}
            for name, model in method.variants().items()
        }
        timing["evaluate_s"] = time.perf_counter() - clock
        fields = dict(
            **scores,
            steps=info.get("steps"),
            fit_seconds=info.get("fit_seconds"),
            stop_reason=info.get("stop_reason"),
            curve=_thin(info.get("curve", [])),
            hyperparameters=method.hyperparameters(),
            details={
                "train_source": train.source,
                "test_source": None if test is None else test.source,
                "n_train": len(train),
                "n_test": None if test is None else len(test),
                "domain": dataclasses.asdict(system.domain),
                **{k: v for k, v in info.items() if k not in ("curve", "steps", "fit_seconds", "stop_reason")},
                **method.record_details(),
                "variants": variants,
            },
        )
        if system.simulated and test is not None and spec.rollout:
            clock = time.perf_counter()
            fields["rollout"] = _rollout(method, system, test)
            timing["rollout_s"] = time.perf_counter() - clock
        fields["details"]["timing"] = {k: round(v, 3) for k, v in timing.items()}
        bad = [k for k in ("train_mse", "test_mse") if fields[k] is not None and not math.isfinite(fields[k])]
        if bad:
            return rec.new_record(d, "failed", error=f"non-finite {' and '.join(bad)} (the model produced NaN or inf)", **fields)
        return rec.new_record(d, "ok", **fields)
    except Exception as exc:
        tb = traceback.format_exc(limit=-6)
        return rec.new_record(d, "failed", error=f"{type(exc).__name__}: {exc}", details={"traceback": tb})


def warm_up_torch() -> None:
    """Do torch's lazy one-time work before a budget starts: constructing the
    first optimiser imports ``torch._dynamo`` (about 1 s on a laptop core),
    which would otherwise be charged to the first run's fit."""
    import torch

    torch.optim.Adam([torch.zeros(1, requires_grad=True)])


def _scores(model, experiment: str, train, test, truth=None, system=None) -> dict:
    """Train and test MSE in the experiment's target, the readable expression,
    and whether it is exactly the true Lagrangian (see :mod:`bench.recovery`)."""
    from bench.data import mse

    expr = model.readable_expression()
    out = {
        "train_mse": mse(model.predict(train, experiment), train.target(experiment)),
        "test_mse": mse(model.predict(test, experiment), test.target(experiment)) if test is not None else None,
        "expression": None if expr is None else _clip(str(expr)),
        "exact": None,
    }
    if expr is not None and truth is not None:
        from bench.recovery import judge

        out["exact"] = judge(expr, truth, system.dof, experiment, domain=system.domain).exact
    return out


def _rollout(model, system, test) -> dict:
    """The rollout entry (:mod:`bench.rollout`); a fault in it is recorded, not raised."""
    from bench.rollout import rollout_error

    try:
        return rollout_error(model, system, test)
    except Exception as exc:  # the model's fault: its own status
        return {"status": "failed", "q_rmse": None, "detail": f"{type(exc).__name__}: {exc}"}


#: longest expression text kept in a record
MAX_EXPRESSION_CHARS = 20000


def _clip(text: str) -> str:
    """An expression's text, cut at :data:`MAX_EXPRESSION_CHARS` with a note of its full length."""
    if len(text) <= MAX_EXPRESSION_CHARS:
        return text
    return text[:MAX_EXPRESSION_CHARS] + f" ... [cut: {len(text)} characters in all]"


def _thin(curve: list, keep: int = 300) -> list:
    """Keep at most ``keep`` curve points, always the first and last."""
    if len(curve) <= keep:
        return [list(p) for p in curve]
    step = (len(curve) - 1) / (keep - 1)
    return [list(curve[round(i * step)]) for i in range(keep)]


# -- process isolation ---------------------------------------------------------------

def thread_env(threads: int) -> dict:
    env = dict(os.environ)
    for var in THREAD_VARS:
        env[var] = str(threads)
    root = str(rec.PROJECT_ROOT)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


_FORK_SERVER = {"context": None, "failed": None}


def fork_server():
    """The multiprocessing fork server that runs are forked from, started on
    first use with :mod:`bench.preload` imported (torch, the suite, the
    registries), or ``None`` where it cannot be used: no ``fork`` on this
    platform, inside a daemonic process (a Dask worker), or it failed to start."""
    import multiprocessing

    if _FORK_SERVER["context"] is not None or _FORK_SERVER["failed"]:
        return _FORK_SERVER["context"]
    if "forkserver" not in multiprocessing.get_all_start_methods() or multiprocessing.current_process().daemon:
        _FORK_SERVER["failed"] = "unsupported here"
        return None
    from multiprocessing import forkserver

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["bench.preload"])
    saved = {var: os.environ.get(var) for var in THREAD_VARS}
    try:
        os.environ.update({var: "1" for var in THREAD_VARS})  # read by the server before it imports torch
        forkserver.ensure_running()
    except Exception as exc:
        _FORK_SERVER["failed"] = f"{type(exc).__name__}: {exc}"
        return None
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value
    _FORK_SERVER["context"] = ctx
    return ctx


class _Child:
    """A running worker: a process forked from the fork server, or a fresh
    interpreter where the fork server cannot serve the spec."""

    def __init__(self, spec: RunSpec, spec_file: Path, record_file: Path, phase_file: Path, log_file: Path, fresh: bool):
        ctx = None if fresh or spec.threads != 1 else fork_server()
        self.proc = self.popen = None
        if ctx is not None:
            from bench.worker import forked_main

            self.proc = ctx.Process(target=forked_main, args=(str(spec_file), str(record_file), str(phase_file), str(log_file), os.getcwd()))
            self.proc.start()
            return
        with open(log_file, "wb") as log:
            self.popen = subprocess.Popen(
                [sys.executable, "-m", "bench.worker", str(spec_file), str(record_file), str(phase_file)],
                env=thread_env(spec.threads), stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
            )

    @property
    def pid(self) -> int:
        return self.proc.pid if self.proc is not None else self.popen.pid

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds; whether the process has ended."""
        if self.proc is not None:
            self.proc.join(timeout)
            return self.proc.exitcode is not None
        try:
            self.popen.wait(timeout=timeout)
            return True
        except subprocess.TimeoutExpired:
            return False

    @property
    def returncode(self) -> int | None:
        return self.proc.exitcode if self.proc is not None else self.popen.returncode

    def kill(self) -> None:
        """Kill the worker's whole process group (it runs in its own session)."""
        try:
            os.killpg(self.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            if self.proc is not None:
                self.proc.kill()
            else:
                self.popen.kill()
        self.wait(None)


def run_isolated(spec: RunSpec, out_dir: str | os.PathLike, *, poll_s: float = 0.05, fresh: bool = False) -> dict:
    """Run ``spec`` in its own process; write and return its record.

    The process is forked from the harness's fork server (:func:`fork_server`),
    which has imported torch and the suite once; ``fresh=True``, a spec with
    more than one thread, or a platform without the server starts a fresh
    interpreter instead. The child reports its phases in a small file. From
    the start of its fit it has ``KILL_FACTOR * budget_s`` seconds to finish
    the fit before it is killed and recorded as ``timeout``; evaluation on the
    full data after the fit is not part of the budget and has
    ``EVALUATION_TIMEOUT_S``. A child that dies without writing a record is
    recorded as ``failed`` with the tail of its log.
    """
    out_dir = Path(out_dir)
    path = rec.record_path(out_dir, spec.run_id)
    logs = out_dir / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    spec_file, phase_file, log_file = (logs / f"{spec.run_id}{s}" for s in (".spec.json", ".phase", ".log"))
    for f in (phase_file, path, log_file):
        f.unlink(missing_ok=True)
    write_json(spec_file, spec.to_dict())
    d = spec.to_dict()
    child = _Child(spec, spec_file, path, phase_file, log_file, fresh)
    kill_at = time.monotonic() + STARTUP_TIMEOUT_S
    phase = "startup"
    record = None
    while not child.wait(poll_s):
        now = time.monotonic()
        new_phase = _read_phase(phase_file) or phase
        if new_phase != phase:
            phase = new_phase
            kill_at = now + (KILL_FACTOR * spec.budget_s if phase == "fit" else EVALUATION_TIMEOUT_S)
        if now >= kill_at:
            child.kill()
            if phase == "fit":
                error = f"fit still running at {KILL_FACTOR} x its {spec.budget_s:g} s budget; killed"
                record = rec.new_record(d, "timeout", error=error)
            elif phase == "startup":
                record = rec.new_record(d, "failed", error=f"did not start its fit within {STARTUP_TIMEOUT_S:g} s; killed")
            else:
                record = rec.new_record(d, "failed", error=f"evaluation after the fit took over {EVALUATION_TIMEOUT_S:g} s; killed")
            break
    if record is None:
        if path.exists():
            with open(path) as f:
                return json.load(f)
        tail = _tail(log_file)
        record = rec.new_record(d, "failed", error=f"worker exited with code {child.returncode} and wrote no record: {tail}")
    rec.write_record(path, record)
    return record


def _read_phase(path: Path) -> str | None:
    try:
        lines = path.read_text().split()
    except OSError:
        return None
    return lines[-1] if lines else None


def _tail(path: Path, lines: int = 3) -> str:
    try:
        text = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return "(no log)"
    return " | ".join(text[-lines:]) or "(empty log)"


# -- the matrix ------------------------------------------------------------------------

def build_specs(
    systems: Iterable[str],
    methods: Iterable[str],
    experiments: Iterable[str],
    seeds: Iterable[int],
    budget_s: float,
    noises: Iterable[float] = (0.0,),
    **common,
) -> list[RunSpec]:
    """The matrix systems x methods x experiments x noise levels x seeds."""
    noises = list(noises)
    return [
        RunSpec(system=s, method=m, experiment=e, seed=k, budget_s=budget_s, noise=float(z), **common)
        for s in systems for m in methods for e in experiments for z in noises for k in seeds
    ]


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


def run_matrix(
    specs: list[RunSpec],
    out_dir: str | os.PathLike,
    *,
    workers: int | None = None,
    resume: bool = True,
    report: Callable[[str], None] | None = None,
    cluster=None,
) -> list[dict]:
    """Run every spec, ``workers`` at a time, each in its own process.

    Runs that already have a record in ``out_dir`` are skipped (``resume``).
    Unavailable and not-applicable runs are recorded without starting a process.
    Returns the records in the order of ``specs``.

    ``cluster`` hands the runs to Dask distributed instead of the local pool:
    ``"local"`` starts a ``LocalCluster`` of ``workers`` single-threaded
    processes; a scheduler address (``"tcp://host:8786"``), a Dask cluster
    object (``dask_jobqueue.SLURMCluster(...)``) or a ``Client`` uses that.
    Each Dask task runs :func:`run_isolated` on its worker, in a scratch
    directory there, and returns the record, which is written here; workers
    need the suite installed, not a shared file system.
    """
    import_plugins({p for s in specs for p in s.plugins})
    report = report if report is not None else print_now
    workers = workers or default_workers()
    out_dir = Path(out_dir)
    results: dict[str, dict] = {}
    todo: list[RunSpec] = []
    resumed = cannot_run = 0
    for spec in specs:
        path = rec.record_path(out_dir, spec.run_id)
        if resume and path.exists():
            with open(path) as f:
                results[spec.run_id] = json.load(f)
            resumed += 1
            continue
        early = preflight(spec)
        if early:
            rec.write_record(path, early)
            results[spec.run_id] = early
            cannot_run += 1
            continue
        todo.append(spec)
    if report and cannot_run:
        report(f"{cannot_run} run(s) recorded without running (method unavailable here or not applicable)")
    tracker = _MatrixProgress(len(todo), resumed, workers, report)
    if todo and cluster is not None:
        for record in _run_on_dask(todo, out_dir, cluster, workers, tracker):
            results[record["run_id"]] = record
    elif todo:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for record in pool.map(lambda s: tracker.done(run_isolated(s, out_dir)), todo):
                results[record["run_id"]] = record
    tracker.summary()
    return [results[s.run_id] for s in specs]


def run_remote(spec_dict: dict) -> dict:
    """A Dask task: :func:`run_isolated` in a scratch directory; returns the record."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="syrenets-bench-") as scratch:
        return run_isolated(RunSpec.from_dict(spec_dict), scratch)


def _run_on_dask(todo: list[RunSpec], out_dir: Path, cluster, workers: int, tracker) -> Iterable[dict]:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UserError("--cluster needs Dask distributed: pip install 'syrenets-bench[dask]'") from None
    own = None
    if cluster == "local":
        own = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(own)
    elif isinstance(cluster, Client):
        client = cluster
    else:
        try:
            client = Client(cluster, timeout="30s")
        except OSError as exc:
            raise UserError(f"cannot reach the Dask scheduler {cluster}: {exc}") from None
    try:
        futures = [client.submit(run_remote, s.to_dict(), key=f"bench-{s.run_id}-{time.time_ns()}", pure=False) for s in todo]
        for future in as_completed(futures):
            record = future.result()
            rec.write_record(rec.record_path(out_dir, record["run_id"]), record)
            yield tracker.done(record)
    finally:
        if client is not cluster:
            client.close()
        if own is not None:
            own.close()


def print_now(line: str) -> None:
    """A progress ``report`` that prints each line at once."""
    print(line, flush=True)


def quiet(line: str) -> None:
    """A ``report`` for :func:`run_matrix` that prints nothing."""


class _MatrixProgress:
    """Progress of the matrix: finished, failed and remaining runs and the time left.

    With :func:`print_now` on a terminal this is a tqdm bar, with one line per
    finished run printed above it; otherwise (a log file, or another
    ``report``) each finished run gives one line that starts with a text bar.
    """

    def __init__(self, total: int, skipped: int, workers: int, report):
        self.total, self.skipped, self.workers, self.report = total, skipped, workers, report
        self.finished = self.failed = 0
        self.start = time.monotonic()
        if report and skipped:
            report(f"resuming: {skipped} run(s) already have records")
        if report:
            report(f"{total} run(s) to do on {workers} worker(s)")
        self.bar = None
        if report is print_now and total and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="run", dynamic_ncols=True, postfix={"failed": 0})

    def done(self, record: dict) -> dict:
        self.finished += 1
        self.failed += record["status"] != "ok"
        if not self.report:
            return record
        if record["status"] == "ok":
            test = record["test_mse"]
            outcome = f"ok train {record['train_mse']:.3g} test {'-' if test is None else f'{test:.3g}'}"
        else:
            outcome = f"{record['status']} ({record['error']})"
        what = f"{record['system']} {record['method']} {record['experiment']} seed={record['seed']}: {outcome}"
        if self.bar is not None:
            self.bar.write(what)
            self.bar.set_postfix(failed=self.failed, refresh=False)
            self.bar.update(1)
            return record
        elapsed = time.monotonic() - self.start
        left = self.total - self.finished
        eta = elapsed / self.finished * left
        self.report(f"{_text_bar(self.finished, self.total)} {self.finished}/{self.total} done, {self.failed} not ok, "
                    f"{left} left, ~{_fmt_time(eta)} to go | {what}")
        return record

    def summary(self) -> None:
        if self.bar is not None:
            self.bar.close()
        if self.report and self.total:
            self.report(f"matrix done in {_fmt_time(time.monotonic() - self.start)}: {self.finished - self.failed} ok, {self.failed} not ok")


def _text_bar(done: int, total: int, width: int = 20) -> str:
    filled = round(width * done / total) if total else width
    return "[" + "#" * filled + "." * (width - filled) + "]"


def _fmt_time(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
