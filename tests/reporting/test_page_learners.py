"""A learner the pages do not name appears on them once its records are there: a toy method registered here,
with records of its own beside the published ones, gets its row on the measured page's learners table and its
column on the arms page, under its own title."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from bench.reporting import arms, measured
from bench.reporting.pages import learners
from methods import METHODS, Method

RESULTS = Path(__file__).resolve().parents[2] / "results"


@pytest.fixture
def toy():
    @METHODS.add("toy_ridge", "regression")
    class ToyRidge(Method):
        """A learner no page names."""

        title = "toy ridge"

    yield ToyRidge
    METHODS.remove("toy_ridge")


def _copy_as_toy(source: Path, target: Path, like: str) -> None:
    """``source``'s records into ``target``, and each of the method ``like``'s again as the toy's."""
    shutil.copytree(source, target)
    for path in sorted(source.glob(f"*__{like}__*.json")):
        record = json.loads(path.read_text())
        record["method"] = "toy_ridge"
        record["run_id"] = record["run_id"].replace(f"__{like}__", "__toy_ridge__")
        record["spec"]["method"] = "toy_ridge"
        (target / path.name.replace(f"__{like}__", "__toy_ridge__")).write_text(json.dumps(record))


def test_the_pages_list_a_registered_learner_that_they_do_not_name(toy, tmp_path):
    for folder, _ in measured.MATRICES:
        _copy_as_toy(RESULTS / folder / "records", tmp_path / folder / "records", "delan")
    page = measured.learners(tmp_path)
    published = measured.learners(RESULTS)
    row = next(line for line in page.splitlines() if line.startswith("| toy ridge |"))
    delan = next(line for line in published.splitlines() if line.startswith("| DeLaN |"))
    assert row.split("|")[2:] == delan.split("|")[2:]  # the toy's records are DeLaN's: the same figures
    assert "toy ridge" not in published
    _copy_as_toy(RESULTS / "arms" / "structure_60s" / "records", tmp_path / "arms" / "structure_60s" / "records", "mlp")
    header = arms.table(tmp_path, "arms/structure_60s", "panda").splitlines()[0]
    assert header.endswith("| toy ridge |") and "| MLP |" in header


def test_a_pages_own_labels_and_order_come_first_and_a_hybrid_is_named_by_its_parts(toy):
    rows = learners({"toy_ridge", "mlp", "standard+toy_ridge", "delan"}, (("mlp", "MLP (the page's words)"),))
    assert rows == [("mlp", "MLP (the page's words)"), ("delan", "DeLaN"), ("standard+toy_ridge", "standard model + toy ridge"),
                    ("toy_ridge", "toy ridge")]
