"""Import circles and long functions of the Python package (a measurement, not a test).

    python benches/import_graph.py [python/oxyline]

Reads every module with :mod:`ast` (nothing is imported), builds the graph of imports between
the package's modules twice: module-level imports only, and every import including those inside
functions; prints each strongly connected component of more than one module (an import circle),
the number of function-local imports of the package, the functions longer than 80 lines and the
lines of the package by role (module-level literal tables counted apart as data tables).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import networkx as nx


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def resolve(current: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = current.split(".")
    base = base if is_pkg else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports(tree: ast.Module, current: str, is_pkg: bool, known: set[str]):
    """(target module, is function-local) for every import of a package module."""
    local_lines: set[int] = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for sub in ast.walk(fn):
                if isinstance(sub, (ast.Import, ast.ImportFrom)):
                    local_lines.add(id(sub))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = resolve(current, is_pkg, node)
            # `from pkg import mod` imports the submodule pkg.mod when it is one
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                     for a in node.names]
        else:
            continue
        if _type_checking_only(tree, node):
            continue
        for name in names:
            while name and name not in known:
                name = name.rpartition(".")[0]
            if name and name != current:
                yield name, id(node) in local_lines


def _type_checking_only(tree: ast.Module, node: ast.AST) -> bool:
    for top in tree.body:
        if (isinstance(top, ast.If) and "TYPE_CHECKING" in ast.unparse(top.test)
                and any(sub is node for sub in ast.walk(top))):
            return True
    return False


def long_functions(tree: ast.Module, mod: str, limit: int = 80):
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = fn.end_lineno - fn.lineno + 1
            if n > limit:
                yield n, f"{mod}.{fn.name}"


#: the package's modules by role (first matching prefix; the rest is "orchestration")
ROLES = (
    ("validation", ("oxyline.model", "oxyline.units", "oxyline.errors",
                    "oxyline.memory", "oxyline.options", "oxyline.description")),
    ("results/plots", ("oxyline.result", "oxyline.io.results", "oxyline.io.result_reader",
                       "oxyline.checkpoint", "oxyline.plot", "oxyline.monitor")),
    ("readers/writers of formats", ("oxyline.io", "oxyline.loader", "oxyline.svzerod",
                                    "oxyline.pwdb")),
    ("CLI", ("oxyline.cli",)),
    ("reference solvers", ("oxyline.reference",)),
)

#: nodes a data table (a literal parameter set written as Python) is made of: containers,
#: numbers, strings, arithmetic on them, names and calls such as ``np.array(...)``
_DATA_NODES = (ast.Constant, ast.Dict, ast.List, ast.Tuple, ast.Set, ast.UnaryOp, ast.BinOp,
               ast.Name, ast.Attribute, ast.Call, ast.keyword, ast.Starred, ast.operator,
               ast.unaryop, ast.expr_context)


def role(mod: str) -> str:
    for name, prefixes in ROLES:
        if any(mod == p or mod.startswith((p + ".", p + "_")) for p in prefixes):
            return name
    return "orchestration"


def data_table_lines(tree: ast.Module) -> set[int]:
    """Lines of the module-level assignments of literal tables of 4 numbers or strings or
    more (a parameter set, a published data table): data that need not be code."""
    out: set[int] = set()
    for node in tree.body:
        value = node.value if isinstance(node, (ast.Assign, ast.AnnAssign)) else None
        if value is None or not isinstance(value, (ast.Dict, ast.List, ast.Tuple, ast.Call)):
            continue
        if any(isinstance(t, ast.Name) and t.id == "__all__"
               for t in getattr(node, "targets", [getattr(node, "target", None)])):
            continue
        subs = list(ast.walk(value))
        if (all(isinstance(n, _DATA_NODES) for n in subs)
                and sum(isinstance(n, ast.Constant) for n in subs) >= 4):
            out.update(range(node.lineno, node.end_lineno + 1))
    return out


def formula_sites(tree: ast.Module) -> list[int]:
    """Lines of code that look like a physics formula: π, a cube or fourth power, a square
    root, an exponential or a trapezoid integral (the core's job; a hit is a place to look)."""
    out = []
    for node in ast.walk(tree):
        name = (node.attr if isinstance(node, ast.Attribute)
                else node.func.attr if isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute) else None)
        power = (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow)
                 and isinstance(node.right, ast.Constant) and node.right.value in (3, 4))
        if power or name in ("pi", "sqrt", "exp", "trapezoid", "trapz"):
            out.append(node.lineno)
    return sorted(set(out))


def docstring_lines(tree: ast.Module) -> int:
    n = 0
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = node.body[0] if node.body else None
            if (isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant)
                    and isinstance(doc.value.value, str)):
                n += doc.end_lineno - doc.lineno + 1
    return n


def main(root: Path) -> None:
    files = {module_name(root, p): p for p in sorted(root.rglob("*.py"))}
    # the compiled extension (oxyline._core, typed by its .pyi) is a leaf of the graph
    known = set(files) | {module_name(root, p) for p in root.rglob("*.pyi")}
    top, every = nx.DiGraph(), nx.DiGraph()
    top.add_nodes_from(files)
    every.add_nodes_from(files)
    local = 0
    longs = []
    for mod, path in files.items():
        tree = ast.parse(path.read_text(), str(path))
        for target, is_local in imports(tree, mod, path.name == "__init__.py", known):
            every.add_edge(mod, target)
            if is_local:
                local += 1
            else:
                top.add_edge(mod, target)
        longs.extend(long_functions(tree, mod))
    for label, g in (("module-level imports", top), ("all imports (incl. function-local)", every)):
        circles = [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]
        print(f"{label}: {len(circles)} circle(s)")
        for c in sorted(circles, key=len, reverse=True):
            print(f"  {len(c):3d} modules: {', '.join(c)}")
    print(f"function-local imports of the package: {local}")
    print(f"functions over 80 lines: {len(longs)}")
    for n, name in sorted(longs, reverse=True):
        print(f"  {n:4d}  {name}")
    lines: dict[str, int] = {}
    docs = 0
    formulas: dict[str, list[int]] = {}
    for mod, path in files.items():
        text = path.read_text()
        tree = ast.parse(text, str(path))
        data = len(data_table_lines(tree))
        lines["data tables"] = lines.get("data tables", 0) + data
        lines[role(mod)] = lines.get(role(mod), 0) + len(text.splitlines()) - data
        docs += docstring_lines(tree)
        if hits := formula_sites(tree):
            formulas[mod] = hits
    print(f"lines: {sum(lines.values())} (of them docstrings: {docs})")
    for name, n in sorted(lines.items(), key=lambda x: -x[1]):
        print(f"  {n:6d}  {name}")
    print(f"lines that look like a formula (pi, x**3, x**4, sqrt, exp, trapezoid): "
          f"{sum(map(len, formulas.values()))}")
    for mod, hits in sorted(formulas.items()):
        print(f"  {mod}: {', '.join(map(str, hits))}")

if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "python/oxyline"))
