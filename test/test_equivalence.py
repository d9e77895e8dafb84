"""The default and paper configurations compute what they computed when test/data/equivalence.json was
recorded (test/equivalence.py): filter answers, `simulate` trajectories and Monte Carlo runs, bit for bit.

Recorded at 2a433b1, before the pointing constraints became data (the cone table, the registry): a pure
refactor of the paper's constraints keeps every digest. The 1,000-run campaigns of seed 7 are kept per run in
test/data/equivalence_runs_*.csv and compared by hand (`test/equivalence.py check-runs`): 5 minutes here."""

from __future__ import annotations

import json
from pathlib import Path

from equivalence import record

DATA = Path(__file__).parent / "data" / "equivalence.json"


def test_default_and_paper_configurations_compute_what_they_did_bit_for_bit() -> None:
    recorded = json.loads(DATA.read_text())
    assert recorded["commit"] == "2a433b1"
    now = record()
    assert sorted(now) == sorted(recorded["records"])
    differ = [k for k in now if now[k] != recorded["records"][k]]
    assert not differ, f"records that changed: {differ}"
