"""results/index.md and the figures pages show: every published file is in
the manifest, the index is what the manifest and the records give, and no
page's marked figure disagrees with its records."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from bench.core.errors import UserError
from bench.reporting.index import INDEX, build_index, figures, read_manifest, stale_figures, unlisted, write_index
from bench.reporting.pages import stale_blocks
from bench.reporting.tables import label
from bench.runner.records import read_records
from tests.commandline import cli

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "results"
STUDY = "syrenets/studies/syrenets_300s_compiled_best"


def published() -> list[Path] | None:
    """The files under results/ that the repository holds (what a user's own runs
    beside them do not change); ``None`` outside a git checkout: every file there."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "results"], cwd=ROOT, capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return [ROOT / name for name in out.stdout.decode().split("\0") if name]


def test_every_published_file_is_in_the_manifest():
    assert unlisted(RESULTS, files=published()) == []


def test_the_readmes_own_runs_write_where_git_ignores_them():
    # the quick start's folders must not turn up among the published results, nor in git status
    text = (ROOT / "README.md").read_text() + (ROOT / "docs" / "cli.md").read_text()
    outs = set(re.findall(r"--out (runs/\w+)", text))
    assert {"runs/first", "runs/mine", "runs/my_run", "runs/by_work"} <= outs
    assert "--out results/" not in re.sub(r"--out results/(quick|measured|residual|harness|paper|syrenets|arms|scaling|leaderboard)", "", text)
    ignored = subprocess.run(["git", "check-ignore", "-q", "runs/first/tables.md"], cwd=ROOT)
    assert ignored.returncode == 0


def test_the_index_is_what_the_manifest_and_the_records_give():
    assert (RESULTS / INDEX).read_text() == build_index(RESULTS) + "\n"


def test_no_page_shows_a_figure_its_records_do_not_give():
    assert stale_figures(RESULTS) == []
    assert len(re.findall(r"<!-- figure ", (ROOT / "README.md").read_text())) >= 3


def test_a_number_changed_on_a_published_page_is_found(tmp_path):
    page = tmp_path / "README.md"
    text = (RESULTS / "measured" / "README.md").read_text()
    assert stale_blocks(RESULTS, [RESULTS / "measured" / "README.md"]) == []
    # one figure of a generated table: the MLP's driven row on the default split
    row = next(line for line in text.splitlines() if line.startswith("| MLP |"))
    shown = re.search(r"\((\d+)/(\d+) windows\)", row)
    assert shown, row
    changed = f"({int(shown[1]) - 1}/{shown[2]} windows)"
    page.write_text(text.replace(row, row.replace(shown[0], changed, 1)))
    (stale,) = stale_blocks(RESULTS, [page])
    assert "block measured.kuka.learners differs" in stale
    # one marked figure in its prose
    mark = re.search(r"<!-- figure measured.kuka.delan.train -->(.*?)<!-- /figure -->", text)
    assert mark and mark[1] == figures(RESULTS)["measured.kuka.delan.train"]


def test_every_link_in_the_readme_the_docs_and_the_results_resolves():
    link = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    pages += [p for p in RESULTS.rglob("*.md") if "records" not in p.parts]
    broken = [f"{p.relative_to(ROOT)}: {t}" for p in pages for t in link.findall(p.read_text())
              if "://" not in t and not (p.parent / t).exists()]
    assert broken == []


def _small_results(tmp_path: Path, figure_text: str) -> Path:
    root = tmp_path / "results"
    shutil.copytree(RESULTS / STUDY, root / "study", ignore=shutil.ignore_patterns("*.png"))
    (root / "manifest.toml").write_text(
        '[[result]]\npath = "study"\ngroup = "syrenets"\ntitle = "a study"\nstatus = "current"\ncommand = "make it"\n'
        '[[result.figure]]\nname = "study.indirect"\nlabel = "All 10"\n'
        'records = { system = "double_pendulum", experiment = "indirect", method = "syrenets" }\n')
    (tmp_path / "README.md").write_text(f"SyReNets reaches <!-- figure study.indirect -->{figure_text}<!-- /figure -->.\n")
    return root


def test_a_figure_typed_by_hand_is_found_and_rewritten_from_the_records(tmp_path):
    root = _small_results(tmp_path, "0.001")
    (stale,) = stale_figures(root)
    assert "study.indirect shows 0.001, the records give 0.0081" in stale
    r = cli("index", root)
    assert r.returncode == 0, r.stderr
    assert "<!-- figure study.indirect -->0.0081<!-- /figure -->" in (tmp_path / "README.md").read_text()
    assert stale_figures(root) == []
    assert "| [study](study): a study | current | All 10 0.0081 | `make it` | 50baa511b5 |" in (root / INDEX).read_text()


