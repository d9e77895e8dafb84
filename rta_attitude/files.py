"""Output files that are whole or absent: checked directories and atomic writes.

Every command that writes files checks its output location before it starts work
(`output_dir`, `output_file`: created if missing, probed by writing one byte), and writes each file
through `atomic`: into a temporary file next to it, renamed over the target only once complete, so
a full disk or an unwritable directory never leaves a half-written file under the final name. Every
failure is an `OutputError` with one line naming the path and the operating system's reason.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from rta_attitude.errors import OutputError


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def output_dir(path: Path, option: str = "--out") -> Path:
    """Create `path` (and its parents) if needed and check that a file can be written in it.

    Raises:
        OutputError: it is a file, cannot be created, or is not writable (read-only, full disk).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{option} {path}: is a file, not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot create the directory ({_reason(exc)})") from None
    _probe(path, option, path)
    return path


def output_file(path: Path, option: str, overwrite: bool = True) -> Path:
    """Check that `path` can be written as a new file: not a directory, its directory exists (created
    if missing) and is writable; with overwrite False, not an existing file.

    Raises:
        OutputError: any of these fails.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{option} {path}: is a directory, not a file")
    if path.exists() and not overwrite:
        raise OutputError(f"{option} {path}: exists")
    if path.parent.exists() and not path.parent.is_dir():
        raise OutputError(f"{option} {path}: {path.parent} is not a directory")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {path}: cannot create directory {path.parent} ({_reason(exc)})") from None
    _probe(path.parent, option, path)
    return path


def _probe(directory: Path, option: str, shown: Path) -> None:
    probe = directory / f".rta_attitude_probe_{os.getpid()}"
    try:
        with probe.open("wb") as f:
            f.write(b"\0")
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise OutputError(f"{option} {shown}: cannot write in {directory} ({_reason(exc)})") from None
    finally:
        try:
            probe.unlink()
        except OSError:
            pass


@contextmanager
def atomic(path: Path) -> Iterator[Path]:
    """Yield a temporary path in `path`'s directory (same suffix, so writers that pick a format by
    extension work); on success it replaces `path`, on any failure it is removed.

    Raises:
        OutputError: writing or renaming failed (an OSError inside the block).
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({_reason(exc)})") from None
    finally:
        try:
            tmp.unlink()
        except OSError:
            pass


def write_text(path: Path, text: str) -> Path:
    """Write a text file atomically. Returns the path.

    Raises:
        OutputError: it could not be written (nothing is left under `path` then).
    """
    with atomic(path) as tmp:
        tmp.write_text(text)
    return Path(path)


__all__ = ["atomic", "output_dir", "output_file", "write_text"]
