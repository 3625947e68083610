"""The package's shape: no import circle anywhere in jcrowd/, and every module imports alone.

Oracle for the circles: Tarjan's strongly connected components over grimp's module graph (the
same graph ``lint-imports`` checks its contracts on), counting imports inside functions too. A
circle is what makes ``import jcrowd.cli.render`` fail or depend on what was imported first.
"""

from __future__ import annotations

import subprocess
import sys

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
