"""Keeps numba's on-disk cache of the compiled kernels consistent across source changes.

numba invalidates a cached function when its own source file changes, but not when a function it
calls from another file changes: after an edit to `active_set.py` (or a `git pull` that brings
one), `filter_kernel`'s cache would still hold the old solver, linked in, and run it (or crash
when Python calls the new one: "NRT_adapt_ndarray_to_python: 'descr' is NULL", seen here).
`drop_stale_caches` hashes the kernel sources and, when the hash differs from the one recorded
next to the cache, deletes the kernels' cache files so everything recompiles together. It runs
on package import, before any kernel is called (numba reads its cache at the first call).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

KERNEL_MODULES: tuple[str, ...] = ("active_set", "barrier_rows", "filter_kernel", "plant_kernel")
"""Modules with numba kernels that call each other."""
STAMP_NAME = "rta_kernels.sha256"


def drop_stale_caches(package_dir: Path | None = None) -> bool:
    """Delete the kernels' numba cache files (<package>/__pycache__/<module>.*.nbi/.nbc) if the
    kernel sources changed since they were written. Returns True if files were deleted.
    Does nothing where the cache directory is not writable (numba then caches elsewhere and
    recompiles after any change of the package files' stamps)."""
    here = package_dir or Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in KERNEL_MODULES:
        try:
            digest.update((here / f"{name}.py").read_bytes())
        except OSError:
            return False
    cache = here / "__pycache__"
    stamp = cache / STAMP_NAME
    try:
        if stamp.read_text() == digest.hexdigest():
            return False
    except OSError:
        pass
    dropped = False
    try:
        cache.mkdir(exist_ok=True)
        for name in KERNEL_MODULES:
            for f in list(cache.glob(f"{name}.*.nbi")) + list(cache.glob(f"{name}.*.nbc")):
                f.unlink(missing_ok=True)
                dropped = True
        tmp = stamp.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(digest.hexdigest())
        tmp.replace(stamp)  # atomic: concurrent processes read a whole stamp or none
    except OSError:
        return dropped
    return dropped


__all__ = ["KERNEL_MODULES", "drop_stale_caches"]
