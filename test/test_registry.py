"""Constraints are data: no pointing constraint's name is spelled in the package's code (only in the default
YAML), no boresight is a literal in a kernel, and every consumer names the rows as the registry does."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import yaml

from rta_attitude import config
from rta_attitude.constraints import ConstraintSet
from rta_attitude.constraints.registry import registry

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rta_attitude"


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the docstring nodes of a module, its classes and functions (and the strings after an
    assignment, the attribute docstrings of this codebase)."""
    out: set[int] = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        for stmt in body:
            value = stmt.value if isinstance(stmt, ast.Expr) else None
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                out.add(id(value))
    return out


def _spellings(path: Path, name: str) -> list[str]:
    """Where the code of one file spells `name`: string constants (not docstrings) holding it as a word,
    identifiers and attributes that contain it."""
    tree = ast.parse(path.read_text(), str(path))
    docs = _docstrings(tree)
    word = re.compile(rf"\b{re.escape(name)}\b")
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            if word.search(node.value):
                hits.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.value[:60]!r}")
        elif ((isinstance(node, ast.Name) and name in node.id)
              or (isinstance(node, ast.Attribute) and name in node.attr)):
            hits.append(f"{path.relative_to(ROOT)}:{node.lineno} identifier")
    return hits


def test_no_pointing_constraint_name_is_spelled_in_the_package() -> None:
    doc = yaml.safe_load((ROOT / "config" / "rta_attitude.yaml").read_text())
    names = list(doc["/**"]["ros__parameters"]["constraints"]["pointing"])
    assert names == ["exclusion_zone", "communication"]  # the paper's two, named in the YAML only
    hits = [h for path in sorted(PACKAGE.rglob("*.py")) for n in names for h in _spellings(path, n)]
    assert not hits, hits


def test_the_spelling_check_finds_a_spelling() -> None:
    """The check above can fail: it finds a name spelled in code and ignores it in a docstring."""
    import tempfile

    with tempfile.NamedTemporaryFile("w", suffix=".py", dir=ROOT / "test", delete=True) as fh:
        fh.write('"""About exclusion_zone."""\nx = cfg.gains("exclusion_zone")\nexclusion_zone_row = 0\n')
        fh.flush()
        hits = _spellings(Path(fh.name), "exclusion_zone")
    assert len(hits) == 2


def test_no_boresight_literal_in_a_kernel() -> None:
    literal = re.compile(r"pointing\(\s*-?[01]\.0\s*,\s*-?[01]\.0\s*,\s*-?[01]\.0")
    hits = [f"{p.relative_to(ROOT)}" for p in PACKAGE.rglob("*.py") if literal.search(p.read_text())]
    assert not hits, hits


def test_every_consumer_names_the_rows_as_the_registry_does() -> None:
    import dataclasses
    import math

    from rta_attitude.config.schema import PointingConstraint
    from rta_attitude.filter.asif import AsifFilter

    base = config.load()
    tracker = PointingConstraint("star_tracker", "keep_out", (0.0, 0.0, -1.0), "earth", math.radians(30.0),
                                 base.pointing[0].gains)
    cfg = dataclasses.replace(base, pointing=(*base.pointing, tracker))
    reg = registry(cfg)
    assert reg.names == cfg.constraint_names
    assert reg.names[:3] == ("exclusion_zone", "communication", "star_tracker")
    assert [c.row for c in reg] == list(range(len(reg)))
    assert reg["star_tracker"].unit == "rad" and reg["star_tracker"].hard and reg["star_tracker"].level == 0
    assert reg["star_tracker"].display(math.radians(2.0)) == 2.0
    assert ConstraintSet(cfg).names == AsifFilter(cfg).names == reg.names
    assert len(ConstraintSet(cfg).safety_values(cfg.scenario("paper-example").x0)) == len(reg)
