"""Output files that are whole or absent: checked directories and atomic writes.

Every command that writes files checks its output location before it starts work
(`output_dir`, `output_file`: created if missing, probed by writing one byte), and writes each file
through `atomic`: into a temporary file next to it, renamed over the target only once complete, so
a full disk or an unwritable directory never leaves a half-written file under the final name. A
command that fails leaves no empty folder either: `output_dir` removes what it created when its probe
fails, and `output_folder` (a command's whole work) removes the folders it created that are still
empty when the work fails. Every failure is an `OutputError` with one line naming the path and the
operating system's reason.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from rta_attitude.errors import OutputError


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _missing(path: Path) -> list[Path]:
    """path and those of its ancestors that do not exist (not even as a link), deepest first."""
    out = []
    p = path
    while not (p.exists() or p.is_symlink()) and p != p.parent:
        out.append(p)
        p = p.parent
    return out


def _remove_empty(created: list[Path]) -> None:
    """Remove the directories of `created` (deepest first) while they are empty."""
    for d in created:
        try:
            d.rmdir()
        except OSError:  # not empty (or gone): it and its parents stay
            return


def output_dir(path: Path, option: str = "--out") -> Path:
    """Create `path` (and its parents) if needed and check that a file can be written in it; on failure
    the directories it created are removed again.

    Raises:
        OutputError: it is a file, cannot be created, or is not writable (read-only, full disk).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{option} {path}: is a file, not a directory")
    created = _missing(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _remove_empty(created)
        raise OutputError(f"{option} {path}: cannot create the directory ({_reason(exc)})") from None
    try:
        _probe(path, option, path)
    except OutputError:
        _remove_empty(created)
        raise
    return path


@contextmanager
def output_folder(path: Path, option: str = "--out") -> Iterator[Path]:
    """`output_dir` around a command's work: yields the checked directory, and if the block raises
    (an error or an interrupt), removes the directories this call created that are still empty, so a
    failed command leaves no empty folder behind. Whole files written before the failure stay.

    Raises:
        OutputError: as `output_dir`.
    """
    path = Path(path)
    created = _missing(path)
    output_dir(path, option)
    try:
        yield path
    except BaseException:
        _remove_empty(created)
        raise


def output_file(path: Path, option: str, overwrite: bool = True) -> Path:
    """Check that `path` can be written as a new file: not a directory, its directory exists (created
    if missing, and removed again if the check fails) and is writable; with overwrite False, not an
    existing file.

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
    created = _missing(path.parent)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _remove_empty(created)
        raise OutputError(f"{option} {path}: cannot create directory {path.parent} ({_reason(exc)})") from None
    try:
        _probe(path.parent, option, path)
    except OutputError:
        _remove_empty(created)
        raise
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


__all__ = ["atomic", "output_dir", "output_file", "output_folder", "write_text"]
