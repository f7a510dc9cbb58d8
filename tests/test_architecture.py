"""No import circle anywhere in `palpation` (docs/ARCHITECTURE.md); the layers are import-linter's contract.

A circle is a strongly connected group of modules (imports inside functions count: they still tie the two
modules' designs together). Each is reported with its modules and one shortest circle through them.
"""

from __future__ import annotations

import grimp
import pytest


def import_circles(graph: grimp.ImportGraph) -> list[list[str]]:
    """The strongly connected groups of more than one module, each sorted, in name order (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups = []
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            module, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.find_modules_directly_imported_by(child)))))
                elif child in on_stack:
                    low[module] = min(low[module], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[module])
            if low[module] == index[module]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == module:
                        break
                if len(group) > 1:
                    groups.append(sorted(group))
    return sorted(groups)


def shortest_circle(graph: grimp.ImportGraph, module: str) -> list[str]:
    """One shortest chain of imports from `module` back to itself."""
    chains = [graph.find_shortest_chain(importer=child, imported=module)
              for child in graph.find_modules_directly_imported_by(module)]
    best = min((c for c in chains if c), key=len)
    return [module, *best]


def describe(graph: grimp.ImportGraph, groups: list[list[str]]) -> str:
    """Per circle: its modules, one shortest circle, and every import between its modules (what to untie)."""
    lines = []
    for group in groups:
        inside = [f"{a} -> {b}" for a in group for b in sorted(graph.find_modules_directly_imported_by(a))
                  if b in group]
        lines += [f"{len(group)} modules: {', '.join(group)}",
                  f"  shortest: {' -> '.join(shortest_circle(graph, group[0]))}",
                  f"  imports inside: {'; '.join(inside)}"]
    return "\n".join(lines)


def toy_graph(imports: list[tuple[str, str]]) -> grimp.ImportGraph:
    graph = grimp.ImportGraph()
    for importer, imported in imports:
        graph.add_import(importer=importer, imported=imported)
    return graph


def test_finder_names_each_circle_and_only_circles():
    graph = toy_graph([("p.a", "p.b"), ("p.b", "p.c"), ("p.c", "p.a"), ("p.c", "p.d"),
                       ("p.e", "p.f"), ("p.f", "p.e"), ("p.g", "p.a")])
    groups = import_circles(graph)
    assert groups == [["p.a", "p.b", "p.c"], ["p.e", "p.f"]]
    assert shortest_circle(graph, "p.a") == ["p.a", "p.b", "p.c", "p.a"]
    text = describe(graph, groups)
    assert "shortest: p.e -> p.f -> p.e" in text and "imports inside: p.a -> p.b; p.b -> p.c; p.c -> p.a" in text
    assert import_circles(toy_graph([("p.a", "p.b"), ("p.b", "p.c"), ("p.a", "p.c")])) == []


def test_no_import_circle_in_the_package():
    graph = grimp.build_graph("palpation", cache_dir=None)
    groups = import_circles(graph)
    if groups:
        pytest.fail(f"import circles in palpation (untie each; docs/ARCHITECTURE.md):\n{describe(graph, groups)}",
                    pytrace=False)
