"""results/index.md: every published result, from results/manifest.toml and
the records.

The manifest lists each result once (a folder or a page, with the files that
belong to it), its group, whether it is current or superseded (and by
what), the command that made it, and its headline figures. A figure is
computed, never typed: from a folder's records (one system, experiment and
method, a group of seeds and a split, as in the tables) or from a key of a
JSON file. The commit is the records' (the most common, and how many
there are) or, for a page without records, the manifest's.

A figure also has a name. Wherever a page (README.md, or any page under
results/) marks a number as ``<!-- figure NAME -->0.0081<!-- /figure -->``,
:func:`write_index` rewrites it from the records, and :func:`stale_figures`
lists the marks that disagree with them. A number in prose may also be named by
the records it comes from, without a manifest entry:
``<!-- figure records/leaderboard/cart_pole/direct/delan/all -->2.0e-5<!-- /figure -->``
(:data:`INLINE`), or by a JSON file under results/ and a dotted key in it:
``<!-- figure json/measured/kuka_loop/sysid_default.json/mse_after.test -->0.336<!-- /figure -->``
(:data:`INLINE_JSON`; a record is such a file too); it is checked and rewritten in the style it is typed in. A page's generated tables and lists
(:mod:`bench.reporting.pages`) are rewritten and checked the same way.
"""

from __future__ import annotations

import json
import re
import tomllib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from bench.core.errors import UserError
from bench.core.fileio import atomic_write
from bench.reporting.groups import GROUPS, HALVES_FROM, SEED_STATISTICS, TESTED_GROUP, group_stats, seed_statistic
from bench.reporting import arms, measured, panda_log, tuned  # noqa: F401  (the pages' generated blocks)
from bench.reporting.pages import rewrite, stale_blocks
from bench.reporting.tables import expand_variants
from bench.runner.records import read_records

MANIFEST = "manifest.toml"
#: what an inline figure may count instead: how many seeds' expressions are exactly the true L
EXACT = "exact"
#: an inline figure's All n test MSE over the standard model's the records carry
RATIO = "ratio"
INDEX = "index.md"
STATUSES = ("current", "superseded")
#: the scratch folder ``make bench`` writes into (ignored by git): no published result
SCRATCH = "quick"
MARK = re.compile(r"<!-- figure (?P<name>[\w.+@/-]+) -->(?P<value>.*?)<!-- /figure -->")
#: a figure named by its records: ``records/FOLDER/SYSTEM/EXPERIMENT/METHOD/GROUP[/train]``, FOLDER under
#: results/, GROUP one of :data:`~bench.reporting.groups.GROUPS` with ``_`` for a space or of
#: :data:`~bench.reporting.groups.SEED_STATISTICS`, or :data:`EXACT` or :data:`RATIO` (:func:`inline_value`)
INLINE = re.compile(r"records/(?P<folder>[\w./-]+)/(?P<system>\w+)/(?P<experiment>direct|indirect)/"
                    r"(?P<method>[\w+@-]+)/(?P<group>best|best_half|all|worse_half|median|worst|exact|ratio)(?:/(?P<split>train))?")
#: a figure named by a JSON file under results/ and a dotted key in it (a part may index a list), with
#: ``/percent`` where a fraction is shown in %: ``json/FILE.json/KEY[/percent]``
INLINE_JSON = re.compile(r"json/(?P<file>[\w./+@-]+?\.json)/(?P<key>[\w.+@-]+?)(?P<percent>/percent)?")


@dataclass(frozen=True)
class Figure:
    """One headline number: ``records`` (system, experiment, method, and
    optionally group, split and noise; ``quantity`` ``standard.KEY`` reads
    ``KEY`` of the standard model the records carry, ``ratio`` the group's
    test MSE over the standard model's) or ``json`` (a file and a dotted key,
    whose parts may index a list). ``over`` names another figure, of any result, that divides
    the value: a hybrid's test MSE over its prior's, a loop's (a JSON) over the standard model's."""

    name: str
    label: str
    format: str = ".2g"
    records: dict | None = None
    json: dict | None = None
    over: str | None = None


