"""The suite's data format on disk: a CSV file.

The columns::

    q_1..q_n, qd_1..qd_n, qdd_1..qdd_n, tau_1..tau_n[, L][, trajectory[, recording]][, time][, sign_qd_1..sign_qd_n]

``trajectory`` and ``recording`` are optional labels (any non-empty text).
Measured data come in recordings, and neighbouring samples of one recording
are near copies; a robot also repeats an excitation trajectory, and a
recording of the same trajectory again is a near copy of the first. So
whatever is validated on held-out data holds out whole *trajectories*, every
recording of one trajectory together (:meth:`Dataset.trajectories`):

* ``trajectory`` alone names each sample's recording, which is then a
  trajectory of its own (the DFKI recordings, DeLaN's characters);
* ``trajectory`` with ``recording`` names the trajectory a recording
  follows and the recording itself (the KUKA's runs 1 and 2 repeat one
  trajectory);
* ``recording`` alone is refused: recordings whose trajectories are not
  named cannot be held out honestly.

Generated samples are independent and have none of these.

``time`` is optional: each sample's time in its recording, in seconds. The
driven rollouts of measured data (:mod:`bench.evaluation.driven`) need it.

``sign_qd_i`` is optional too: the sign of joint i's velocity as the
torque's low-pass saw it. Where a recording's torque was filtered
(:func:`bench.core.recordings.preprocess`), Coulomb friction's jump at
``qd = 0`` reaches the samples rounded off over the filter's span, and a
model whose friction column is ``sign(qd)`` fits that rounding with a
steeper viscous slope. The converter therefore puts ``sign(qd)`` through the
same filter at the full rate (parallel filtering) and writes it here; every
term's torque that contains ``sign(qd_i)`` uses it
(:meth:`Dataset.velocity_sign`). Without these columns it is ``sign(qd)``.

Further columns (time stamps, labels) are allowed and ignored. The same
format serves generated and measured data, so any method can be given
measured data.
"""

from __future__ import annotations

import os
from collections import Counter
import re
import warnings
from pathlib import Path

import numpy as np

from bench.core.data import Dataset
from bench.core.errors import DataError
from bench.core.fileio import atomic_write

_COLUMN = re.compile(r"^(q|qd|qdd|tau)_(\d+)$")
#: the optional column naming each sample's trajectory (alone: its recording, a trajectory of its own)
TRAJECTORY = "trajectory"
#: the optional column naming each sample's recording, beside :data:`TRAJECTORY`
RECORDING = "recording"
#: the optional column of each sample's time in its recording, s
TIME = "time"
#: the optional columns ``sign_qd_1..sign_qd_n`` (:attr:`Dataset.sign_qd`)
SIGN = "sign_qd"


def columns(dof: int, with_L: bool) -> list[str]:
    cols = [f"{k}_{i}" for k in ("q", "qd", "qdd", "tau") for i in range(1, dof + 1)]
    return cols + (["L"] if with_L else [])


def write_csv(data: Dataset, path: str | os.PathLike) -> None:
    """Write ``data`` in the suite's CSV format, atomically (no partial file)."""
    import pandas as pd

    arrays = {}
    for k in ("q", "qd", "qdd", "tau"):
        for i in range(data.dof):
            arrays[f"{k}_{i + 1}"] = getattr(data, k)[:, i]
    if data.L is not None:
        arrays["L"] = data.L
    if data.recording is not None:
        arrays[TRAJECTORY] = data.trajectory_labels()
        if data.trajectory is not None:
            arrays[RECORDING] = data.recording
    if data.time is not None:
        arrays[TIME] = data.time
    if data.sign_qd is not None:
        for i in range(data.dof):
            arrays[f"{SIGN}_{i + 1}"] = data.sign_qd[:, i]
    frame = pd.DataFrame(arrays)
    atomic_write(Path(path), lambda f: frame.to_csv(f, index=False, float_format="%.17g"))


#: the separators besides the comma that a CSV file may use, tried in turn where its header has no comma:
#: a semicolon, a tab, or any run of spaces and tabs (a logger's aligned columns), each by pandas' reader
OTHER_SEPARATORS = (";", "\t", r"\s+")
#: how an error names the separators it tried
SEPARATOR_NAMES = {",": "comma", ";": "semicolon", "\t": "tab", r"\s+": "whitespace"}


