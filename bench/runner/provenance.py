"""How a result was obtained: the code's commit and dirty flag, package
versions, thread settings, the machine and the time. Every record and every
result file of the suite carries it."""

from __future__ import annotations

import datetime as _dt
import functools
import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

from bench.core.budget import Budget
from bench.core.devices import describe

#: the checkout the suite runs from
PROJECT_ROOT = Path(__file__).resolve().parents[2]
_PACKAGES = ("torch", "numpy", "scipy", "sympy", "pandas", "deap", "pysr")


@functools.lru_cache(maxsize=1)
def git_state() -> dict:
    """Commit and dirty flag of the project checkout (results/ excluded), read
    once per process: a process forked after the first call (from the
    runner's fork server) reports the state its code was imported in."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(PROJECT_ROOT), *args], capture_output=True, text=True, timeout=20, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)results"))
        return {"commit": commit, "dirty": dirty}
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown", "dirty": None}


#: the folders of the checkout that hold the suite's code
CODE_FOLDERS = ("bench", "methods", "systems")


def code_state() -> str | None:
    """The code of the checkout now (results/ and docs excluded): the
    committed trees of :data:`CODE_FOLDERS` and their uncommitted changes,
    as one text; ``None`` outside a git checkout. Unlike :func:`git_state`
    it is read afresh on each call, for a matrix to notice code that
    changed under it."""
    try:
        def git(*args: str) -> str:
            return subprocess.run(["git", "-C", str(PROJECT_ROOT), *args], capture_output=True, text=True,
                                  timeout=20, check=True).stdout

        trees = git("rev-parse", *(f"HEAD:{f}" for f in CODE_FOLDERS))
        return trees + git("diff", "HEAD", "--", *CODE_FOLDERS)
    except (OSError, subprocess.SubprocessError):
        return None


@functools.lru_cache(maxsize=1)
def _cpuinfo() -> str | None:
    """The text of ``/proc/cpuinfo``, read once; ``None`` where it cannot be read."""
    try:
        return Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return None


def _fields(text: str) -> dict[str, str]:
    """The ``key : value`` lines of ``/proc/cpuinfo`` text, the first value of each key."""
    fields: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())
    return fields


@functools.lru_cache(maxsize=1)
def cpu_model() -> str:
    fields = _fields(_cpuinfo() or "")
    if "model name" in fields:
        return fields["model name"]
    return platform.processor() or platform.machine()


@functools.lru_cache(maxsize=1)
def cpu_id() -> str:
    """What tells two processors of one model name apart, from ``/proc/cpuinfo``:
    family, model and stepping and the widest vector instructions, e.g.
    ``family 25 model 1 stepping 1, AVX2``. A virtual machine often shows
    only a generic name ("AMD EPYC") for processors whose speeds differ
    twofold; timings are comparable only where this matches. (The clock is
    left out: on a bare machine it changes from one reading to the next.)
    Empty where ``/proc/cpuinfo`` cannot be read."""
    text = _cpuinfo()
    return "" if text is None else describe_cpu(text)


def describe_cpu(text: str) -> str:
    """:func:`cpu_id` of the text of a ``/proc/cpuinfo`` (its first processor)."""
    fields = _fields(text.split("\n\n", 1)[0])
    flags = set((fields.get("flags") or fields.get("Features", "")).split())  # Features: ARM's
    vector = next((name for flag, name in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"), ("sse2", "SSE2"),
                                           ("asimd", "ASIMD")) if flag in flags), None)
    names = {"family": "cpu family", "model": "model", "stepping": "stepping"}
    parts = [" ".join(f"{name} {fields[key]}" for name, key in names.items() if key in fields), vector]
    return ", ".join(p for p in parts if p)


def machine(prov: dict) -> str:
    """The processor of a provenance in words, with its :func:`cpu_id` where the
    provenance has one (older records do not): ``AMD EPYC (family 25 model 1
    stepping 1, AVX2; 2 cores)``."""
    detail = "; ".join(str(x) for x in (prov.get("cpu_id"), f"{prov.get('cpu_count')} cores") if x)
    return f"{prov.get('cpu')} ({detail})"


def package_versions() -> dict:
    """The versions of Python and of the packages a record names, read once per process (reading an installed
    package's metadata scans the environment: tens of milliseconds a package, in every run)."""
    return dict(_package_versions())


@functools.lru_cache(maxsize=1)
def _package_versions() -> dict:
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def device_entry(device: str) -> dict:
    """What a record says of the device its fit trained on: :func:`bench.core.devices.describe`,
    with the processor's model where it is the CPU."""
    entry = describe(device)
    return {**entry, "name": cpu_model()} if entry["type"] == "cpu" else entry


def provenance(threads: int | None = None) -> dict:
    """This process's provenance, now.

    ``threads`` is given for a record this process makes of a run that ran
    (or would have run) elsewhere with that many threads pinned: the record
    then states the run's threads, not this process's.
    """
    if threads is not None:
        pinned = {k: str(threads) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
        return {**provenance(), "threads": {**pinned, "torch_intra_op": threads, "torch_inter_op": 1}}
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    if "torch" in sys.modules:
        import torch

        threads["torch_intra_op"] = torch.get_num_threads()
        threads["torch_inter_op"] = torch.get_num_interop_threads()
    return {
        **git_state(),
        "packages": package_versions(),
        "threads": threads,
        "cpu": cpu_model(),
        "cpu_id": cpu_id(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "hostname": platform.node(),
        "utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }




def made_at(prov: dict, digits: int = 7) -> str:
    """Where a provenance's code was, in words: ``commit 1a2b3c4`` and, for a
    tree with uncommitted changes, ``, dirty tree``."""
    return f"commit {str(prov.get('commit', '?'))[:digits]}{', dirty tree' if prov.get('dirty') else ''}"


class Provenanced:
    """What the suite's two result types share, :class:`bench.runner.records.Record`
    (a run of the matrix) and :class:`bench.residual.result.ResidualResult` (a
    run of the loop): a ``provenance`` (:func:`provenance`) and a ``budget``
    (:meth:`bench.core.budget.Budget.to_json`), read through these methods."""

    provenance: dict
    budget: dict | None

    @property
    def made_at(self) -> str:
        """:func:`made_at` of the result's provenance."""
        return made_at(self.provenance)

    def work(self) -> Budget | None:
        """The budget the result was made under (``None``: a record from before budgets were recorded)."""
        return None if self.budget is None else Budget.from_json(self.budget)
