"""The package's shape: no import circle anywhere in jcrowd/, every module imports alone, module
docstrings say what the code does in at most 40 lines and functions fit in 80 (the limits the
project keeps so that a module reads top to bottom).

Oracle for the circles: Tarjan's strongly connected components over grimp's module graph (the
same graph ``lint-imports`` checks its contracts on), counting imports inside functions too. A
circle is what makes ``import jcrowd.cli.render`` fail or depend on what was imported first.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import grimp


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (iterative Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def test_the_cycle_finder_finds_a_planted_circle() -> None:
    """Which bug would this catch: a finder that never reports anything."""
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _cycles(edges) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circle_in_jcrowd() -> None:
    graph = grimp.build_graph("jcrowd")
    edges = {m: set(graph.find_modules_directly_imported_by(m)) for m in graph.modules}
    assert _cycles(edges) == []


def test_the_cli_modules_and_packages_import_on_their_own() -> None:
    """Each in a fresh interpreter, imported first (one process per module is slow, so the
    entry points a user imports directly: the CLI's subcommands and the packages)."""
    names = [
        "jcrowd.cli.render",
        "jcrowd.cli.run",
        "jcrowd.cli.export",
        "jcrowd.pedestrians",
        "jcrowd.crowd",
        "jcrowd.rollouts",
    ]
    for name in names:
        subprocess.run([sys.executable, "-c", f"import {name}"], check=True, timeout=120)


_SOURCES = sorted((Path(__file__).resolve().parents[1] / "jcrowd").rglob("*.py"))


def test_module_docstrings_are_at_most_40_lines() -> None:
    long = {}
    for path in _SOURCES:
        doc = ast.get_docstring(ast.parse(path.read_text()))
        if doc and len(doc.splitlines()) > 40:
            long[str(path)] = len(doc.splitlines())
    assert _SOURCES and not long, long


def test_functions_are_at_most_80_lines() -> None:
    long = {}
    for path in _SOURCES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > 80:
                    long[f"{path}:{node.lineno} {node.name}"] = lines
    assert not long, long
