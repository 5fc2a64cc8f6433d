"""The suite's one record type: one immutable JSON file per run, of a method
(kind ``run``) or of the residual loop (kind ``residual``, :func:`residual_record`).

A :class:`Record` holds the run's configuration (system, method, experiment,
seed, budget, hyperparameters, data), its status (``ok``, ``failed``,
``timeout``, ``unavailable`` or ``not_applicable``) and error, the train and
test MSE in the experiment's own target (``L`` for direct, ``tau`` for
indirect), the best-so-far curve of training MSE over wall-clock time, the
number of steps, the learned expression where there is one, and provenance
(:mod:`bench.runner.provenance`). It also says:

* ``budget``: the budget's kind, seconds or steps of work
  (:meth:`bench.core.budget.Budget.to_json`);
* ``replay``: what ``python -m bench rerun`` needs to repeat the run: the
  work it did and its schedule (:class:`~bench.core.budget.Schedule`), or
  ``{"unavailable": why}``;
* ``code``: a hash of the code that ran (:func:`bench.runner.sources.code_hash`), by
  which a resumed matrix knows a run made by other code;
* ``failed_stages``: the stages after the fit that failed
  (``{"exact": "ValueError: ..."}``); the run keeps its fit's MSE and stays
  ``ok``.

On disk a record is the JSON object of :meth:`Record.to_json`, written
atomically to ``OUT/records/<run id>.json``; :meth:`Record.from_json`
checks a file's object field by field. A file that fails the check is moved
aside to ``OUT/records/corrupt/`` (:func:`quarantine`): the resume redoes its
run, and tables count it as missing until then (:meth:`Record.missing`).
Tables are a pure function of a folder of records.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import functools
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from bench.core.budget import Budget
from bench.core.experiment import EXPERIMENTS, Experiment
from bench.core.errors import UserError
from bench.core.fileio import write_json
from bench.core.names import MethodName, MethodNameError
from bench.runner.provenance import Provenanced, provenance
from bench.runner.spec import RunSpec, parse_run_id

SCHEMA = "syrenets-bench/record/1"
STATUSES = ("ok", "failed", "timeout", "unavailable", "not_applicable")
#: fields added to the schema after records were first published, with the
#: value a record written before them has
ADDED_LATER = {"exact": None, "noise": 0.0, "rollout": None, "budget": None, "replay": None, "code": None,
               "failed_stages": {}, "kind": "run"}
#: what made a record: a run of a method (``run``: the matrix, ``bench fit``) or the residual loop
#: (``residual``: ``bench residual``, whose own results are in :attr:`Record.details`, :func:`residual_record`)
KINDS = ("run", "residual")
#: the residual loop's results that are the record's own fields, by the loop's name for them
RESIDUAL_OWN = {"system": "system", "method": "method", "seed": "seed", "budget_s": "budget_s", "budget": "budget",
                "provenance": "provenance", "lagrangian": "expression", "seconds": "fit_seconds",
                "rollout": "rollout", "spec": "spec", "code": "code"}
#: the status of a run whose record file was corrupt (in memory only, never written)
MISSING = "missing"
#: where corrupt record files are moved, under ``OUT/records``
CORRUPT = "corrupt"


class RecordError(UserError, ValueError):
    """A record file that is not a valid record; the message names the file and the field."""


@dataclass(frozen=True)
class Record(Provenanced):
    """One run's record; fields in the order of the JSON file."""

    schema: str
    run_id: str
    system: str
    method: str
    experiment: str
    seed: int
    budget_s: float | None
    noise: float
    target: str
    spec: dict
    status: str
    error: str | None = None
    train_mse: float | None = None
    test_mse: float | None = None
    steps: int | None = None
    fit_seconds: float | None = None
    stop_reason: str | None = None
    curve: list = field(default_factory=list)
    expression: str | None = None
    exact: bool | None = None
    rollout: dict | None = None
    hyperparameters: dict | None = None
    details: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    budget: dict | None = None
    replay: dict | None = None
    code: dict | None = None
    failed_stages: dict = field(default_factory=dict)
    kind: str = "run"

    @classmethod
    def new(cls, run: RunSpec, status: str, *, elsewhere: bool = False, **fields) -> "Record":
        """A complete record of ``run``, stamped with this process's provenance
        or, with ``elsewhere``, with the threads the run has in its own process."""
        spec = run.to_dict()
        if status not in STATUSES:
            raise ValueError(f"unknown status {status!r}")
        noise = spec.get("noise", 0.0)
        fields.setdefault("budget", run.budget.to_json())
        return cls(
            schema=SCHEMA,
            run_id=run.run_id,
            system=spec["system"], method=spec["method"], experiment=spec["experiment"], seed=spec["seed"],
            budget_s=spec["budget_s"], noise=noise, target=Experiment.of(spec["experiment"]).target,
            spec=spec, status=status, provenance=provenance(spec.get("threads", 1) if elsewhere else None), **fields,
        )

    @functools.cached_property
    def name(self) -> MethodName:
        """The parts of the run's method's name (:class:`bench.core.names.MethodName`)."""
        return MethodName.parse(self.method)

    @property
    def tuned(self) -> bool:
        """Whether the run chose its hyperparameters on its training data (:mod:`bench.evaluation.tuning`)."""
        return bool(self.spec.get("tune"))

    @property
    def budget_kind(self) -> str:
        """``"seconds"`` or ``"steps"`` (a record written before budgets had kinds had seconds)."""
        return (self.budget or {}).get("kind", "seconds")

    @property
    def error_line(self) -> str | None:
        """The first line of :attr:`error`, ``None`` where there is none."""
        text = (self.error or "").strip()
        return text.splitlines()[0] if text else None

    def describe_budget(self) -> str:
        """The budget in words: ``60 s`` or ``5000 steps``."""
        work = self.work()
        return f"{self.budget_s:g} s" if work is None else work.describe()

    @classmethod
    def missing(cls, rid: str, why: str) -> "Record | None":
        """An in-memory stand-in for a run whose record is missing (status
        :data:`MISSING`), so that tables count it; ``None`` where ``rid`` is
        not a run id."""
        parts = parse_run_id(rid)
        if parts is None:
            return None
        tuned, profile = parts.pop("tuned"), parts.pop("profile")
        return cls(schema=SCHEMA, run_id=rid, target=Experiment.of(parts["experiment"]).target, budget_s=math.nan,
                   spec={**({"tune": True} if tuned else {}), **({"profile": profile} if profile != "default" else {})},
                   status=MISSING, error=why, **parts)

    def replace(self, **changes) -> "Record":
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, obj, source: str = "record") -> "Record":
        """The record in ``obj`` (a file's JSON object); :class:`RecordError`
        naming ``source`` and the first field that is wrong otherwise."""
        if not isinstance(obj, dict):
            raise RecordError(f"{source}: not a record (a JSON {type(obj).__name__}, not an object)")
        if "schema" not in obj and {"mse_before", "mse_after", "rounds"} <= set(obj):
            try:  # the residual loop's JSON, as written before it was a record
                obj = residual_record(obj).to_json()
            except (AttributeError, KeyError, TypeError, ValueError, UserError) as exc:
                raise RecordError(f"{source}: not a record of the residual loop ({type(exc).__name__}: {exc})"[:300]) from None
        names = [f.name for f in dataclasses.fields(cls)]
        obj = {**{k: v for k, v in ADDED_LATER.items() if k not in obj}, **obj}
        missing = [n for n in names if n not in obj]
        if missing:
            raise RecordError(f"{source}: not a record (missing field(s) {', '.join(missing)})")
        unknown = sorted(set(obj) - set(names))
        if unknown:
            raise RecordError(f"{source}: unknown record field(s) {', '.join(unknown)}")

        def bad(name: str, why: str):
            return RecordError(f"{source}: field {name} {why}, got {obj[name]!r}"[:300])

        if obj["schema"] != SCHEMA:
            raise bad("schema", f"must be {SCHEMA!r}")
        for name in ("run_id", "system", "method", "target"):
            if not isinstance(obj[name], str) or not obj[name]:
                raise bad(name, "must be a non-empty string")
        try:
            MethodName.parse(obj["method"])
        except MethodNameError as exc:
            raise bad("method", f"is not a method's name ({exc})") from None
        if obj["status"] not in STATUSES:
            raise bad("status", f"must be one of {', '.join(STATUSES)}")
        if obj["kind"] not in KINDS:
            raise bad("kind", f"must be one of {', '.join(KINDS)}")
        if obj["experiment"] not in EXPERIMENTS:
            raise bad("experiment", f"must be one of {', '.join(EXPERIMENTS)}")
        if not _is_int(obj["seed"]):
            raise bad("seed", "must be an integer")
        if not _is_number(obj["noise"]):
            raise bad("noise", "must be a number")
        if obj["budget_s"] is not None and not _is_number(obj["budget_s"]):
            raise bad("budget_s", "must be a number or null")
        for name, kind in (("spec", dict), ("details", dict), ("provenance", dict), ("curve", list),
                           ("failed_stages", dict)):
            if not isinstance(obj[name], kind):
                raise bad(name, f"must be a JSON {'object' if kind is dict else 'array'}")
        for name in ("budget", "replay", "code"):
            if obj[name] is not None and not isinstance(obj[name], dict):
                raise bad(name, "must be a JSON object or null")
        if obj["budget"] is not None:
            try:
                Budget.from_json(obj["budget"])
            except UserError as exc:
                raise bad("budget", f"is not a budget ({exc})") from None
        for name in ("train_mse", "test_mse", "fit_seconds"):
            if obj[name] is not None and not _is_number(obj[name]):
                raise bad(name, "must be a number or null")
        if obj["status"] == "ok" and not (_is_number(obj["train_mse"]) and math.isfinite(obj["train_mse"])):
            raise bad("train_mse", "of an ok run must be a finite number")
        return cls(**obj)


