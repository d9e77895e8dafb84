"""Keeps numba's on-disk cache of the compiled kernels consistent across source changes.

numba invalidates a cached function when its own source file changes, but not when a function it
calls from another file changes: after an edit of `filter/active_set.py` (or a `git pull` that
brings one), `filter/qp.py`'s cache would still hold the old solver, linked in, and run it (or
crash when Python calls the new one: "NRT_adapt_ndarray_to_python: 'descr' is NULL", seen here).
`drop_stale_caches` hashes the sources of every module with kernels and, when the hash differs from
the one recorded next to the caches, deletes those modules' cache files so everything recompiles
together.

Nothing runs at import: the entry points that compile or load kernels call it first (`AsifFilter`,
the plant node, every `rta-attitude` command (cli.main), the Monte Carlo's `run_runs` and
`sample_initial_states`, the test session). A fresh installation has no cache, so only a developer who
edits kernel sources and then calls a kernel without one of those entry points can meet a stale cache
(a script calling `run_runs` after an edit of the backup law, not through an entry point, would).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

STAMP_NAME = "rta_kernels.sha256"
PACKAGE_DIR = Path(__file__).resolve().parent


def kernel_modules(package_dir: Path = PACKAGE_DIR) -> list[Path]:
    """The package's source files that define numba kernels (they mention `numba.`), sorted."""
    out = []
    for path in sorted(package_dir.rglob("*.py")):
        try:
            if "numba." in path.read_text(errors="replace"):
                out.append(path)
        except OSError:
            continue
    return out


def drop_stale_caches(package_dir: Path = PACKAGE_DIR) -> bool:
    """Delete the kernels' numba cache files (<folder>/__pycache__/<module>.*.nbi/.nbc) if any kernel
    source changed since they were written. Returns True if files were deleted. Does nothing where the
    package directory is not writable (numba then caches elsewhere and recompiles after any change of
    the package files' stamps)."""
    modules = kernel_modules(package_dir)
    digest = hashlib.sha256()
    for path in modules:
        digest.update(str(path.relative_to(package_dir)).encode())
        digest.update(path.read_bytes())
    stamp = package_dir / "__pycache__" / STAMP_NAME
    try:
        if stamp.read_text() == digest.hexdigest():
            return False
    except OSError:
        pass
    dropped = False
    try:
        for path in modules:
            cache = path.parent / "__pycache__"
            for f in list(cache.glob(f"{path.stem}.*.nbi")) + list(cache.glob(f"{path.stem}.*.nbc")):
                f.unlink(missing_ok=True)
                dropped = True
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(digest.hexdigest())
        tmp.replace(stamp)  # atomic: concurrent processes read a whole stamp or none
    except OSError:
        return dropped
    return dropped


__all__ = ["PACKAGE_DIR", "STAMP_NAME", "drop_stale_caches", "kernel_modules"]