def test_a_number_named_by_its_records_is_checked_and_rewritten_in_its_own_style(tmp_path):
    root = _small_results(tmp_path, "0.0081")
    name = "records/study/double_pendulum/indirect/syrenets"
    (tmp_path / "README.md").write_text(
        f"All 10 <!-- figure {name}/all -->0.00806<!-- /figure -->, typed by hand as "
        f"<!-- figure {name}/all -->8.0e-3<!-- /figure -->; no such method <!-- figure records/study/double_pendulum/"
        f"indirect/mlp/all -->1.0<!-- /figure -->.\n")
    stale = stale_figures(root)
    assert len(stale) == 2 and "all shows 8.0e-3, the records give 8.1e-3" in stale[0] and "no such figure" in stale[1]
    assert cli("index", root).returncode == 0
    text = (tmp_path / "README.md").read_text()
    assert f"{name}/all -->0.00806<" in text and f"{name}/all -->8.1e-3<" in text and "mlp/all -->1.0<" in text
    tests = sorted(r.test_mse for r in read_records(root / "study") if r.status == "ok" and r.experiment == "indirect"
                   and r.method == "syrenets")
    (tmp_path / "README.md").write_text(f"<!-- figure {name}/median -->1.00e0<!-- /figure --> <!-- figure {name}/worst -->"
                                        f"1.00e0<!-- /figure -->")
    stale = stale_figures(root)
    median, worst = (f"{v:.2e}".replace("e-0", "e-") for v in (float(np.median(tests)), tests[-1]))
    assert len(stale) == 2 and f"the records give {median}" in stale[0] and f"the records give {worst}" in stale[1]
    assert cli("index", root).returncode == 0 and stale_figures(root) == []


def test_a_number_named_by_a_json_key_or_by_its_exact_seeds_is_checked_and_rewritten(tmp_path):
    root = _small_results(tmp_path, "0.0081")
    (root / "study" / "loop.json").write_text('{"mse_after": {"test": 0.33561}, "per_joint": [0.5, 0.0123]}')
    exact = sum(bool(r.exact) for r in read_records(root / "study") if r.status == "ok"
                and (r.experiment, r.method) == ("indirect", "syrenets"))
    (tmp_path / "README.md").write_text(
        "<!-- figure json/study/loop.json/mse_after.test -->0.34<!-- /figure --> "
        "<!-- figure json/study/loop.json/per_joint.1/percent -->1.2<!-- /figure --> % "
        "<!-- figure json/study/loop.json/mse_before.test -->1.0<!-- /figure --> "
        f"<!-- figure records/study/double_pendulum/indirect/syrenets/exact -->{exact + 1}<!-- /figure -->/10\n")
    stale = stale_figures(root)
    assert len(stale) == 2, stale
    assert "mse_before.test shows 1.0, the records give no such figure" in stale[0]
    assert f"exact shows {exact + 1}, the records give {exact}" in stale[1]
    assert cli("index", root).returncode == 0
    text = (tmp_path / "README.md").read_text()
    assert "test -->0.34<" in text and "percent -->1.2<" in text and f"exact -->{exact}<" in text
    (tmp_path / "README.md").write_text("<!-- figure json/study/loop.json/per_joint.1/percent -->1.5<!-- /figure -->\n")
    (stale,) = stale_figures(root)
    assert "shows 1.5, the records give 1.2" in stale


def test_a_figure_over_another_is_computed_from_both(tmp_path):
    root = _small_results(tmp_path, "0.0081")
    manifest = root / "manifest.toml"
    manifest.write_text(manifest.read_text() + (
        '[[result.figure]]\nname = "study.train"\nlabel = "train"\nformat = ".6g"\n'
        'records = { system = "double_pendulum", experiment = "indirect", method = "syrenets", split = "train" }\n'
        '[[result.figure]]\nname = "study.test"\nlabel = "test"\nformat = ".6g"\n'
        'records = { system = "double_pendulum", experiment = "indirect", method = "syrenets" }\n'
        '[[result.figure]]\nname = "study.generalises"\nlabel = "test over train"\nformat = ".6g"\n'
        'records = { system = "double_pendulum", experiment = "indirect", method = "syrenets" }\nover = "study.train"\n'
        '[[result.figure]]\nname = "study.itself"\nlabel = "over its own"\nformat = ".3f"\n'
        'records = { system = "double_pendulum", experiment = "indirect", method = "syrenets" }\nover = "study.test"\n'))
    values = figures(root)
    ratio = float(values["study.test"]) / float(values["study.train"])
    assert values["study.test"] != values["study.train"] and abs(float(values["study.generalises"]) / ratio - 1) < 1e-5
    assert values["study.itself"] == "1.000"
    manifest.write_text(manifest.read_text().replace('over = "study.train"', 'over = "study.nothing"'))
    with pytest.raises(UserError, match="over 'study.nothing', which no figure is named"):
        read_manifest(root)