def residual_record(loop: dict) -> Record:
    """The record of a run of the residual loop, from the loop's results as JSON
    (:meth:`bench.residual.result.ResidualResult.to_json`'s fields): kind ``residual``; the
    spec, the system, the method, the seed, the budget, the provenance and the code are the
    record's own (a result without a spec gets one from its system, method, seed and budget);
    the Lagrangian is its ``expression``, the loop's seconds its ``fit_seconds``, the torque MSE
    after the loop its ``train_mse`` and ``test_mse``; the rest is in ``details``, by the loop's
    names (:func:`residual_fields` reads it back)."""
    loop = dict(loop)
    if "mse_heldout_recordings" in loop:  # the key's name in files published before
        loop["mse_heldout_trajectories"] = loop.pop("mse_heldout_recordings")
    budget = Budget.from_json(loop["budget"]) if loop.get("budget") else Budget(seconds=loop.get("budget_s"))
    spec = loop.get("spec") or RunSpec(
        system=loop.get("system") or "unknown", method=loop["method"], experiment="indirect", seed=loop.get("seed", 0),
        budget_s=budget.seconds, steps=budget.steps).to_dict()
    run = RunSpec.from_dict(spec)
    after = loop.get("mse_after") or {}
    own = {field: loop.get(name) for name, field in RESIDUAL_OWN.items() if name not in ("spec", "system")}
    own["provenance"] = own["provenance"] or {}
    return Record(schema=SCHEMA, run_id=run.run_id, system=loop.get("system") or run.system, experiment="indirect",
                  noise=run.noise, target="tau", spec=spec, status="ok", train_mse=after.get("train"),
                  test_mse=after.get("test"), kind="residual",
                  details={k: v for k, v in loop.items() if k not in RESIDUAL_OWN}, **own)


