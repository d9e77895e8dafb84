"""Viability oracle, independent of the filter: from a state and a horizon, is there a command
sequence in U (zero-order hold, the plant's RK4 substeps) that keeps every enforced constraint at
every sample and substep? Answers "recoverable" with a witness, "no witness found" (proves nothing)
or "unrecoverable" when a rule proves it (docs/viability.md).

- `params`: the oracle's parameters from the Config; `model`: its casadi model, exact re-simulation
  and constraint values; `rules`: the proofs; `laws`: warm-start laws; `transcription`: the
  multiple-shooting NLP and its compiled derivative blocks; `search`: `find_witness`; `result`.

casadi is imported by the submodules that need it; importing this package loads it (not at the
import of the rest of rta_attitude: the CLI imports it in `run`).
"""

from __future__ import annotations

from rta_attitude.viability.result import NO_WITNESS, RECOVERABLE, UNRECOVERABLE, VERDICTS, Result, format_table
from rta_attitude.viability.search import find_witness

__all__ = ["NO_WITNESS", "RECOVERABLE", "UNRECOVERABLE", "VERDICTS", "Result", "find_witness", "format_table"]
