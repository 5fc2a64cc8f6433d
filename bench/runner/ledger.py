"""The finished jobs of a long study, kept as they finish so that the same
command, run again, resumes where it stopped.

A :class:`Ledger` is a JSON-lines file beside the study's page
(``PAGE.partial.jsonl``). :func:`bench.runner.job.run_jobs` appends one line
per job that finished (its name, its fields, the code that ran it and its
result) and, when started again, takes a job's result from the ledger instead
of running it where all three match: the same name, the same fields and the
same code. The code is :func:`~bench.runner.provenance.code_state`'s digest
(the committed trees of bench/, methods/ and systems/ and their uncommitted
changes), so a job is never reported from code other than the page's. A
torn last line (the process killed while writing it) is skipped. The study
deletes its ledger once its page is written (:meth:`Ledger.close`).
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from pathlib import Path
from typing import Any

from bench.runner.provenance import code_state


def code_digest() -> str | None:
    """A digest of the code now (:func:`~bench.runner.provenance.code_state`); ``None`` outside a git checkout."""
    state = code_state()
    return None if state is None else hashlib.sha256(state.encode()).hexdigest()


class Ledger:
    """The finished jobs of one study's page, by name (module docstring)."""

    def __init__(self, page: str | os.PathLike):
        self.path = Path(page).with_suffix(".partial.jsonl")
        self.code = code_digest()
        self._lock = threading.Lock()

    def finished(self, jobs: dict[str, dict]) -> tuple[dict[str, Any], int]:
        """The results kept for ``jobs`` (``{name: the job's fields}``) that this code made with the same
        fields, and how many of ``jobs`` the ledger holds only from other code or other fields."""
        if not self.path.exists():
            return {}, 0
        kept, other = {}, set()
        for line in self.path.read_text(encoding="utf-8").splitlines():
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                continue
            name = entry.get("name")
            if name not in jobs:
                continue
            if self.code is not None and entry.get("code") == self.code and entry.get("fields") == jobs[name]:
                kept[name] = entry["result"]
            else:
                other.add(name)
        return kept, len(other - set(kept))

    def add(self, name: str, fields: dict, result: Any) -> None:
        """Keep a finished job's result, on disk before this returns."""
        if self.code is None:
            return
        line = json.dumps({"name": name, "fields": fields, "code": self.code, "result": result})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self._lock, open(self.path, "a", encoding="utf-8") as f:
            f.write(line + "\n")
            f.flush()
            os.fsync(f.fileno())

    def close(self) -> None:
        """The page is written: its ledger goes."""
        self.path.unlink(missing_ok=True)
