"""The library's documented example runs: examples/your_controller.py (docs/api.md's thirty lines) ends SAFE,
and the code block of docs/api.md is the example's loop."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_your_controller_runs_and_the_filter_keeps_every_constraint() -> None:
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "your_controller.py")], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "SAFE"
    lines = {line.split()[0]: line for line in r.stdout.splitlines()[:-1]}
    assert "exclusion_zone" in lines and "deg" in lines["exclusion_zone"]


def test_the_doc_shows_the_examples_calls() -> None:
    doc = (ROOT / "docs" / "api.md").read_text()
    example = (ROOT / "examples" / "your_controller.py").read_text()
    for call in ("asif.filter(x, u_des, t).u", "plant.step(u)", "make_state([0.0, 0.0, 0.0, 1.0]",
                 "u_des = tau / (cfg.spacecraft.torque_sign * D)"):
        assert call in doc and call in example, call