@dataclass(frozen=True)
class Entry:
    path: str
    group: str
    title: str
    status: str
    command: str
    also: tuple[str, ...] = ()
    superseded_by: str | None = None
    commit: str | None = None
    figures: tuple[Figure, ...] = field(default_factory=tuple)

    def paths(self) -> tuple[str, ...]:
        return (self.path, *self.also)


def read_manifest(root: Path) -> list[Entry]:
    """The manifest's entries; a bad one ends in one line naming the field."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise UserError(f"{path}: no such file; index lists the results a manifest names (docs/cli.md, 'index'); "
                        f"a run folder's tables are written by python -m bench table {root}")
    try:
        raw = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"{path}: {exc}") from None
    entries = []
    for i, item in enumerate(raw.get("result", [])):
        where = f"{path}: result {i + 1} ({item.get('path', '?')})"
        for key in ("path", "group", "title", "status", "command"):
            if not isinstance(item.get(key), str):
                raise UserError(f"{where}: '{key}' must be a string")
        if item["status"] not in STATUSES:
            raise UserError(f"{where}: 'status' must be one of {', '.join(STATUSES)}, got {item['status']!r}")
        if item["status"] == "superseded" and not item.get("superseded_by"):
            raise UserError(f"{where}: a superseded result names what supersedes it in 'superseded_by'")
        figures = []
        for f in item.get("figure", []):
            if not isinstance(f.get("name"), str) or not isinstance(f.get("label"), str):
                raise UserError(f"{where}: a figure needs a 'name' and a 'label'")
            if ("records" in f) == ("json" in f):
                raise UserError(f"{where}: figure {f['name']} takes its value from 'records' or from 'json'")
            figures.append(Figure(f["name"], f["label"], f.get("format", ".2g"), f.get("records"), f.get("json"),
                                  f.get("over")))
        entries.append(Entry(item["path"], item["group"], item["title"], item["status"], item["command"],
                             tuple(item.get("also", ())), item.get("superseded_by"), item.get("commit"), tuple(figures)))
    names = Counter(f.name for e in entries for f in e.figures)
    twice = sorted(n for n, k in names.items() if k > 1)
    if twice:
        raise UserError(f"{path}: the figure name {twice[0]!r} is used twice")
    unknown = sorted(f.over for e in entries for f in e.figures if f.over is not None and f.over not in names)
    if unknown:
        raise UserError(f"{path}: a figure is over {unknown[0]!r}, which no figure is named")
    return entries


class _Records:
    """Each result folder's records, read once however many figures and
    commits ask for them, with a record per variant a run reported
    (``METHOD@VARIANT``, as the tables have them)."""

    def __init__(self, root: Path):
        self.root, self._read = Path(root), {}

    def __call__(self, path: str) -> list:
        if path not in self._read:
            self._read[path] = expand_variants(read_records(self.root / path))
        return self._read[path]


def json_number(root: Path, file: str, key: str, name: str) -> float:
    """The number at dotted ``key`` of JSON ``file`` under ``root`` (a part may index a list)."""
    value = json.loads((Path(root) / file).read_text())
    try:
        for part in key.split("."):
            value = value[int(part)] if isinstance(value, list) else value[part]
        return float(value)
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise UserError(f"{Path(root) / MANIFEST}: figure {name}: {file} has no number at "
                        f"{key} ({type(exc).__name__}: {exc})") from None


def figure_value(root: Path, entry: Entry, figure: Figure, records: _Records | None = None) -> float:
    """A figure's value, from the entry's records or from its JSON file."""
    if figure.json is not None:
        return json_number(root, figure.json["file"], figure.json["key"], figure.name)
    want = figure.records
    records = [r for r in (records or _Records(root))(entry.path)
               if (r.system, r.experiment, r.method, r.noise, r.tuned) == (
                   want["system"], want["experiment"], want["method"], float(want.get("noise", 0.0)),
                   bool(want.get("tuned", False)))]
    if not records:
        raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: no records of {want} in {entry.path}")
    group = want.get("group", TESTED_GROUP)
    if group not in GROUPS + SEED_STATISTICS + (EXACT,):
        raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: group {group!r} is none of "
                        f"{', '.join(GROUPS + SEED_STATISTICS + (EXACT,))}")
    if group == EXACT:
        return float(sum(bool(r.exact) for r in records if r.status == "ok"))
    quantity = want.get("quantity", "")
    standard = next((r.details["standard_model"] for r in records if (r.details or {}).get("standard_model")), None)
    if quantity.startswith("standard."):
        if standard is None or standard.get(quantity[len("standard."):]) is None:
            raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: the records carry no {quantity}")
        return float(standard[quantity[len("standard."):]])
    split = want.get("split", "test")
    if group in SEED_STATISTICS:  # over every ok seed's own MSE
        value = seed_statistic(records, group, split)
        if value is None:
            raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: no seed of its records is ok")
    else:
        stats = group_stats(records)
        if group not in stats:
            raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: its records have no {group!r} group "
                            f"(fewer than {HALVES_FROM} seeds, or none ok)")
        value = stats[group][split][0]
    if quantity == "ratio":
        if standard is None or not standard.get("test_mse"):
            raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: the records carry no standard model")
        return value / standard["test_mse"]
    if quantity not in ("", "mse"):
        raise UserError(f"{Path(root) / MANIFEST}: figure {figure.name}: quantity {quantity!r} is none of mse, ratio, "
                        f"standard.KEY")
    return value


def commit_of(root: Path, entry: Entry, records: _Records | None = None) -> str:
    """The commit of a result's records (the most common; how many there are), or the manifest's."""
    if (Path(root) / entry.path / "records").is_dir():
        commits = Counter(r.provenance.get("commit", "")[:10] for r in (records or _Records(root))(entry.path))
        top, _ = commits.most_common(1)[0]
        return top if len(commits) == 1 else f"{top} and {len(commits) - 1} more"
    return entry.commit or "—"


def figures(root: Path, entries: list[Entry] | None = None, records: _Records | None = None) -> dict[str, str]:
    """Every named figure, formatted as pages show it."""
    entries = read_manifest(root) if entries is None else entries
    records = records or _Records(root)
    raw = {f.name: figure_value(root, e, f, records) for e in entries for f in e.figures}
    shown = [f for e in entries for f in e.figures]
    return {f.name: format(raw[f.name] / raw[f.over] if f.over else raw[f.name], f.format) for f in shown}


def build_index(root: Path, entries: list[Entry] | None = None, values: dict[str, str] | None = None,
                records: _Records | None = None) -> str:
    """The index's text (``values``: the figures, where already computed from ``records``)."""
    entries = read_manifest(root) if entries is None else entries
    records = records or _Records(root)
    values = figures(root, entries, records) if values is None else values
    lines = ["# Results index", "",
             f"Generated by `python -m bench index` from [{MANIFEST}]({MANIFEST}) and the records; do not edit. "
             "Each result's figures are computed from its records (All n is the mean over the n seeds, as in the "
             "tables); a superseded result is kept because a current page cites it.", ""]
    for group in dict.fromkeys(e.group for e in entries):
        lines += [f"## {group}", "", "| result | status | headline | command | commit |", "|---|---|---|---|---|"]
        for e in (e for e in entries if e.group == group):
            status = e.status if e.superseded_by is None else f"superseded by [{e.superseded_by}]({e.superseded_by})"
            headline = "; ".join(f"{f.label} {values[f.name]}" for f in e.figures) or "—"
            lines.append(f"| [{e.path}]({e.path}): {e.title} | {status} | {headline} | {_command(e.command)} | {commit_of(root, e, records)} |")
        lines.append("")
    return "\n".join(lines)


