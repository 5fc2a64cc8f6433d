"""Atomic writes leave nothing behind, even after a killed writer; output
paths are checked before any work starts."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from bench.core.errors import UserError
from bench.core.fileio import atomic_write, check_output


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_killed_writers_temporary_file_is_removed_by_the_next_write(tmp_path):
    target = tmp_path / "plot.png"
    leftover = tmp_path / f".plot.png.{dead_pid()}.abc123.tmp"  # what a writer killed mid-write leaves
    leftover.write_bytes(b"half a png")
    live = tmp_path / f".plot.png.{os.getpid()}.def456.tmp"  # a writer still at work keeps its file
    live.write_bytes(b"in progress")
    other = tmp_path / f".table.md.{dead_pid()}.x.tmp"  # another file's leftover waits for that file's write
    other.write_text("x")
    atomic_write(target, lambda f: f.write(b"png"), binary=True)
    assert target.read_bytes() == b"png"
    assert not leftover.exists() and live.exists() and other.exists()


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "t.md"
    target.write_text("old")

    def broken(f):
        f.write("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(target, broken)
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["t.md"]


def test_output_paths_are_checked_before_work(tmp_path):
    a_file = tmp_path / "f.txt"
    a_file.write_text("x")
    assert check_output(tmp_path / "new" / "deeper" / "out.json") == tmp_path / "new" / "deeper" / "out.json"
    with pytest.raises(UserError, match="f.txt is a file, not a folder"):
        check_output(a_file / "run.json")
    with pytest.raises(UserError, match="is a folder, not a file"):
        check_output(tmp_path)
    with pytest.raises(UserError, match="is a file, not a folder"):
        check_output(a_file, folder=True)
    assert check_output(tmp_path / "out", folder=True) == tmp_path / "out"
