"""The package graph of mitpiv has no cycle: counting every import a module can execute
(module-level and the lazy ones inside functions; not ``if TYPE_CHECKING:`` blocks), no
subpackage imports one that imports it back. The root package (a facade that re-exports
``set_variant`` / ``render_scene``) and the CLI sit on top and are left out."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "mitpiv"
TOP = {"mitpiv", "cli"}  # the facade and the command line: allowed to import anything


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "mitpiv"


def _imports(tree: ast.AST):
    """Imported module names, skipping ``if TYPE_CHECKING:`` bodies."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module == "mitpiv":
                yield from (f"mitpiv.{a.name}" for a in node.names)
            else:
                yield node.module
        stack.extend(ast.iter_child_nodes(node))


def package_graph() -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for f in ROOT.rglob("*.py"):
        module = ".".join(f.relative_to(ROOT.parent).with_suffix("").parts).removesuffix(".__init__")
        src = _unit(module)
        for name in _imports(ast.parse(f.read_text())):
            if name == "mitpiv" or name.startswith("mitpiv."):
                dst = _unit(name)
                if dst != src:
                    edges.setdefault(src, set()).add(dst)
    return edges


def _cycle(edges):
    """One cycle of the graph as a list of nodes, or None."""
    colour, parent = {}, {}

    def visit(n):
        colour[n] = 1
        for m in sorted(edges.get(n, ())):
            if m in TOP:
                continue
            if colour.get(m) == 1:
                path, x = [], n
                while x != m:
                    path.append(x)
                    x = parent[x]
                return [m] + path[::-1] + [m]
            if m not in colour:
                parent[m] = n
                c = visit(m)
                if c:
                    return c
        colour[n] = 2
        return None

    for n in sorted(edges):
        if n not in TOP and n not in colour:
            c = visit(n)
            if c:
                return c
    return None


def test_no_import_cycle_between_subpackages():
    edges = package_graph()
    assert _cycle(edges) is None, f"import cycle: {' -> '.join(_cycle(edges))}"


def test_layers():
    """The rooms of the design guide: physics knows no renderer, io stores but does not
    compute, render knows no reconstruction or analysis, reconstruct/analysis know no
    renderer and no study, nothing below studies imports studies."""
    edges = package_graph()
    assert not edges.get("physics", set()) & {"render", "io", "reconstruct", "analysis", "lightfield", "studies"}
    assert not edges.get("io", set()) & {"render", "reconstruct", "analysis", "lightfield", "studies", "imaging"}
    assert not edges.get("render", set()) & {"reconstruct", "analysis", "studies"}
    for pkg in ("reconstruct", "analysis", "lightfield", "holography", "tracking"):
        assert not edges.get(pkg, set()) & {"render", "studies"}, pkg
    # tracking is a peer of reconstruct: physics, io, grid, analysis below it
    assert not edges.get("tracking", set()) & {"reconstruct", "lightfield", "holography", "imaging"}
    for pkg, dst in edges.items():
        if pkg not in TOP | {"studies", "replications"}:
            assert "studies" not in dst, pkg
    # the replications sit above the experiment engine: only the facade and the CLI import them
    for pkg, dst in edges.items():
        if pkg not in TOP | {"replications"}:
            assert "replications" not in dst, pkg


def test_the_checker_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}}) is None
