"""How the package's kernels are compiled: the numba options, in one place.

- `JIT`: kernels that allocate (numpy arrays created inside): numba's reference-counting runtime on.
- `LEAF`: kernels that only read and write the arrays they are given (most of the physics, the
  barriers and the QP steps): compiled without numba's runtime (`_nrt=False`). numba otherwise
  increments and decrements the reference count of every array argument with atomic instructions at
  each call of a function it could not inline, about 20 ns per array on this project's machines
  (numba/numba#2345: "disable _nrt would fix it"); the plant's derivative, called 40 times a step,
  spent more time there than in its arithmetic. A LEAF kernel that tries to allocate fails to compile
  (the error names it), so the split cannot go wrong silently. docs/decisions.md, "compiled kernels".

Both cache to disk (`cache=True`; `kernel_cache` keeps the caches consistent across source edits) and
use numpy's error model (a division by zero gives inf/NaN, as in numpy, instead of raising).
"""

from __future__ import annotations

from typing import Any

JIT: dict[str, Any] = {"cache": True, "error_model": "numpy"}
LEAF: dict[str, Any] = {**JIT, "_nrt": False}

__all__ = ["JIT", "LEAF"]