def test_a_file_in_no_result_stops_the_index_in_one_line(tmp_path):
    root = _small_results(tmp_path, "0.0081")
    (root / "stray.md").write_text("# a result nobody listed\n")
    r = cli("index", root)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "stray.md is in no result" in r.stderr
    assert not (root / INDEX).exists()


@pytest.mark.parametrize("edit, message", [
    (lambda s: s.replace('status = "current"', 'status = "old"'), "'status' must be one of current, superseded"),
    (lambda s: s.replace('status = "current"', 'status = "superseded"'), "names what supersedes it"),
    (lambda s: s.replace('title = "a study"\n', ''), "'title' must be a string"),
    (lambda s: s.replace('records = {', 'json = { file = "x", key = "y" }\nrecords = {'), "from 'records' or from 'json'"),
    (lambda s: s + "[[result\n", "manifest.toml"),
])
def test_a_bad_manifest_is_one_line_naming_the_field(tmp_path, edit, message):
    root = _small_results(tmp_path, "0.0081")
    manifest = root / "manifest.toml"
    manifest.write_text(edit(manifest.read_text()))
    with pytest.raises(UserError, match=re.escape(message)):
        write_index(root)
    assert not (root / INDEX).exists()


def test_a_pages_stated_commit_is_its_commit_and_the_manifest_may_not_repeat_it(tmp_path):
    root = _small_results(tmp_path, "0.0081")
    (root / "page.md").write_text("# A study\n\nGenerated by `make page` (commit 5c085e2).\n")
    manifest = root / "manifest.toml"
    entry = '[[result]]\npath = "page.md"\ngroup = "residual"\ntitle = "a page"\nstatus = "current"\ncommand = "make page"\n'
    manifest.write_text(manifest.read_text() + entry)
    write_index(root)
    assert "| [page.md](page.md): a page | current | — | `make page` | 5c085e2 |" in (root / INDEX).read_text()
    manifest.write_text(manifest.read_text() + 'commit = "49e98f9"\n')  # a second home, which drifted
    with pytest.raises(UserError, match=re.escape("(page.md): the page states the commit it was made at (5c085e2); "
                                                  "remove 'commit' (49e98f9) from its entry")):
        write_index(root)


def test_the_manifest_lists_each_result_once():
    paths = [p for e in read_manifest(RESULTS) for p in e.paths()]
    assert len(paths) == len(set(paths))


def test_the_scratch_folder_of_make_bench_is_no_result_and_no_page(tmp_path):
    root = _small_results(tmp_path, "0.0081")
    (root / "quick" / "records").mkdir(parents=True)
    (root / "quick" / "records" / "run.json").write_text("{}")
    (root / "quick" / "tables.md").write_text("<!-- figure study.indirect -->9<!-- /figure -->\n")
    assert unlisted(root) == [] and stale_figures(root) == []
    assert cli("index", root).returncode == 0
    assert "-->9<!--" in (root / "quick" / "tables.md").read_text()



def test_a_table_names_each_run_that_is_not_ok_with_its_reason(tmp_path):
    from bench.reporting.tables import write_tables

    shutil.copytree(RESULTS / "measured" / "kuka_swapped_60s" / "records", tmp_path / "records")
    killed = tmp_path / "records" / "kuka_lwr4__syrenets__indirect__seed1.json"
    record = json.loads(killed.read_text())
    record |= {"status": "timeout", "error": "fit still running at 1.5 x its 60 s budget; killed\nTraceback ...",
               "train_mse": None, "test_mse": None}
    killed.write_text(json.dumps(record))
    text = write_tables(tmp_path)
    assert "- **syrenets**, seed 1: timeout: fit still running at 1.5 x its 60 s budget; killed" in text
    assert "Traceback" not in text  # the first line of its reason
    records = read_records(tmp_path)
    bad = [r for r in records if r.status != "ok"]
    named = [line for line in text.splitlines() if line.startswith("- **")]
    assert bad and 1 <= len(named) <= len(bad)
    for r in bad:  # each run that is not ok is named, under its column, with its seed and its reason
        assert any(line.startswith(f"- **{label(r)}**, seed") and str(r.seed) in line and r.status in line
                   for line in named), r.run_id
    ok_only = {label(r) for r in records} - {label(r) for r in bad}
    assert not any(f"**{m}**" in line for m in ok_only for line in named)  # the runs that are ok are not named