#: the most columns a log's header may have: a robot's logger writes a few per joint and signal, and a header
#: far wider is not a log (it is read before the rows, in time linear in its width, and refused)
MAX_COLUMNS = 10_000


def header_width(path: Path, limit: int = 1 << 22) -> int:
    """The most fields the first line of ``path`` (its first ``limit`` bytes, decompressed as pandas would by
    its name's suffix) splits into under any of the separators a log may use: read as bytes, in time linear in
    its length, before pandas parses it (which takes seconds on a header of 300,000 names)."""
    import pandas as pd

    with pd.io.common.get_handle(path, "rb", compression="infer", is_text=False) as handle:
        line = handle.handle.readline(limit)
    return max(line.count(b",") + 1, line.count(b";") + 1, line.count(b"\t") + 1, len(line.split()))


def read_frame(path: Path, nrows: int | None = None):
    """A CSV file (optionally compressed) as a DataFrame with at least one row,
    two columns or more (at most :data:`MAX_COLUMNS`) and distinct column names (its first ``nrows`` rows
    only, where given); :class:`DataError` naming the file otherwise. A file
    whose header is one name holding semicolons, tabs or spaces is read with
    that separator (a spreadsheet's export in a locale whose decimal mark is
    the comma; a logger's space-separated columns, CRLF line ends included);
    a header that stays one column is refused naming the separators tried."""
    import pandas as pd

    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path}: is a folder, not a file")
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    width = header_width(path)
    if width > MAX_COLUMNS:
        raise DataError(f"{path}: its header has {width:,} columns or more, more than the {MAX_COLUMNS:,} a log may have")
    try:
        header = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False)
        sep = ","
        if header.shape[1] == 1 and len(header):
            for other in OTHER_SEPARATORS:
                split = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False, sep=other)
                if split.shape[1] > 1:
                    sep, header = other, split
                    break
            else:
                tried = ", ".join(SEPARATOR_NAMES[s] for s in (",", *OTHER_SEPARATORS))
                raise DataError(f"{path}: its header reads as one column ({str(header.iloc[0, 0]).strip()!r:.60}); "
                                f"tried the separators {tried}")
        with warnings.catch_warnings():
            # rows one field wider than the header: pandas would take their first field as an index and shift
            # every other one a column left (index_col=False), or drop a field and warn; both are refused
            warnings.simplefilter("error", pd.errors.ParserWarning)
            frame = pd.read_csv(path, nrows=nrows, sep=sep, index_col=False)
    except pd.errors.EmptyDataError:
        raise DataError(f"{path}: the file is empty") from None
    except pd.errors.ParserWarning:
        raise DataError(f"{path}: not a readable CSV file (some rows have more fields than its header has "
                        f"names)") from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError, EOFError, OSError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{path}: not a readable CSV file ({first})") from None
    names = [str(v).strip() for v in header.iloc[0]] if len(header) else []
    repeated = sorted(n for n, k in Counter(names).items() if k > 1)
    if repeated:
        raise DataError(f"{path}: column name(s) {', '.join(map(repr, repeated))} appear more than once")
    if len(frame) == 0:
        raise DataError(f"{path}: the file has a header but no rows")
    _check_widths(path, sep, len(names), nrows)
    if sep != ",":  # spaces around a name beside a semicolon or tab (" \t ") are not part of it
        frame.columns = [str(c).strip() for c in frame.columns]
    return frame


