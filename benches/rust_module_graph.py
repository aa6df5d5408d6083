"""Circles between the Rust core's modules (a measurement, not a test).

    python benches/rust_module_graph.py [rust/oxyline-core/src]

A module is a file (``run/mean_flow.rs`` is ``run::mean_flow``, ``run/mod.rs`` or ``run.rs``
is ``run``); it depends on every module it names through ``crate::…`` or ``super::…`` paths
outside comments. A module and its ancestors are not counted as depending on each other (a
parent declares and re-exports its children); every other strongly connected component of more
than one module is printed.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import networkx as nx

PATH = re.compile(r"\b(crate|super)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")
GROUP = re.compile(r"\b(crate|super)::\{([^}]*)\}")


def module_of(src: Path, f: Path) -> tuple[str, ...]:
    parts = list(f.relative_to(src).with_suffix("").parts)
    if parts[-1] in ("mod", "lib"):
        parts.pop()
    return tuple(parts)


def strip_comments(text: str) -> str:
    return "\n".join(line.split("//")[0] for line in text.splitlines())


def targets(text: str, here: tuple[str, ...], is_dir_module: bool) -> list[tuple[str, ...]]:
    parent = here if is_dir_module else here[:-1]
    out = []
    paths = [(m.group(1), m.group(2)) for m in PATH.finditer(text)]
    for m in GROUP.finditer(text):  # use super::{a, b::c}
        paths += [(m.group(1), "::" + item.strip()) for item in m.group(2).split(",")]
    for root, rest in paths:
        base = () if root == "crate" else parent[:-1] if is_dir_module else parent
        if root == "super" and is_dir_module:
            base = here[:-1]
        out.append(base + tuple(p for p in rest.split("::") if p))
    return out


def main(src: Path) -> None:
    files = {module_of(src, f): f for f in sorted(src.rglob("*.rs"))}
    g = nx.DiGraph()
    g.add_nodes_from(files)
    for mod, f in files.items():
        is_dir_module = f.name in ("mod.rs", "lib.rs")
        for path in targets(strip_comments(f.read_text()), mod, is_dir_module):
            while path and path not in files:
                path = path[:-1]
            if not path or path == mod or mod[:len(path)] == path or path[:len(mod)] == mod:
                continue  # itself, an ancestor or a descendant
            g.add_edge(mod, path)
    circles = [sorted("::".join(m) for m in c) for c in nx.strongly_connected_components(g)
               if len(c) > 1]
    print(f"Rust modules: {len(files)}, circles: {len(circles)}")
    for c in sorted(circles, key=len, reverse=True):
        print(f"  {len(c):3d} modules: {', '.join(c)}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "rust/oxyline-core/src"))
