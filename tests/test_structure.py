"""The shape of the package (issue 23): no import circle, no module re-exporting names it does not
define (package faces, ``__init__.py``, excepted), no ``_private`` name used across modules.

Read statically from the source (ast, and grimp: import-linter's graph builder), so a new module
is covered the day it is added.
"""

from __future__ import annotations

import ast
from pathlib import Path

import grimp  # import-linter's graph builder (a test dependency): missing, this file fails

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "rosnet_tui"


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PKG.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _resolve(module: str, node: ast.ImportFrom, is_package: bool) -> str:
    """The absolute module name of a (possibly relative) ``from X import`` in *module*."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _defined(tree: ast.Module) -> set[str]:
    """Names a module binds itself at top level (defs, classes, assignments), not by import."""
    names: set[str] = set()

    def targets(t: ast.AST) -> None:
        if isinstance(t, ast.Name):
            names.add(t.id)
        elif isinstance(t, (ast.Tuple, ast.List)):
            for e in t.elts:
                targets(e)

    def walk(body: list[ast.stmt]) -> None:
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, ast.Assign):
                for t in node.targets:
                    targets(t)
            elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
                targets(node.target)
            elif isinstance(node, (ast.If, ast.Try)):
                walk(node.body)
                walk(node.orelse)
                for h in getattr(node, "handlers", []):
                    walk(h.body)
    walk(tree.body)
    return names


def test_the_import_graph_has_no_circle():
    graph = grimp.build_graph("rosnet_tui")
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    circles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:      # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for m in sorted(graph.modules):
        if m not in index:
            visit(m)
    assert not circles, f"import circles: {circles}"


def test_no_module_reexports_a_name_it_does_not_define():
    """``from rosnet_tui.x.y import n`` (anywhere: product, tests, bench, scripts) names something
    y defines, or a submodule of a package; only package faces (``__init__.py``) gather names."""
    defined = {m: _defined(_tree(p)) for m, p in MODULES.items() if p.name != "__init__.py"}
    bad = []
    sources = [*PKG.rglob("*.py"), *(ROOT / "tests").rglob("*.py"), *(ROOT / "bench").rglob("*.py"),
               *(ROOT / "scripts").rglob("*.py")]
    for path in sorted(sources):
        rel = path.relative_to(ROOT).with_suffix("").parts
        here = ".".join(rel[:-1] if rel[-1] == "__init__" else rel)
        for node in ast.walk(_tree(path)):
            if not isinstance(node, ast.ImportFrom):
                continue
            target = _resolve(here, node, path.name == "__init__.py")
            if target not in defined:
                continue
            for alias in node.names:
                if alias.name != "*" and alias.name not in defined[target] \
                        and f"{target}.{alias.name}" not in MODULES:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {alias.name} "
                               f"from {target}")
    assert not bad, "names imported from a module that only re-exports them:\n" + "\n".join(bad)


def test_no_product_module_uses_another_modules_private_name():
    bad = []
    for module, path in MODULES.items():
        tree = _tree(path)
        aliases: dict[str, str] = {}       # local name -> rosnet_tui module it stands for
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(module, node, path.name == "__init__.py")
                for alias in node.names:
                    full = f"{target}.{alias.name}"
                    if full in MODULES:
                        aliases[alias.asname or alias.name] = full
                    elif target in MODULES and target != module and alias.name.startswith("_") \
                            and not alias.name.startswith("__"):
                        bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: "
                                   f"{alias.name} from {target}")
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in MODULES and alias.asname:
                        aliases[alias.asname] = alias.name
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in aliases and aliases[node.value.id] != module \
                    and node.attr.startswith("_") and not node.attr.startswith("__"):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: "
                           f"{aliases[node.value.id]}.{node.attr}")
    assert not bad, "private names used across modules:\n" + "\n".join(bad)


def test_the_development_docs_where_things_live_table_names_files_that_exist():
    """docs/DEVELOPMENT.md: every module the table names exists (a file moved is a row to fix)."""
    import re

    lines = (ROOT / "docs" / "DEVELOPMENT.md").read_text(encoding="utf-8").splitlines()
    start = next(n for n, line in enumerate(lines) if "Where things live" in line)
    rows = []
    for line in lines[start + 1:]:
        if line.strip().startswith("|"):
            rows.append(line)
        elif rows:
            break
    assert len(rows) > 10
    missing = []
    for row in rows:
        folder = ""
        for name in re.findall(r"`([A-Za-z0-9_./<>{},-]+(?:\.py|/))`", row):
            if "<" in name or "{" in name:
                continue
            if "/" in name.rstrip("/"):
                folder = name.rsplit("/", 1)[0] if name.endswith(".py") else name.rstrip("/")
                path = name
            else:               # a bare file name in a row that named its folder before
                path = f"{folder}/{name}" if folder else name
            base = ROOT if path.startswith("tests/") else PKG
            if not (base / path).exists():
                missing.append(path)
    assert not missing, f"docs/DEVELOPMENT.md's table names what is not there: {missing}"


def test_core_keeps_at_most_8_loose_modules():
    """core/ is a floor plan of packages by role (issue 33); only what every floor shares is loose
    at its top, and the layers contract in pyproject.toml states the floors' order."""
    loose = sorted(p.name for p in (PKG / "core").glob("*.py") if p.name != "__init__.py")
    assert len(loose) <= 8, f"put these in the package of their role: {loose}"