def residual_fields(record: Record, source: str | os.PathLike | None = None) -> dict:
    """The residual loop's results in ``record`` (kind ``residual``), by the loop's names: the inverse of
    :func:`residual_record`; a record of another kind is refused in one line naming ``source`` (the file it was
    read from), else its run id."""
    if record.kind != "residual":
        where = str(source) if source is not None else f"record {record.run_id}"
        raise RecordError(f"{where}: a record of a {record.kind}, not of the residual loop")
    return {**record.details, **{name: getattr(record, field) for name, field in RESIDUAL_OWN.items()}}


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def record_path(out_dir: str | os.PathLike, rid: str) -> Path:
    return Path(out_dir) / "records" / f"{rid}.json"


def write_record(path: str | os.PathLike, record: Record) -> None:
    write_json(path, record.to_json())


def read_record(path: str | os.PathLike) -> Record:
    """The record in the file ``path``; :class:`RecordError` naming the file otherwise."""
    path = Path(path)
    try:
        with open(path) as f:
            obj = json.load(f)
    except json.JSONDecodeError as exc:
        raise RecordError(f"{path}: not a JSON file ({exc.msg} at line {exc.lineno})") from None
    except UnicodeDecodeError:
        raise RecordError(f"{path}: not a text file") from None
    return Record.from_json(obj, str(path))


def records_folder(out_dir: str | os.PathLike) -> Path:
    """``out_dir/records``, or ``out_dir`` itself when it holds the records directly."""
    root = Path(out_dir)
    return root / "records" if (root / "records").is_dir() else root


def read_records(out_dir: str | os.PathLike, on_bad: Callable[[Path, RecordError], None] | None = None,
                 kind: str = "run") -> list[Record]:
    """The records of ``kind`` under ``out_dir/records`` (or ``out_dir`` itself), sorted by file name (a
    residual loop's record among a matrix's is not one of its runs).

    A file that is not a valid record raises :class:`RecordError`, or, with
    ``on_bad``, is passed to it with the error and left out.
    """
    records = []
    for path in sorted(records_folder(out_dir).glob("*.json")):
        try:
            record = read_record(path)
        except RecordError as exc:
            if on_bad is None:
                raise
            on_bad(path, exc)
        else:
            if record.kind == kind:
                records.append(record)
    return records


def quarantine(path: Path) -> Path:
    """Move a corrupt record file to ``records/corrupt/``, stamped with the
    time, so that its run is redone; returns where it went."""
    folder = path.parent / CORRUPT
    folder.mkdir(exist_ok=True)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%S%fZ")
    target = folder / f"{path.stem}.{stamp}.json"
    os.replace(path, target)
    return target


def missing_runs(out_dir: str | os.PathLike, records: list[Record]) -> list[Record]:
    """Stand-ins (:meth:`Record.missing`) for the runs whose record was moved
    to ``records/corrupt/`` and has not been redone."""
    have = {r.run_id for r in records}
    out = {}
    for path in sorted((records_folder(out_dir) / CORRUPT).glob("*.json")):
        rid = path.name.rsplit(".", 2)[0]  # <run id>.<time stamp>.json
        if rid not in have and rid not in out:
            stand_in = Record.missing(rid, f"its record was corrupt (moved to {path})")
            if stand_in is not None:
                out[rid] = stand_in
    return list(out.values())
