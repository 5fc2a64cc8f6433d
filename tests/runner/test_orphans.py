"""No process outlives the command that started it: after ``kill -9`` of a
matrix whose method hangs, its fork server, its run and the resource tracker
end within :data:`GONE_S` (the run hangs: without them ending with it, it would outlive the matrix);
after Ctrl-C, the run is killed and left unrecorded, so that
the resume runs it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = str(ROOT / "tests" / "plugins" / "faulty.py")
#: seconds the killed tree may take to end: the kernel kills it at once, but its three processes took 1.3 to
#: 2.7 s to be gone with both cores busy and the test niced, and more than 5 s in a fresh clone's suite run
#: beside two busy processes
GONE_S = 30


def start_hanging_matrix(out: Path) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench", "run", "--methods", "toy_sleeper", "--plugin", PLUGIN, "--seeds", "0",
         "--budget", "100", "--experiments", "indirect", "--n-train", "64", "--n-test", "32", "--no-rollout",
         "--workers", "1", "--out", str(out)],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONFAULTHANDLER": "1"},  # SIGABRT then prints every thread's stack
        # Python turns SIGINT into KeyboardInterrupt only if SIGINT is not ignored when it starts, and
        # a child inherits its parent's dispositions: the matrix gets the terminal's default, whatever
        # this test process was started with
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # until the run is in its (endless) fit
        if any("fit" in p.read_text() for p in (out / "logs").glob("*.phase")):
            return proc
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.1)
    raise AssertionError("the run did not start its fit")


def descendants(pid: int) -> list[int]:
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], list(children.get(pid, []))
    while todo:
        p = todo.pop()
        out.append(p)
        todo += children.get(p, [])
    return out


def running(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_kill_9_of_the_matrix_leaves_no_process_behind(tmp_path):
    proc = start_hanging_matrix(tmp_path / "out")
    tree = descendants(proc.pid)
    assert len(tree) >= 2  # the fork server and the run at least
    t0 = time.monotonic()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    while any(running(p) for p in tree) and time.monotonic() - t0 < GONE_S:
        time.sleep(0.05)
    assert [p for p in tree if running(p)] == [], "processes outlived the matrix"


def test_ctrl_c_kills_the_runs_and_records_none_of_them(tmp_path):
    out = tmp_path / "out"
    proc = start_hanging_matrix(out)
    tree = descendants(proc.pid)
    proc.send_signal(signal.SIGINT)
    try:
        code = proc.wait(timeout=20)
    except subprocess.TimeoutExpired:  # say where it hangs: the stacks of all its threads
        proc.send_signal(signal.SIGABRT)
        raise AssertionError(f"still running 20 s after Ctrl-C (SIGINT here: {signal.getsignal(signal.SIGINT)}); "
                             f"its stacks:\n{proc.communicate(timeout=20)[1]}") from None
    assert code == 130
    assert "interrupted" in proc.stderr.read()
    assert not list((out / "records").glob("*.json"))  # the resume will run it
    t0 = time.monotonic()
    while any(running(p) for p in tree) and time.monotonic() - t0 < GONE_S:
        time.sleep(0.05)
    assert [p for p in tree if running(p)] == []
