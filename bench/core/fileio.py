"""Files: atomic writes (a reader never sees a partial file, and a killed
writer leaves nothing behind for good), and checks of output paths before
any work starts."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Callable, IO

from bench.core.errors import UserError
from bench.core.processes import process_alive


def atomic_write(path: str | os.PathLike, write: Callable[[IO], Any], *, binary: bool = False) -> None:
    """Call ``write(f)`` on a temporary file beside ``path``, then rename it into place.

    On any error the temporary file is removed and ``path`` is left as it
    was. The temporary file's name carries the writer's process id, so that
    the next write of ``path`` removes what a killed writer left. The file's
    bytes are synced to disk before the rename and the folder's entry after
    it, so that a power loss leaves the old file or the whole new one, never
    an empty one.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        with os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"newline": ""})) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        _sync_folder(path.parent)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _sync_folder(folder: Path) -> None:
    """Sync ``folder``'s entries to disk, where the system lets a folder be opened for it."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def remove_leftovers(path: Path) -> None:
    """Remove temporary files of ``path`` whose writer is no longer running."""
    pattern = re.compile(re.escape(f".{path.name}.") + r"(\d+)\..*\.tmp$")
    try:
        names = os.listdir(path.parent)
    except OSError:
        return
    for name in names:
        m = pattern.match(name)
        if m and not process_alive(int(m.group(1))):
            try:
                os.unlink(path.parent / name)
            except OSError:
                pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def link(target: str | os.PathLike, page: str | os.PathLike) -> str:
    """``target`` as a relative markdown link from the page at ``page``, wherever the page is written."""
    return Path(os.path.relpath(Path(target).resolve(), Path(page).resolve().parent)).as_posix()


def write_json(path: str | os.PathLike, obj: Any) -> None:
    atomic_write(path, lambda f: (json.dump(obj, f, indent=1, allow_nan=True), f.write("\n")))


def check_output(path: str | os.PathLike, *, folder: bool = False) -> Path:
    """``path`` if the suite can write a file (or, with ``folder``, a folder)
    there; :class:`UserError` in one line otherwise, before any work starts.

    Refused: a file path that is an existing folder (or a folder path that is
    an existing file), a path under an existing file, and a folder that
    cannot be written.
    """
    path = Path(path)
    if path.exists():
        if folder and not path.is_dir():
            raise UserError(f"{path}: is a file, not a folder")
        if not folder and path.is_dir():
            raise UserError(f"{path}: is a folder, not a file")
    parent = path if folder and path.is_dir() else path.parent
    ancestor = parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise UserError(f"{path}: cannot be written, {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise UserError(f"{path}: cannot be written, {ancestor} is not writable ({os.strerror(errno.EACCES)})")
    return path


def file_digest(path: str | os.PathLike) -> str:
    """The sha256 of a file's bytes, in hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


#: what a converted CSV's sidecar is named after: ``OUT.csv`` -> ``OUT.csv.convert.json``
SETTINGS_SUFFIX = ".convert.json"


def settings_path(csv: str | os.PathLike) -> Path:
    """Where ``convert`` writes the settings a CSV was made with (beside it)."""
    return Path(str(csv) + SETTINGS_SUFFIX)


def read_settings(csv: str | os.PathLike) -> dict | None:
    """The settings ``convert`` wrote beside ``csv`` (:func:`settings_path`);
    ``None`` where there are none or they are unreadable."""
    try:
        return json.loads(settings_path(csv).read_text())
    except (OSError, ValueError):
        return None
