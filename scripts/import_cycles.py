"""List import cycles between the modules of Python packages (exit 1 when there is one).

    .venv/bin/python scripts/import_cycles.py ercuts_core addon

Every ``import``/``from … import`` of a module of the same package counts, at module level
or inside a function (a lazy import only hides a cycle), except those under
``if TYPE_CHECKING:``. ``from .pkg import name`` is an edge to the module ``pkg.name`` when
that is a module, else to ``pkg``'s ``__init__``. The cycles are the strongly connected
components of that graph with more than one module (or a module importing itself).
"""
from __future__ import annotations

import ast
import os
import sys


def _module_name(root: str, path: str) -> str:
    rel = os.path.relpath(path, os.path.dirname(root))[:-3].replace(os.sep, ".")
    return rel[: -len(".__init__")] if rel.endswith(".__init__") else rel


def modules(package_dir: str) -> dict[str, str]:
    """Dotted module name → file path for every ``.py`` file under ``package_dir``."""
    root = os.path.abspath(package_dir)
    out = {}
    for base, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__" and not d.startswith("."))
        for f in sorted(files):
            if f.endswith(".py"):
                path = os.path.join(base, f)
                out[_module_name(root, path)] = path
    return out


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def imports_of(name: str, path: str, known: dict[str, str]) -> set[str]:
    """Modules of ``known`` that module ``name`` (file ``path``) imports."""
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), path)
    skip = _type_checking_lines(tree)
    package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name in known)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in known:
                    out.add(sub)
                elif target in known:
                    out.add(target)
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with a cycle (Tarjan 1972), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
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
            if len(comp) > 1 or v in graph.get(v, ()):
                out.append(sorted(comp))

    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def import_graph(package_dirs: list[str]) -> dict[str, set[str]]:
    """Module → the package modules it imports, over every package in ``package_dirs``."""
    known: dict[str, str] = {}
    for d in package_dirs:
        known.update(modules(d))
    return {name: imports_of(name, path, known) for name, path in known.items()}


def main(argv: list[str] | None = None) -> int:
    dirs = (argv if argv is not None else sys.argv[1:]) or ["ercuts_core", "addon"]
    graph = import_graph(dirs)
    found = cycles(graph)
    for comp in found:
        print("import cycle: " + " <-> ".join(comp))
    print(f"{len(graph)} modules, {sum(map(len, graph.values()))} imports, {len(found)} cycles")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
