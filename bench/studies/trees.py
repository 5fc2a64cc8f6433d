"""An earlier commit's tree beside this one, for the studies that time the two in one run: the commit
exported with ``git archive`` into a folder, whose code a process runs with it first on ``PYTHONPATH``."""

from __future__ import annotations

import subprocess
from pathlib import Path

from bench.core.errors import UserError

ROOT = Path(__file__).resolve().parents[2]


def export(revision: str, into: Path) -> str:
    """``revision``'s tree exported into ``into``; returns its full commit id."""
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", f"{revision}^{{commit}}"],
                                capture_output=True, text=True, check=True).stdout.strip()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        raise UserError(f"--against {revision}: not a commit of {ROOT} ({getattr(e, 'stderr', e) or e})") from None
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return commit
