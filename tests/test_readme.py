"""The README's examples as a newcomer meets them: its quick start's commands
(``make bench`` as the Makefile runs it, ``bench list``, the one-minute run)
read from the README and the Makefile and run at a smoke budget, and its two
code blocks under "Adding a method" and "Adding a system" saved as files of
one's own, listed and run in a matrix with ``--plugin``, exactly as the
README's commands do (every link in the README and docs/ resolves:
tests/reporting/test_index.py)."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def _python_block(section: str) -> str:
    body = README.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"```python\n(.*?)```", body, flags=re.S)
    return block


#: the README's sections whose shell blocks are its quick start
QUICK_START = ("Set-up: two commands", "A one-minute run, and reading its tables")


def _bench(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.long
def test_the_readmes_method_and_system_run_as_plugins_in_a_matrix(tmp_path):
    (tmp_path / "my_method.py").write_text(_python_block("Adding a method"))
    (tmp_path / "my_system.py").write_text(_python_block("Adding a system"))
    listed = _bench("list", "--plugin", "my_method.py", "--plugin", "my_system.py", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert "toy_quadratic" in listed.stdout and "toy_mass_spring" in listed.stdout
    run = _bench("run", "--plugin", "my_method.py", "--plugin", "my_system.py", "--methods", "toy_quadratic",
                 "--systems", "toy_mass_spring", "--steps", "1", "--n-seeds", "1", "--workers", "1",
                 "--set", "toy_quadratic.ridge=0", "--out", "out", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    records = [json.loads(p.read_text()) for p in sorted((tmp_path / "out" / "records").glob("*.json"))]
    assert len(records) == 2 and all(r["status"] == "ok" for r in records)
    assert all(r["test_mse"] < 1e-20 for r in records)  # L = m qd^2/2 - k q^2/2 lies in the toy's basis
    assert "## toy_mass_spring, indirect experiment" in (tmp_path / "out" / "tables.md").read_text()



def _shell_commands(section: str) -> list[list[str]]:
    """The commands of the section's ``sh`` blocks, each as its words (comments and line continuations gone)."""
    body = README.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    text = "\n".join(re.findall(r"```sh\n(.*?)```", body, flags=re.S)).replace("\\\n", " ")
    return [shlex.split(line, comments=True) for line in text.splitlines() if shlex.split(line, comments=True)]


def _make_recipe(target: str) -> list[list[str]]:
    """The commands of the Makefile's ``target``, its ``$(BIN)/python`` as this interpreter."""
    makefile = (ROOT / "Makefile").read_text()
    body = re.search(rf"^{target}:.*\n((?:\t.*\n)+)", makefile, flags=re.M).group(1)
    return [shlex.split(line.strip().replace("$(BIN)/python", "python")) for line in body.splitlines()]


#: the generated samples of each run of a quick start's matrix at the smoke budget
SMOKE_SAMPLES = ("--n-train", "2000", "--n-test", "500")


def _at_smoke_budget(words: list[str]) -> list[str]:
    """A bench command bounded by one step of work and one seed instead of its seconds, steps and seeds, on
    :data:`SMOKE_SAMPLES` generated samples, and without the simulated rollouts after each fit (what is run is
    the command's matrix, not its scores)."""
    out, words = [], list(words)
    while words:
        word = words.pop(0)
        if word in ("--budget", "--steps", "--n-seeds", "--seeds", "--n-train", "--n-test"):
            words.pop(0)
            continue
        out.append(word)
    return out + ["--steps", "1", "--n-seeds", "1", "--no-rollout", *SMOKE_SAMPLES] if "run" in out else out


def _quick_start() -> list[list[str]]:
    """Every ``python -m bench`` command of the README's quick start, ``make bench`` as the Makefile runs it,
    in the README's order; ``make test`` (this suite) and activating the environment are left out."""
    commands = []
    for section in QUICK_START:
        for words in _shell_commands(section):
            if words[:2] == ["make", "bench"]:
                commands += _make_recipe("bench")
            elif words[:3] == ["python", "-m", "bench"]:
                commands.append(words)
            else:
                assert words[:2] == ["make", "test"] or words[0] == "source", f"a quick start command not run: {words}"
    return commands


@pytest.mark.long
# with the tests that compile DeLaN's loss (tests/methods/test_delan.py): the matrix's DeLaN run compiles the same
# graph, so that whichever runs first compiles it and the other finds it in torch's cache on disk
@pytest.mark.xdist_group("torch.compile")
def test_the_quick_starts_commands_run_every_method_that_applies(tmp_path):
    commands = _quick_start()
    assert any("run" in c for c in commands) and any("list" in c for c in commands)
    for words in commands:
        smoke = _at_smoke_budget(words)
        done = _bench(*smoke[3:], cwd=tmp_path)
        assert done.returncode == 0, f"{shlex.join(smoke)}: exit {done.returncode}: {done.stderr[-2000:]}"
        if smoke[3] != "run":
            continue
        out = tmp_path / smoke[smoke.index("--out") + 1]
        named = smoke[smoke.index("--methods") + 1].split(",") if "--methods" in smoke else None
        _check_matrix(out, named, done.stdout)


def _registered_methods() -> list[str]:
    """The methods a fresh command line registers (this test process may hold other tests' plugins)."""
    names = subprocess.run([sys.executable, "-c", "from bench.cli import main; from methods import METHODS; "
                            "print(*METHODS.names())"], cwd=ROOT, capture_output=True, text=True, check=True)
    return names.stdout.split()


def _check_matrix(out: Path, named: list[str] | None, stdout: str) -> None:
    """Every method (those named, else every registered one) has a record for each experiment; each runs where
    it applies, and each that does not is named with its reason once on stdout and in the tables."""
    records = [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    methods = named or _registered_methods()
    by_method = {m: [r for r in records if r["method"] == m] for m in methods}
    tables = (out / "tables.md").read_text()
    for method, runs in by_method.items():
        assert runs, f"{method}: no record in {out}"
        assert {r["status"] for r in runs} <= {"ok", "unavailable", "not_applicable"}, (method, runs[0]["error"])
        for r in runs:
            if r["status"] != "ok":
                assert f"- **{method}** is {r['status'].replace('_', ' ')}: {r['error']}" in tables
    assert all(r["status"] == "ok" for m in ("sparse", "mlp", "sysid", "delan") if m in by_method for r in by_method[m])
    if named is None:  # a method that applies to none of the systems is a line, not a refusal
        refused = [m for m in methods if any(r["status"] == "not_applicable" for r in by_method[m])
                   and all(r["status"] != "ok" for r in by_method[m])]
        assert "loop" in refused  # SysId on an arm's linear form: the double pendulum has none
        for method in refused:
            assert re.search(rf"^not applicable, recorded as such: {method}: ", stdout, flags=re.M), stdout[:2000]
