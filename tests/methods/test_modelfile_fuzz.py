"""Model files from strangers: saved models with flipped bytes, cut short, or
with their header and expression trees mutated, each given to ``bench
predict`` in this process. Every outcome is a prediction or one line with
exit 2, nothing written; none raises, and none hangs (a guard of
:data:`GUARD_S` seconds an example, far above what a load takes, fails the
test where a file would hang; it measures nothing).

Each test runs :data:`EXAMPLES` files; ``BENCH_FUZZ_EXAMPLES`` raises it
(2,000 files and the crafted ones: ``BENCH_FUZZ_EXAMPLES=1000``; ``--hypothesis-show-statistics`` counts
the files predicted and refused)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument

from bench.cli import main as cli_main
from bench.core import modelfile
from tests.commandline import cli

#: mutated files each test runs
EXAMPLES = int(os.environ.get("BENCH_FUZZ_EXAMPLES", "60"))
#: seconds after which an example counts as a hang
GUARD_S = 20


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A saved expression model (sparse regression) and an MLP of the double pendulum, and a log."""
    folder = tmp_path_factory.mktemp("fuzz")
    for part, seed in (("train", 0), ("test", 1000)):
        assert cli("data", "--system", "double_pendulum", "--n", 64 if part == "test" else 300, "--seed", seed,
                   "--out", folder / f"{part}.csv").returncode == 0
    for method, extra in (("sparse", ("--set", "samples=128")), ("mlp", ())):
        r = cli("fit", "--system", "double_pendulum", "--method", method, "--experiment", "indirect", "--train",
                folder / "train.csv", "--steps", 2, *extra, "--save", folder / f"{method}.npz")
        assert r.returncode == 0, r.stderr
        r = cli("predict", "--model", folder / f"{method}.npz", "--log", folder / "test.csv", "--out",
                folder / f"{method}.predicted.csv")
        assert r.returncode == 0, r.stderr
    return folder


def _torques(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def _reseal(header, entries: dict) -> None:
    """``header`` with the digest of its contents as they now are: a stranger who edits a file and seals it
    again, so that the checks past the digest are reached."""
    if isinstance(header, dict):
        arrays = {n[:-4]: np.load(io.BytesIO(d), allow_pickle=False) for n, d in entries.items()
                  if n != modelfile.HEADER}
        try:
            header["digest"] = modelfile.digest(header, arrays)
        except (TypeError, ValueError, RecursionError):  # a header json cannot write: left as it is
            pass


@contextlib.contextmanager
def _guard():
    def hang(*_):
        raise AssertionError(f"a model file held predict past {GUARD_S} s")
    previous = signal.signal(signal.SIGALRM, hang)
    signal.alarm(GUARD_S)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


#: each file's seconds in predict, for the closing figure (``-s`` prints the slowest; nothing asserts on it)
SECONDS: list[float] = []


@pytest.fixture(scope="module", autouse=True)
def _slowest():
    yield
    if SECONDS:
        print(f"\n{len(SECONDS)} files through predict; the slowest took {max(SECONDS):.3f} s")


def _predict(path: Path, log: Path, out: Path, same_as: Path | None = None, bound=None) -> None:
    """``bench predict`` on ``path``: it predicts, or says why not in one line with exit 2 and writes nothing.
    A prediction is finite, equals ``same_as``'s (the file before it was mutated) where given, and keeps
    ``bound`` (the original file's ``torque_bound``) where given."""
    if out.exists():
        out.unlink()
    err = io.StringIO()
    start = time.perf_counter()
    with _guard(), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli_main(["predict", "--model", str(path), "--log", str(log), "--out", str(out)])
    SECONDS.append(time.perf_counter() - start)
    if code == 0:
        assert out.exists()
        predicted = _torques(out)
        assert np.isfinite(predicted).all()
        if same_as is not None:
            np.testing.assert_array_equal(predicted, _torques(same_as))
        if bound is not None:
            assert (np.abs(predicted) <= np.asarray(bound)).all()
        _count("predicted")
        return
    _count("refused")
    lines = err.getvalue().strip().splitlines()
    assert code == 2 and len(lines) == 1 and str(path) in lines[0], (code, err.getvalue()[-500:])
    assert not out.exists()


def _count(outcome: str) -> None:
    """Count ``outcome`` in hypothesis' statistics, inside a hypothesis test."""
    try:
        event(outcome)
    except InvalidArgument:  # a crafted file, outside hypothesis
        pass


def _fuzz(**kwargs):
    return settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow], **kwargs)


@_fuzz()
@given(which=st.sampled_from(["sparse", "mlp"]), where=st.floats(0, 1), bit=st.integers(0, 7),
       cut=st.booleans())
def test_a_flipped_bit_or_a_cut_file_predicts_or_is_refused_in_one_line(saved, tmp_path, which, where, bit, cut):
    data = bytearray((saved / f"{which}.npz").read_bytes())
    at = min(int(where * len(data)), len(data) - 1)
    if cut:
        data = data[:at]
    else:
        data[at] ^= 1 << bit
    path = tmp_path / "m.npz"
    path.write_bytes(bytes(data))
    _predict(path, saved / "test.csv", tmp_path / "p.csv", same_as=saved / f"{which}.predicted.csv")


#: JSON values a stranger might put anywhere: numbers out of range, wrong types, deep and wide containers
_json = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10 ** 30, 10 ** 30), st.floats(allow_nan=True),
              st.text(max_size=20), st.sampled_from(["urdf:/etc/passwd", "measured:/etc/passwd", "kuka_lwr4",
                                                     "double_pendulum", "Pow", "Add", "linear", "hybrid"])),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=12)
