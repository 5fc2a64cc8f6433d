"""Generated hostile input: CSV files, robot logs, record files and ``--set``
values, each either accepted whole or refused in one line naming the file,
with nothing written and no traceback."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from bench.cli import main
from bench.core.arguments import assignment
from bench.core.data import DataError
from bench.core.csv_format import MAX_ABS_VALUE, read_csv
from bench.core.errors import UserError
from bench.runner.records import Record, RecordError, read_record, read_records, record_path, write_record
from bench.runner.spec import RunSpec
from methods import METHODS

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

REQUIRED = ["q_1", "q_2", "qd_1", "qd_2", "qdd_1", "qdd_2", "tau_1", "tau_2"]
COLUMNS = REQUIRED + ["L", "time", "q_3", "tau", "", "q_1 ", "trajectory"]
CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["1e308", "-1e308", "1e155", "5e-324", "2.2250738585072014e-308", "inf", "-inf", "nan", "NaN",
                     "", " ", "x", "1,5", '"', "0x10", "1e", "--1", "٣"]),
    st.integers(-10**30, 10**30).map(str),
)


@st.composite
def csv_texts(draw):
    # any header, or the suite's columns in any order with extras: most of the latter load
    header = draw(st.one_of(st.lists(st.sampled_from(COLUMNS), max_size=10),
                            st.tuples(st.permutations(REQUIRED), st.lists(st.sampled_from(COLUMNS), max_size=2))
                            .map(lambda t: list(t[0]) + t[1])))
    cells = st.one_of(CELLS, st.floats(-1e6, 1e6).map(repr)) if draw(st.booleans()) else st.floats(-1e6, 1e6).map(repr)
    rows = draw(st.lists(st.lists(cells, min_size=len(header), max_size=len(header)), max_size=4))
    text = "\n".join([",".join(header)] + [",".join(row) for row in rows])
    return text + draw(st.sampled_from(["", "\n", "\n\n"]))


def check_refusal(exc: Exception, path) -> None:
    message = str(exc)
    assert str(path) in message and "\n" not in message and "Traceback" not in message


def _read_or_refused(path):
    """The file read as the suite's format of two joints, or ``None`` where it was refused in one line naming
    it."""
    try:
        data = read_csv(path, dof=2)
    except DataError as exc:
        check_refusal(exc, path)
        event("refused")
        return None
    event("read")
    return data


@SETTINGS
@given(content=st.one_of(csv_texts().map(str.encode), st.binary(max_size=200)))
def test_a_csv_file_loads_whole_or_is_refused_in_one_line(tmp_path, content):
    path = tmp_path / "data.csv"
    path.write_bytes(content)
    data = _read_or_refused(path)
    if data is None:
        return
    for name in ("q", "qd", "qdd", "tau"):
        values = getattr(data, name)
        assert values.shape == (len(data), 2) and np.isfinite(values).all() and (np.abs(values) <= MAX_ABS_VALUE).all()
    assert data.L is None or np.isfinite(data.L).all()
    assert data.recording is None or (data.recording.shape == (len(data),) and all(r.strip() for r in data.recording))


@st.composite
def log_texts(draw):
    """A log of time, q_1, qd_1, tau_1 in any order with extras, a time column
    that mostly increases, and values that are mostly sound."""
    header = list(draw(st.permutations(["time", "q_1", "qd_1", "tau_1"]))) + draw(st.lists(st.sampled_from(COLUMNS), max_size=2))
    n = draw(st.integers(0, 300))
    rows = []
    for i in range(n):
        row = [repr(i * 0.002) if name == "time" else repr(math.sin(0.01 * i + k)) for k, name in enumerate(header)]
        rows.append(row)
    for _ in range(draw(st.integers(0, 3))):  # a few hostile cells
        if rows:
            rows[draw(st.integers(0, n - 1))][draw(st.integers(0, len(header) - 1))] = draw(CELLS)
    return "\n".join([",".join(header)] + [",".join(r) for r in rows]) + "\n"


@SETTINGS
@given(content=log_texts())
def test_a_robot_log_converts_or_is_refused_in_one_line_and_nothing_is_written(tmp_path, capsys, content):
    raw, out = tmp_path / "log.csv", tmp_path / "out.csv"
    raw.write_text(content)
    out.unlink(missing_ok=True)
    code = main(["convert", "--columns", "time=time,q_1=q_1,qd_1=qd_1,tau_1=tau_1", "--trim", "0.02", "--decimate", "1",
                 str(raw), "--out", str(out)])
    err = capsys.readouterr().err
    if code == 0:
        assert read_csv(out, dof=1) is not None
        event("converted")
    else:
        assert code == 2 and err.startswith("error: ") and err.count("\n") == 1 and not out.exists()


def valid_record() -> dict:
    spec = RunSpec(system="double_pendulum", method="mlp", experiment="direct", seed=0, budget_s=1.0)
    return Record.new(spec, "ok", train_mse=1.0, test_mse=2.0).to_json()


JSON_VALUES = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=5),
                        st.lists(st.integers(), max_size=2), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


@st.composite
def record_texts(draw):
    kind = draw(st.sampled_from(["mutated", "bytes", "json"]))
    if kind == "bytes":
        return draw(st.binary(max_size=100))
    if kind == "json":
        return json.dumps(draw(JSON_VALUES)).encode()
    obj = valid_record()
    for key in draw(st.lists(st.sampled_from(sorted(obj)), max_size=3, unique=True)):
        if draw(st.booleans()):
            del obj[key]
        else:
            obj[key] = draw(JSON_VALUES)
    return json.dumps(obj, allow_nan=True).encode()


@SETTINGS
@given(content=record_texts())
def test_a_record_file_is_read_whole_or_set_aside_in_one_line(tmp_path, content):
    folder = tmp_path / "records"
    folder.mkdir(exist_ok=True)
    path = folder / "double_pendulum__mlp__direct__seed0.json"
    path.write_bytes(content)
    bad = []
    records = read_records(tmp_path, on_bad=lambda p, e: bad.append((p, e)))
    if records:
        (r,) = records
        assert r.status in ("ok", "failed", "timeout", "unavailable", "not_applicable")
        if r.status == "ok":
            assert math.isfinite(r.train_mse)
        assert bad == []
    else:
        ((where, error),) = bad
        assert where == path and isinstance(error, RecordError)
        check_refusal(error, path)


@SETTINGS
@given(name=st.sampled_from(["hidden", "layers", "lr", "batch_size", "max_steps", "eval_samples", "betas", "dtype",
                             "lr_factor", "hiden", "", "x y"]),
       value=st.one_of(st.text(max_size=8), st.integers(-5, 5).map(str), st.floats().map(repr),
                       st.sampled_from(["true", "No", "(0.9, 0.99)", "[1, 2]", "None", "'float32'", "1e400", "nan"])))
def test_a_set_value_is_taken_or_refused_in_one_line(name, value):
    try:
        key, parsed = assignment(f"{name}={value}")
        model = METHODS["mlp"](**{key: parsed})
    except UserError as exc:
        assert "\n" not in str(exc)
        return
    assert getattr(model.config, key) is not None or key == "max_steps"


def test_the_table_command_never_counts_a_broken_record_as_ok(tmp_path, capsys):
    good = Record.from_json(valid_record())
    write_record(record_path(tmp_path, good.run_id), good)
    (tmp_path / "records" / "double_pendulum__mlp__direct__seed1.json").write_text('{"status": "ok", "train_mse": 1}')
    assert main(["table", str(tmp_path)]) == 0
    assert "| Runs | | 1/2 ok (1 missing) |" in (tmp_path / "tables.md").read_text()
    assert capsys.readouterr().err.count("\n") == 1


@pytest.fixture(autouse=True)
def _quiet_matplotlib(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sep=st.sampled_from([",", ";", "\t", " ", "  ", " \t "]), crlf=st.booleans(), n=st.integers(60, 200),
       seed=st.integers(0, 2**16), glue=st.sampled_from(["", "|", ":"]))
def test_a_log_converts_alike_whatever_common_separator_it_uses_or_names_those_tried(tmp_path, capsys, sep, crlf, n,
                                                                                    seed, glue):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=(n, 3)).round(6)
    end = "\r\n" if crlf else "\n"
    rows = [repr(i * 0.01) for i in range(n)]

    def text(s):
        return end.join([s.join(["time", "q_1", "qd_1", "tau_1"])] +
                        [s.join([t, *(repr(float(x)) for x in v)]) for t, v in zip(rows, values)]) + end

    args = ["convert", "--columns", "time=time,q_1=q_1,qd_1=qd_1,tau_1=tau_1", "--cutoff-hz", "10", "--trim", "0.1"]
    (tmp_path / "comma.csv").write_text(text(","), newline="")
    (tmp_path / "log.txt").write_text(text(glue or sep), newline="")
    for name in ("comma.csv", "log.txt"):
        (tmp_path / f"{name}.out.csv").unlink(missing_ok=True)
    assert main([*args, str(tmp_path / "comma.csv"), "--out", str(tmp_path / "comma.csv.out.csv")]) == 0
    code = main([*args, str(tmp_path / "log.txt"), "--out", str(tmp_path / "log.txt.out.csv")])
    err = capsys.readouterr().err
    if glue:  # no common separator: one line naming the ones tried, nothing written
        assert code == 2 and err.count("\n") == 1 and "log.txt" in err and "tried the separators" in err
        assert not (tmp_path / "log.txt.out.csv").exists()
        return
    assert code == 0, err
    a, b = read_csv(tmp_path / "comma.csv.out.csv", dof=1), read_csv(tmp_path / "log.txt.out.csv", dof=1)
    np.testing.assert_array_equal(a.tau, b.tau)
    np.testing.assert_array_equal(a.qdd, b.qdd)


def valid_loop_json() -> dict:
    """The residual loop's JSON as it was written before it was a record (every field at the top)."""
    return {"system": "double_pendulum", "method": "sysid", "mse_before": {"train": 2.0, "test": 3.0},
            "mse_after": {"train": 1.0, "test": 1.5}, "effects": [], "rounds": [{"round": 0}], "lagrangian": None,
            "seconds": 1.0, "budget_s": 60.0, "fit_budget_s": 30.0, "seed": 0, "train_source": "t.csv",
            "test_source": None, "budget": {"kind": "seconds", "seconds": 60.0}, "provenance": {}}


