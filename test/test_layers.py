"""The package's folders are its layers: every import (module level or inside a function) points to the
same layer or a lower one, and only `ros` imports rclpy. Read from the sources (AST), so a lazy import
cannot hide an upward arrow. docs/architecture.md draws the same order."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "rta_attitude"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("__init__", "errors", "files", "jit", "kernel_cache", "topics"),  # foundation: no physics, no ROS
    ("config",),
    ("dynamics",),
    ("constraints",),
    ("filter",),
    ("simulation",),
    ("montecarlo", "recording", "viability"),
    ("ros",),
    ("cli",),
)
"""Lowest first; a unit is a subpackage folder or a top-level module."""

ALLOWED_UPWARD = {("config", "dynamics.state")}
"""The one exception: the config loader builds each scenario's initial state with the state layout
(dynamics/state.py, numpy only; it imports nothing of the package)."""

RCLPY_LAYERS = {"ros"}


def _rank(unit: str) -> int:
    return next(i for i, layer in enumerate(LAYERS) if unit in layer)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, imported module) of every import in a file, absolute names."""
    out: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            base = node.module
            if node.level:  # relative: resolve against the file's package
                parts = path.relative_to(PACKAGE.parent).with_suffix("").parts[: -node.level]
                base = ".".join((*parts, node.module))
            out.append((node.lineno, base))
            if base == "rta_attitude":  # from rta_attitude import config, topics
                out += [(node.lineno, f"rta_attitude.{a.name}") for a in node.names]
    return out


def _violations(package: Path) -> list[str]:
    bad: list[str] = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        unit = rel.parts[0].removesuffix(".py")
        for line, name in _imports(path):
            where = f"{rel}:{line}"
            if name.split(".")[0] == "rclpy" and unit not in RCLPY_LAYERS:
                bad.append(f"{where} imports rclpy outside ros/")
            if not name.startswith("rta_attitude.") or name == "rta_attitude":
                continue
            target = name.split(".")[1]
            sub = ".".join(name.split(".")[1:3])
            if _rank(target) > _rank(unit) and (unit, sub) not in ALLOWED_UPWARD:
                bad.append(f"{where} ({unit}) imports {name} from a higher layer")
    return bad


def test_every_import_points_down_the_layers() -> None:
    units = {p.name.removesuffix(".py") for p in PACKAGE.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    assert units == {u for layer in LAYERS for u in layer}, "a unit of the package is in no layer"
    assert _violations(PACKAGE) == []


def test_the_check_sees_an_upward_import_even_inside_a_function(tmp_path: Path) -> None:
    pkg = tmp_path / "rta_attitude"
    (pkg / "dynamics").mkdir(parents=True)
    (pkg / "dynamics" / "bad.py").write_text("def f():\n    from rta_attitude.ros import spin\n    import rclpy\n")
    (pkg / "config").mkdir()
    (pkg / "config" / "ok.py").write_text("from rta_attitude.dynamics.state import make_state\n")
    assert _violations(pkg) == ["dynamics/bad.py:2 (dynamics) imports rta_attitude.ros from a higher layer",
                                "dynamics/bad.py:3 imports rclpy outside ros/"]