def unlisted(root: Path, entries: list[Entry] | None = None, files: list[Path] | None = None) -> list[str]:
    """Files under ``root`` (or of ``files``, where given: those a checkout
    publishes) that no entry covers (an entry's folder covers what it holds)."""
    entries = read_manifest(root) if entries is None else entries
    covered = [Path(root) / p for e in entries for p in e.paths()]
    out = []
    for path in sorted(Path(root).rglob("*") if files is None else files):
        if not path.is_file() or path.name in (MANIFEST, INDEX) or _scratch(root, path):
            continue
        if not any(path == c or c in path.parents for c in covered):
            out.append(str(path.relative_to(root)))
    return out


def _scratch(root: Path, path: Path) -> bool:
    return Path(root) / SCRATCH in path.parents


def _pages(root: Path) -> list[Path]:
    top = Path(root).resolve().parent / "README.md"
    pages = [p for p in Path(root).rglob("*.md") if "records" not in p.parts and p.name != INDEX and not _scratch(root, p)]
    return ([top] if top.is_file() else []) + sorted(pages)


def format_like(value: float, shown: str) -> str:
    """``value`` written as ``shown`` is: as many decimals, or in the same
    scientific notation (``2.0e-5``), so that a figure typed in prose is
    checked, and rewritten, in its own style."""
    if "e" in shown:
        mantissa = shown.split("e")[0]
        digits = len(mantissa.split(".")[1]) if "." in mantissa else 0
        text = f"{value:.{digits}e}"
        mantissa, exponent = text.split("e")
        return f"{mantissa}e{int(exponent)}"
    digits = len(shown.split(".")[1]) if "." in shown else 0
    return f"{value:,.{digits}f}" if "," in shown else f"{value:.{digits}f}"