@SETTINGS
@given(changes=st.lists(st.tuples(st.sampled_from(sorted(valid_loop_json())), st.one_of(st.just(None), JSON_VALUES)),
                        max_size=3))
def test_a_loop_result_written_before_it_was_a_record_reads_whole_or_is_refused_in_one_line(tmp_path, changes):
    obj = valid_loop_json()
    for key, value in changes:
        obj[key] = value
    path = tmp_path / "loop.json"
    path.write_text(json.dumps(obj, allow_nan=True))
    try:
        record = read_record(path)
    except RecordError as exc:
        check_refusal(exc, path)
        return
    assert record.kind == "residual" and record.status == "ok" and math.isfinite(record.train_mse)


#: mutated measured-arm files the test runs (``BENCH_FUZZ_EXAMPLES`` raises it: 2,000 with ``=2000``)
ARM_EXAMPLES = int(__import__("os").environ.get("BENCH_FUZZ_EXAMPLES", "60"))


def _toml(value) -> str:
    """``value`` in TOML: strings, numbers, booleans, arrays and inline tables (every key quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, (int, str)):
        return json.dumps(value) if isinstance(value, str) else str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml(v)}" for k, v in value.items()) + " }"


def _arm_files(folder) -> dict:
    """Two recordings of one joint, of trajectories a and b, and the declaration that reads them."""
    t = np.arange(400) * 0.01
    for name, phase in (("a.csv", 0.0), ("b.csv", 0.7)):
        rows = ["t,p,v,f"] + [f"{x:.2f},{np.sin(x + phase):.6f},{np.cos(x + phase):.6f},{np.sin(2 * x):.6f}" for x in t]
        (folder / name).write_text("\n".join(rows) + "\n")
    return {"columns": "time=t,q_1=p,qd_1=v,tau_1=f", "test": ["b"], "filter": {"cutoff_hz": 8.0, "trim_s": 0.1},
            "recordings": {"r1": {"file": "a.csv", "trajectory": "a"}, "r2": {"file": "b.csv", "trajectory": "b"}}}


def _places(node, where=()):
    yield where
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _places(v, (*where, k))
    elif isinstance(node, list):
        for k, v in enumerate(node):
            yield from _places(v, (*where, k))


_HOSTILE = st.recursive(
    st.one_of(st.booleans(), st.integers(-2 ** 63, 2 ** 63 - 1), st.floats(allow_nan=True, allow_infinity=True),
              st.text(max_size=12), st.sampled_from(["a", "b", "a.csv", "b.csv", "../b.csv", "/etc/passwd", "s", "ms",
                                                     "time=t,q_1=p,qd_1=v,tau_1=f", "time=t,q_1=p", "r1"])),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6)


@settings(max_examples=ARM_EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(where=st.floats(0, 1), action=st.sampled_from(["replace", "delete", "add"]), value=_HOSTILE,
       key=st.text(min_size=1, max_size=8))
def test_a_mutated_measured_arm_file_is_refused_in_one_line_or_reads_as_it_declares(tmp_path, where, action, value,
                                                                                     key):
    """A measured arm's file with a field replaced, deleted or added: refused in one line naming the file, or
    read; read, its samples are those of the valid original wherever it declares the same, and finite
    otherwise. Never a traceback, a hang or a sample read from outside what it declares."""
    from systems.measured import _samples, read_spec

    good = _arm_files(tmp_path)
    original = tmp_path / "good.toml"
    original.write_text("".join(f"{json.dumps(k)} = {_toml(v)}\n" for k, v in good.items()))
    base = read_spec(original)
    expected = _samples(base, base.parts("default")["train"], base.filter, True)[0]
    mutated = json.loads(json.dumps(good))
    places = [p for p in _places(mutated) if p]
    place = places[min(int(where * len(places)), len(places) - 1)]
    parent = mutated
    for k in place[:-1]:
        parent = parent[k]
    if action == "replace":
        parent[place[-1]] = value
    elif action == "delete":
        del parent[place[-1]]
    elif isinstance(parent, dict):
        parent.setdefault(key, value)
    else:
        parent.append(value)
    path = tmp_path / "arm.toml"
    path.write_text("".join(f"{json.dumps(k)} = {_toml(v)}\n" for k, v in mutated.items()))
    try:
        spec = read_spec(path)
        got = _samples(spec, spec.parts("default")["train"], spec.filter, True)[0]
    except UserError as exc:
        assert str(path) in str(exc) or ".csv" in str(exc), str(exc)
        assert "\n" not in str(exc) and "Traceback" not in str(exc)
        event("refused")
        return
    event("read")
    assert all(np.isfinite(got[k]).all() for k in ("q", "qd", "qdd", "tau"))
    same = dataclasses.replace(spec, source=base.source) == base
    if same:
        for k in ("q", "qd", "qdd", "tau", "time"):
            np.testing.assert_array_equal(got[k], expected[k])


#: mutated CSV files the test runs (``BENCH_FUZZ_EXAMPLES`` raises it: 2,000 with ``=2000``)
CSV_EXAMPLES = ARM_EXAMPLES


def _valid_csv(rng_seed: int) -> list[list[str]]:
    """A valid file of two joints and a column the suite ignores, six rows, as its header and rows of cells:
    every digit of each float written (``repr``)."""
    rng = np.random.default_rng(rng_seed)
    return [REQUIRED + ["extra"]] + [[repr(float(v)) for v in rng.normal(scale=10.0, size=len(REQUIRED) + 1)]
                                     for _ in range(6)]


def _as_read_by_python(text: str) -> dict[str, list[float]] | None:
    """What a file says, read by Python's own ``csv`` and ``float``: each of :data:`REQUIRED`'s columns, or
    ``None`` where the file is not one the suite may read (a row of another width, a name twice, a column
    missing, a cell that is not a finite number the suite computes with). The oracle the suite's reader is
    held to."""
    import csv
    import io

    rows = [r for r in csv.reader(io.StringIO(text)) if r]
    if len(rows) < 2:
        return None
    header = [n.strip() for n in rows[0]]
    if len(set(header)) != len(header) or any(len(r) != len(header) for r in rows[1:]):
        return None
    if any(n not in header for n in REQUIRED):
        return None
    out = {}
    for name in REQUIRED:
        values = []
        for row in rows[1:]:
            cell = row[header.index(name)].strip()
            try:
                value = float(cell)
            except ValueError:
                return None
            if "_" in cell or not math.isfinite(value) or abs(value) > MAX_ABS_VALUE:
                return None
            values.append(value)
        out[name] = values
    return out


@settings(max_examples=CSV_EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(seed=st.integers(0, 3), action=st.sampled_from(["cell", "delete cell", "add cell", "name", "delete line",
                                                       "repeat line", "blank line", "spaces"]),
       row=st.integers(0, 6), col=st.integers(0, len(REQUIRED) + 1), cell=CELLS, name=st.sampled_from(COLUMNS))
def test_a_mutated_csv_file_is_refused_in_one_line_or_reads_what_it_says(tmp_path, seed, action, row, col, cell,
                                                                          name):
    """A valid CSV with one change (a cell replaced, deleted or added, a column renamed, a line deleted,
    repeated or left blank, spaces around a cell): refused in one line naming the file, or read; read, its
    samples are exactly what Python's own ``csv`` and ``float`` read from it, to the bit, and a file that
    they cannot read as the suite's format is refused. Never a traceback, and never a sample shifted into
    another column or rounded."""
    rows = _valid_csv(seed)
    row, col = min(row, len(rows) - 1), min(col, len(rows[0]) - 1)
    if action == "cell":
        rows[max(row, 1)][col] = cell
    elif action == "delete cell":
        del rows[row][col]
    elif action == "add cell":
        rows[row].insert(col, cell)
    elif action == "name":
        rows[0][col] = name
    elif action == "delete line":
        del rows[max(row, 1)]
    elif action == "repeat line":
        rows.insert(row, list(rows[max(row, 1)]))
    elif action == "blank line":
        rows.insert(max(row, 1), [])
    else:
        rows[row][col] = f"  {rows[row][col]} "
    text = "\n".join(",".join(r) for r in rows) + "\n"
    path = tmp_path / "data.csv"
    path.write_text(text)
    expected = _as_read_by_python(text)
    data = _read_or_refused(path)
    if data is None:
        return
    assert expected is not None, f"read a file Python's csv does not read as the format:\n{text}"
    for name in REQUIRED:
        kind, joint = name.rsplit("_", 1)
        got = getattr(data, kind)[:, int(joint) - 1]
        assert got.tolist() == expected[name], (name, text)


def test_a_header_read_checks_the_rows_it_reads_and_the_whole_read_checks_every_row(tmp_path):
    """``read_frame(path, nrows=1)`` (a log's columns) reads and checks its first row only, so a row that lost a
    field further down is refused by the whole read, not by the header's."""
    from bench.core.csv_format import read_frame

    path = tmp_path / "log.csv.gz"
    rows = [",".join(REQUIRED)] + [",".join(["1.0"] * len(REQUIRED))] * 5 + [",".join(["1.0"] * (len(REQUIRED) - 1))]
    import gzip

    path.write_bytes(gzip.compress(("\n\n".join(rows) + "\n").encode()))
    assert list(read_frame(path, nrows=1).columns) == REQUIRED
    with pytest.raises(DataError, match=r"data row 6 has 7 fields, where its header names 8 columns"):
        read_frame(path)
