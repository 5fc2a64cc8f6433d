"""The finished jobs of a long study, kept as they finish so that the same
command, run again, resumes where it stopped; and the one rule by which a
stored result stands for a job, a study's or a matrix's (:func:`rerun_reason`).

A :class:`Ledger` is a JSON-lines file beside the study's page
(``PAGE.partial.jsonl``). :func:`bench.runner.schedule.run_jobs` appends one line
per job that finished (its name, what it is, the code that ran it and its
result) and, when started again, takes a job's result from the ledger instead
of running it where it stands for the job by the one resume rule
(:func:`rerun_reason`): the same name, the same job
(:meth:`~bench.runner.job.Job.identity`) and the same code
(:meth:`~bench.runner.job.Job.code`: for a study's case, :func:`code_digest`
of :func:`~bench.runner.provenance.code_state`, the committed trees of bench/,
methods/ and systems/ and their uncommitted changes), so a job is never
reported from code other than the page's. A
torn last line (the process killed while writing it) is skipped. The study
deletes its ledger once its page is written (:meth:`Ledger.close`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import threading
from pathlib import Path
from typing import Any, Mapping

from bench.runner.provenance import code_state


def code_digest() -> str | None:
    """A digest of the code now (:func:`~bench.runner.provenance.code_state`); ``None`` outside a git checkout."""
    state = code_state()
    return None if state is None else hashlib.sha256(state.encode()).hexdigest()


@functools.cache
def suite_code() -> str | None:
    """:func:`code_digest` of the code this process started with: a study's case's code
    (:meth:`bench.runner.job.Job.code`)."""
    return code_digest()


def rerun_reason(job, code: str | None, identity: dict | None) -> str | None:
    """The one resume rule, for a matrix's records and a study's ledger alike: why a result stored for
    ``job`` (a :class:`bench.runner.job.Job`), made by ``code`` for ``identity``, does not stand for it now:
    ``"made by other code"`` (its :meth:`~bench.runner.job.Job.code` differs; a result, or a job, whose code
    is not known is not judged by it), ``"made with another configuration"`` (its
    :meth:`~bench.runner.job.Job.identity` differs); ``None``: it stands."""
    now = job.code()
    if code is not None and now is not None and code != now:
        return "made by other code"
    if identity is not None and identity != job.identity():
        return "made with another configuration"
    return None


class Ledger:
    """The finished jobs of one study's page, by name (module docstring)."""

    def __init__(self, page: str | os.PathLike):
        self.path = Path(page).with_suffix(".partial.jsonl")
        self._lock = threading.Lock()

    def finished(self, jobs: Mapping[str, Any]) -> tuple[dict[str, Any], int]:
        """The results kept for ``jobs`` (``{name: job}``) that stand for them (:func:`rerun_reason`), and how
        many of ``jobs`` the ledger holds only from other code or for another configuration."""
        if not self.path.exists():
            return {}, 0
        kept, other = {}, set()
        for line in self.path.read_text(encoding="utf-8").splitlines():
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                continue
            if not isinstance(entry, dict) or entry.get("name") not in jobs:
                continue
            name = entry["name"]
            if entry.get("code") is not None and rerun_reason(jobs[name], entry["code"], entry.get("fields")) is None:
                kept[name] = entry["result"]
            else:
                other.add(name)
        return kept, len(other - set(kept))

    def add(self, name: str, job, result: Any) -> None:
        """Keep a finished job's result, with its code and identity, on disk before this returns; nothing
        where its code is not known (outside a git checkout)."""
        code = job.code()
        if code is None:
            return
        line = json.dumps({"name": name, "fields": job.identity(), "code": code, "result": result})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self._lock, open(self.path, "a", encoding="utf-8") as f:
            f.write(line + "\n")
            f.flush()
            os.fsync(f.fileno())

    def close(self) -> None:
        """The page is written: its ledger goes."""
        self.path.unlink(missing_ok=True)
