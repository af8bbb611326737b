"""The project's import graph, read from the source: data flows one way, so no module
imports one that imports it back, directly or around a circle (a lazy import inside a
function counts: it is the same dependency, only later)."""
import ast

from mixstep import paths


def _modules():
    """{module name: path} for firmware/, mixstep/, boards/sim/ and bench/, by the names
    they are imported under (firmware/ and boards/sim/ are on the unix port's path)."""
    found = {}
    for path in sorted((paths.FIRMWARE).rglob("*.py")):
        rel = path.relative_to(paths.FIRMWARE).with_suffix("")
        found[".".join(rel.parts).replace(".__init__", "")] = path
    for path in sorted((paths.ROOT / "mixstep").glob("*.py")):
        found["mixstep." + path.stem if path.stem != "__init__" else "mixstep"] = path
    for folder in (paths.BOARDS / "sim", paths.ROOT / "bench"):
        for path in sorted(folder.glob("*.py")):
            found.setdefault(path.stem, path)
    return found


def _imports(path, known):
    """The project modules a file imports, anywhere in it."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names if alias.name in known)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                name = node.module + "." + alias.name
                if name in known:
                    out.add(name)
                elif node.module in known:
                    out.add(node.module)
    return out


def import_graph():
    known = _modules()
    return {name: _imports(path, known) - {name} for name, path in known.items()}


def circles(graph):
    """Every strongly connected set of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_graph_sees_the_imports_it_must():
    graph = import_graph()
    assert "mixfw.stepper" in graph["mixfw.planner"]  # from mixfw import stepper as st
    assert "mixfw.planner" in graph["mixfw.assemble"]  # from mixfw.planner import Planner
    assert "mixstep.paths" in graph["mixstep.sim"]
    assert "simanalog" in graph["simmachine"]
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_imports_one_that_imports_it_back():
    assert circles(import_graph()) == []
