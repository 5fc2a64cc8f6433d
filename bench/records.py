"""The suite's one record format: one immutable JSON file per run.

A record holds the run's configuration (system, method, experiment, seed,
budget, hyperparameters, data), its status (``ok``, ``failed``, ``timeout``,
``unavailable`` or ``not_applicable``) and error, the train and test MSE in
the experiment's own target (``L`` for direct, ``tau`` for indirect), the
best-so-far curve of training MSE over wall-clock time, the number of steps,
the learned expression where there is one, and provenance: git commit and
dirty flag, package versions, thread settings, CPU, and UTC time.

Tables are a pure function of a folder of records.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

from bench.fileio import write_json

SCHEMA = "syrenets-bench/record/1"
STATUSES = ("ok", "failed", "timeout", "unavailable", "not_applicable")
PROJECT_ROOT = Path(__file__).resolve().parent.parent
_PACKAGES = ("torch", "numpy", "scipy", "sympy", "pandas", "deap", "pysr")


def run_id(system: str, method: str, experiment: str, seed: int, noise: float = 0.0) -> str:
    """``system__method__experiment__seedN``, with ``__noiseX`` when the targets are noisy."""
    return f"{system}__{method}__{experiment}__seed{seed}" + (f"__noise{noise:g}" if noise else "")


def record_path(out_dir: str | os.PathLike, rid: str) -> Path:
    return Path(out_dir) / "records" / f"{rid}.json"


@functools.lru_cache(maxsize=1)
def git_state() -> dict:
    """Commit and dirty flag of the project checkout (results/ excluded), read
    once per process: a process forked after the first call (from the
    harness's fork server) reports the state its code was imported in."""

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


@functools.lru_cache(maxsize=1)
def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def package_versions() -> dict:
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def provenance() -> dict:
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
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "hostname": platform.node(),
        "utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


def new_record(spec: dict, status: str, **fields) -> dict:
    """A complete record for ``spec`` (a :class:`bench.harness.RunSpec` as a dict)."""
    if status not in STATUSES:
        raise ValueError(f"unknown status {status!r}")
    record = {
        "schema": SCHEMA,
        "run_id": run_id(spec["system"], spec["method"], spec["experiment"], spec["seed"], spec.get("noise", 0.0)),
        "system": spec["system"],
        "method": spec["method"],
        "experiment": spec["experiment"],
        "seed": spec["seed"],
        "budget_s": spec["budget_s"],
        "noise": spec.get("noise", 0.0),
        "target": "L" if spec["experiment"] == "direct" else "tau",
        "spec": spec,
        "status": status,
        "error": None,
        "train_mse": None,
        "test_mse": None,
        "steps": None,
        "fit_seconds": None,
        "stop_reason": None,
        "curve": [],
        "expression": None,
        "exact": None,
        "rollout": None,
        "hyperparameters": None,
        "details": {},
        "provenance": provenance(),
    }
    unknown = set(fields) - set(record)
    if unknown:
        raise KeyError(f"unknown record fields: {sorted(unknown)}")
    record.update(fields)
    return record


def write_record(path: str | os.PathLike, record: dict) -> None:
    write_json(path, record)


def read_records(out_dir: str | os.PathLike) -> list[dict]:
    """All records under ``out_dir/records`` (or ``out_dir`` itself), sorted by run id."""
    root = Path(out_dir)
    folder = root / "records" if (root / "records").is_dir() else root
    records = []
    for path in sorted(folder.glob("*.json")):
        with open(path) as f:
            rec = json.load(f)
        if rec.get("schema") == SCHEMA:
            records.append(rec)
    return records