def _check_widths(path: Path, sep: str, width: int, nrows: int | None) -> None:
    """:class:`DataError` naming the first data row (of the first ``nrows``) with fewer fields than the header's
    ``width``: pandas fills the fields it lacks with empty values, so a row that lost a field reads shifted
    a column left wherever the columns past it are not read.

    The fields are counted with NumPy over the file's bytes (each line's separators) where no field is
    quoted, about four times faster than Python's ``csv`` on a log of 70,000 rows and 30 columns. Quoted fields are counted by ``csv`` (a quoted separator is no separator), a whitespace-separated log by
    ``str.split``."""
    import pandas as pd

    with pd.io.common.get_handle(path, "rb", compression="infer", is_text=False) as handle:
        raw = handle.handle.read() if nrows is None else _first_lines(handle.handle, nrows + 1)
    if sep in (",", ";", "\t") and b'"' not in raw:
        counts = _separators_per_line(raw, ord(sep))
    else:
        import csv
        import io

        lines = io.StringIO(raw.decode("utf-8", errors="replace"))
        rows = (line.split() for line in lines) if sep == r"\s+" else csv.reader(lines, delimiter=sep)
        counts = np.array([len(f) - 1 if f and f != [""] else -1 for f in rows], dtype=np.int64)
    counts = counts[counts >= 0][1:]  # blank lines are skipped (pandas skips them too), then the header
    if nrows is not None:
        counts = counts[:nrows]
    short = np.flatnonzero(counts + 1 < width)
    if short.size:
        row = int(short[0])
        raise DataError(f"{path}: data row {row + 1} has {int(counts[row]) + 1} fields, where its header names "
                        f"{width} columns (a field lost from the row would shift the ones after it)")


def _first_lines(lines, count: int) -> bytes:
    """The lines of a file up to its ``count``-th that is not blank (a header read, ``nrows``, reads no more)."""
    kept, filled = [], 0
    for line in lines:
        kept.append(line)
        filled += bool(line.strip())
        if filled >= count:
            break
    return b"".join(kept)


def _separators_per_line(raw: bytes, sep: int) -> np.ndarray:
    """Each line's count of the byte ``sep``, -1 for a blank line (nothing but a line end)."""
    buf = np.frombuffer(raw, dtype=np.uint8)
    ends = np.flatnonzero(buf == 10)
    starts = np.concatenate(([0], ends + 1))
    ends = np.concatenate((ends, [buf.size]))
    length = ends - starts - (buf[np.maximum(ends - 1, 0)] == 13) * (ends > starts)  # a CRLF's CR is no content
    hits = np.flatnonzero(buf == sep)
    counts = np.searchsorted(hits, ends) - np.searchsorted(hits, starts)
    return np.where(length > 0, counts, -1)


#: the largest magnitude a value read from a file may have: its square stays finite,
#: so that least squares on it cannot overflow
MAX_ABS_VALUE = float(np.sqrt(np.finfo(np.float64).max))


def numeric_column(frame, col: str, path: Path) -> np.ndarray:
    """Column ``col`` as float64; :class:`DataError` naming the file, column and
    data row of the first non-numeric, NaN, empty or infinite value, or of a
    value whose square would overflow (above :data:`MAX_ABS_VALUE`)."""
    import pandas as pd

    values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=np.float64)
    bad_text = np.isnan(values) & frame[col].notna().to_numpy()
    if bad_text.any():
        row = int(np.flatnonzero(bad_text)[0])
        raise DataError(f"{path}: column {col} has a non-numeric value {frame[col].iloc[row]!r} in data row {row + 1}")
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        what = "NaN or empty" if np.isnan(values[row]) else "inf"
        raise DataError(f"{path}: column {col} has a {what} value in data row {row + 1}")
    huge = np.abs(values) > MAX_ABS_VALUE
    if huge.any():
        row = int(np.flatnonzero(huge)[0])
        raise DataError(f"{path}: column {col} has a value too large to compute with ({values[row]:g}, above "
                        f"{MAX_ABS_VALUE:.3g}) in data row {row + 1}")
    return values


