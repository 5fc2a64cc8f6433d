"""The README's examples as a newcomer meets them: its two code blocks under
"Adding a method" and "Adding a system" saved as files of one's own, listed and
run in a matrix with ``--plugin``, exactly as the README's commands do
(every link in the README and docs/ resolves: tests/reporting/test_index.py)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def _python_block(section: str) -> str:
    body = README.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"```python\n(.*?)```", body, flags=re.S)
    return block


def _bench(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


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

