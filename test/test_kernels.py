"""The compile options of the kernels (rta_attitude/jit.py): a kernel compiled without numba's runtime
(LEAF) cannot call one that allocates (JIT). numba would compile such a pair or refuse it depending on
which of the two a process compiled first, so the rule is checked on the sources, where it cannot
depend on order."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "rta_attitude"
ALLOCATING = ("empty", "zeros", "ones", "full", "empty_like", "zeros_like", "array", "copy", "eye")


def _mode(fn: ast.FunctionDef) -> str | None:
    for d in fn.decorator_list:
        text = ast.unparse(d)
        if "njit" in text:
            return "LEAF" if "LEAF" in text else "JIT"
    return None


def _kernels() -> dict[str, dict[str, tuple[str, ast.FunctionDef]]]:
    """module name -> {function name: (mode, node)} of every njit function in the package."""
    out: dict[str, dict[str, tuple[str, ast.FunctionDef]]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        module = ".".join(("rta_attitude", *path.relative_to(PACKAGE).with_suffix("").parts))
        module = module.removesuffix(".__init__")
        found = {n.name: (m, n) for n in tree.body if isinstance(n, ast.FunctionDef) and (m := _mode(n))}
        if found:
            out[module] = found
    return out


def _imports(tree: ast.Module) -> tuple[dict[str, str], dict[str, tuple[str, str]]]:
    """(alias -> module, name -> (module, name)) of a module's rta_attitude imports."""
    modules, names = {}, {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("rta_attitude"):
            for a in node.names:
                names[a.asname or a.name] = (node.module, a.name)
                modules[a.asname or a.name] = f"{node.module}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("rta_attitude"):
                    modules[a.asname or a.name] = a.name
    return modules, names


def test_leaf_kernels_call_only_leaf_kernels_and_do_not_allocate() -> None:
    kernels = _kernels()
    assert sum(len(v) for v in kernels.values()) > 40  # the scan sees the package's kernels
    problems = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        module = ".".join(("rta_attitude", *path.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(
            ".__init__")
        if module not in kernels:
            continue
        modules, names = _imports(tree)
        for name, (mode, fn) in kernels[module].items():
            if mode != "LEAF":
                continue
            for call in (n for n in ast.walk(fn) if isinstance(n, ast.Call)):
                f = call.func
                target = None
                if isinstance(f, ast.Name):
                    if f.id in kernels[module]:
                        target = (module, f.id)
                    elif f.id in names:
                        target = names[f.id]
                elif isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
                    if f.value.id == "np" and f.attr in ALLOCATING:
                        problems.append(f"{module}.{name} allocates (np.{f.attr})")
                    elif f.value.id in modules:
                        target = (modules[f.value.id], f.attr)
                if isinstance(f, ast.Attribute) and f.attr == "copy" and not call.args:
                    problems.append(f"{module}.{name} allocates (.copy())")
                if target and target[1] in kernels.get(target[0], {}):
                    if kernels[target[0]][target[1]][0] == "JIT":
                        problems.append(f"{module}.{name} (LEAF) calls {target[0]}.{target[1]} (JIT)")
    assert not problems, "\n".join(problems)