def read_csv(path: str | os.PathLike, *, dof: int | None = None, system: str | None = None,
             torque_optional: bool = False, states_only: bool = False) -> Dataset:
    """Load a CSV in the suite's format, checking it thoroughly. With
    ``torque_optional``, a file without ``tau_i`` columns is read with zero
    torques and ``meta["no_torque"]`` set (states to predict the torques of);
    with ``states_only``, any ``tau_i`` columns are not read at all (states a
    choice may look at, where their torques must not inform it).

    Raises :class:`DataError` with a one-line message naming the file and the
    problem for: an unreadable or empty file, missing columns, a number of
    degrees of freedom other than ``dof``, non-numeric, NaN or infinite values.
    """
    path = Path(path)
    frame = read_frame(path)

    found: dict[str, set[int]] = {k: set() for k in ("q", "qd", "qdd", "tau")}
    for col in frame.columns:
        m = _COLUMN.match(str(col).strip())
        if m:
            found[m.group(1)].add(int(m.group(2)))
    file_dof = max((max(v) for v in found.values() if v), default=0)
    if file_dof == 0:
        raise DataError(f"{path}: no q_1 column; expected columns {', '.join(columns(dof or 1, False))}")
    if dof is not None and file_dof != dof:
        who = f"system {system!r}" if system else "the model"
        raise DataError(f"{path}: the file has {file_dof} degrees of freedom (q_1..q_{file_dof}) but {who} has {dof}")
    need = columns(file_dof, False)
    no_torque = states_only or (torque_optional and not found["tau"])
    missing = [c for c in need if c not in frame.columns and not (no_torque and c.startswith("tau_"))]
    if missing:
        raise DataError(f"{path}: missing column(s) {', '.join(missing)}")

    def numeric(col: str) -> np.ndarray:
        return numeric_column(frame, col, path)

    arrays = {k: np.stack([numeric(f"{k}_{i}") for i in range(1, file_dof + 1)], axis=1) for k in found
              if not (no_torque and k == "tau")}
    if no_torque:
        arrays["tau"] = np.zeros_like(arrays["q"])
    L = numeric("L") if "L" in frame.columns else None
    trajectory = label_column(frame, TRAJECTORY, path) if TRAJECTORY in frame.columns else None
    recording = label_column(frame, RECORDING, path) if RECORDING in frame.columns else None
    if recording is None:  # the trajectory column alone: each recording a trajectory of its own
        recording, trajectory = trajectory, None
    elif trajectory is None:
        raise DataError(f"{path}: recordings {', '.join(list(dict.fromkeys(map(str, recording)))[:4])} (column {RECORDING}) name no "
                        f"trajectory (column {TRAJECTORY}): say which trajectory each follows, e.g. with "
                        f"bench convert --trajectory NAME")
    else:
        _check_nesting(recording, trajectory, path)
    time = numeric("time") if TIME in frame.columns else None
    signs = [f"{SIGN}_{i}" for i in range(1, file_dof + 1)]
    present = [c for c in signs if c in frame.columns]
    if present and len(present) < len(signs):
        raise DataError(f"{path}: has {', '.join(present)} but not {', '.join(c for c in signs if c not in present)} "
                        f"(the filtered velocity signs come for every joint or for none)")
    sign_qd = np.stack([numeric(c) for c in signs], axis=1) if present else None
    return Dataset(arrays["q"], arrays["qd"], arrays["qdd"], arrays["tau"], L, system, str(path), recording=recording,
                   sign_qd=sign_qd, trajectory=trajectory, time=time, meta={"no_torque": True} if no_torque else {})


def _check_nesting(recording: np.ndarray, trajectory: np.ndarray, path: Path) -> None:
    """Each recording follows one trajectory; :class:`DataError` naming the first that follows two."""
    pairs = np.unique(np.stack([recording, trajectory], axis=1), axis=0)
    names, counts = np.unique(pairs[:, 0], return_counts=True)
    if np.any(counts > 1):
        name = str(names[counts > 1][0])
        both = sorted(str(t) for r, t in pairs if r == name)
        raise DataError(f"{path}: recording {name!r} is labelled with two trajectories ({', '.join(both)}) in column "
                        f"{TRAJECTORY}; a recording follows one trajectory")


def label_column(frame, col: str, path: Path) -> np.ndarray:
    """Column ``col`` as text labels; :class:`DataError` naming the file, column
    and data row of the first empty value."""
    raw = frame[col]
    empty = raw.isna().to_numpy() | (raw.astype(str).str.strip() == "").to_numpy()
    if empty.any():
        row = int(np.flatnonzero(empty)[0])
        raise DataError(f"{path}: column {col} has an empty value in data row {row + 1}")
    return raw.astype(str).str.strip().to_numpy(dtype=str)