#: expression trees a stranger might write: huge powers, deep nesting, wide sums, odd literals
_trees = st.one_of(
    st.builds(lambda b, e: {"op": "Pow", "args": [{"int": str(b)}, {"int": str(e)}]},
              st.integers(-10 ** 6, 10 ** 6), st.integers(-10 ** 12, 10 ** 12)),
    st.integers(1, 400).map(lambda d: _nest(d)),
    st.builds(lambda n: {"op": "Add", "args": [{"int": "7"}] * n}, st.integers(1, 300_000)),
    st.builds(lambda t: {"float": t}, st.sampled_from(["1e999", "nan", "-inf", "1" * 5000, "0x10", "1_0"])),
    st.builds(lambda p, q: {"rational": [p, q]}, st.text(max_size=30), st.sampled_from(["0", "1", "3", "x"])),
    _json)


def _nest(depth: int) -> dict:
    tree = {"symbol": "q_1"}
    for _ in range(depth):
        tree = {"op": "sin", "args": [tree]}
    return tree


#: where the crafted file 3,000 operations deep goes
DEEP = {"symbol": "DEEP"}


def _nest_text(depth: int) -> str:
    return '{"op": "sin", "args": [' * depth + '{"symbol": "q_1"}' + "]}" * depth


def _paths(node, path=()):
    """Every place in a JSON tree, as a path of keys and indices."""
    yield path
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, path + (i,))


def _replace(node, path, value):
    if not path:
        return value
    node[path[0]] = _replace(node[path[0]], path[1:], value)
    return node


@_fuzz()
@given(which=st.sampled_from(["sparse", "mlp"]), where=st.floats(0, 1), value=st.one_of(_json, _trees),
       sealed=st.booleans())
def test_a_mutated_header_or_expression_predicts_or_is_refused_in_one_line(saved, tmp_path, which, where, value,
                                                                             sealed):
    """A mutated file is refused by its digest, or predicts what it did; sealed again by the stranger, it is
    refused by the checks past the digest, or predicts finite torques within the original's bound."""
    source = saved / f"{which}.npz"
    with zipfile.ZipFile(source) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    header = json.loads(entries[modelfile.HEADER])
    bound = header["torque_bound"]
    places = list(_paths(header))
    header = _replace(header, places[min(int(where * len(places)), len(places) - 1)], value)
    if sealed:
        _reseal(header, entries)
    try:
        entries[modelfile.HEADER] = json.dumps(header).encode()
    except (ValueError, RecursionError):  # a value json cannot write is no file to read
        return
    path = tmp_path / "m.npz"
    with zipfile.ZipFile(path, "w") as z:
        for name, data in entries.items():
            z.writestr(name, data)
    same = None if sealed else saved / f"{which}.predicted.csv"
    _predict(path, saved / "test.csv", tmp_path / "p.csv", same_as=same, bound=bound)


def test_the_crafted_files_that_hung_or_crashed_predict_are_refused_in_one_line(saved, tmp_path):
    source = saved / "sparse.npz"
    with zipfile.ZipFile(source) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    base = json.loads(entries[modelfile.HEADER])

    def written(header: dict, name: str) -> Path:
        path = tmp_path / name
        _reseal(header, entries)  # past the digest: the checks of what it holds refuse it
        text = json.dumps(header).replace(json.dumps(DEEP), _nest_text(3000))  # deeper than json.dumps writes
        with zipfile.ZipFile(path, "w") as z:
            for n, data in entries.items():
                z.writestr(n, text.encode() if n == modelfile.HEADER else data)
        return path

    def expression(tree) -> dict:
        header = json.loads(json.dumps(base))
        places = [p for p in _paths(header["model"]) if p and p[-1] == "expression"] or \
                 [p for p in _paths(header["model"]) if p and isinstance(p[-1], int)]
        assert places, "the saved model holds an expression tree"
        _replace(header["model"], places[0], tree)
        return header

    cases = {
        "power.npz": expression({"op": "Pow", "args": [{"int": "10"}, {"int": "100000000"}]}),
        "deep.npz": expression(DEEP),
        "plugins.npz": {**base, "plugins": 5},
        "passwd.npz": {**base, "system": "urdf_passwd", "plugins": ["urdf:/etc/passwd"]},
        "dof.npz": {**base, "dof": 1},
    }
    for name, header in cases.items():
        err = io.StringIO()
        out = tmp_path / "p.csv"
        with _guard(), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli_main(["predict", "--model", str(written(header, name)), "--log", str(saved / "test.csv"),
                             "--out", str(out)])
        assert code == 2 and len(err.getvalue().strip().splitlines()) == 1 and not out.exists(), (name, err.getvalue())
    wide = saved / "mlp.npz"  # a network whose hyperparameters ask for 7 GB of weights the file does not hold
    with zipfile.ZipFile(wide) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    header = json.loads(entries[modelfile.HEADER])
    assert "hidden" in header["model"]["hyperparameters"]
    header["model"]["hyperparameters"]["hidden"] = 30_000
    err = io.StringIO()
    with _guard(), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli_main(["predict", "--model", str(written(header, "wide.npz")), "--log", str(saved / "test.csv"),
                         "--out", str(tmp_path / "p.csv")])
    assert code == 2 and "describe weights other than" in err.getvalue() and not (tmp_path / "p.csv").exists()
    corrupt = bytearray(source.read_bytes())  # a deflated entry whose bytes no longer inflate: zlib's error
    with zipfile.ZipFile(source) as z:
        info = z.getinfo(modelfile.HEADER)
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    corrupt[start:start + 8] = b"\xff" * 8
    (tmp_path / "zlib.npz").write_bytes(bytes(corrupt))
    _predict(tmp_path / "zlib.npz", saved / "test.csv", tmp_path / "p.csv")