def inline_value(root: Path, name: str, shown: str, records: _Records) -> str | None:
    """A figure named by its records (:data:`INLINE`) or by a JSON file (:data:`INLINE_JSON`) in the style it is shown
    in (:func:`format_like`); ``None`` for another name, or where the records
    give no such figure."""
    m = INLINE_JSON.fullmatch(name)
    if m is not None:
        try:
            value = json_number(root, m["file"], m["key"], name)
        except (UserError, OSError, ValueError):
            return None
        return format_like(100 * value if m["percent"] else value, shown)
    m = INLINE.fullmatch(name)
    if m is None:
        return None
    want = {k: m[k] for k in ("system", "experiment", "method")} | {"group": m["group"].replace("_", " ")}
    if m["group"] == RATIO:  # All n's test MSE over the standard model's
        want |= {"group": TESTED_GROUP, "quantity": "ratio"}
    if m["split"]:
        want["split"] = m["split"]
    entry = Entry(m["folder"], "", "", "current", "")
    try:
        return format_like(figure_value(root, entry, Figure(name, name, records=want), records), shown)
    except (UserError, OSError):
        return None


def stale_figures(root: Path) -> list[str]:
    """``page: name shows X, records give Y`` for each marked figure that disagrees
    (or has no entry), and each generated block that is not what its records
    give (:func:`bench.reporting.pages.stale_blocks`)."""
    records = _Records(root)
    values, out = figures(root, records=records), []
    for page in _pages(root):
        for m in MARK.finditer(page.read_text()):
            want = values.get(m["name"]) or inline_value(root, m["name"], m["value"], records)
            if want != m["value"]:
                out.append(f"{page}: {m['name']} shows {m['value']}, the records give {want or 'no such figure'}")
    return out + stale_blocks(root, _pages(root))


def write_index(root: Path) -> tuple[Path, list[Path]]:
    """Write ``root/index.md`` and rewrite every marked figure; returns the index and the pages changed."""
    root = Path(root)
    entries = read_manifest(root)
    missing = unlisted(root, entries)
    if missing:
        raise UserError(f"{root / MANIFEST}: {missing[0]} is in no result (list it, or remove it)"
                        + (f"; {len(missing) - 1} more" if len(missing) > 1 else ""))
    records = _Records(root)
    values = figures(root, entries, records)
    text = build_index(root, entries, values, records) + "\n"  # all computed before anything is written
    changed, made = [], {}
    for page in _pages(root):
        old = page.read_text()
        new = MARK.sub(lambda m: f"<!-- figure {m['name']} -->"
                       f"{values.get(m['name']) or inline_value(root, m['name'], m['value'], records) or m['value']}"
                       f"<!-- /figure -->", old)
        new = rewrite(new, root, made)
        if new != old:
            atomic_write(page, lambda f, t=new: f.write(t))
            changed.append(page)
    index = root / INDEX
    atomic_write(index, lambda f: f.write(text))
    return index, changed


def _command(command: str) -> str:
    """A command in code type; a note about one (in brackets) as text."""
    return command if command.startswith("(") else f"`{command}`"
