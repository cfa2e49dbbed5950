"""The package graph of mitpiv has no cycle: counting every import a module can execute
(module-level and the lazy ones inside functions; not ``if TYPE_CHECKING:`` blocks), no
subpackage imports one that imports it back. The root package (a facade that re-exports
``set_variant`` / ``render_scene``) and the CLI sit on top and are left out.

Inside the experiment engine (``mitpiv/studies``) and the physics (``mitpiv/physics``) the
same holds module by module, and no experiment kind imports another kind: what several
kinds need lives in ``mitpiv.studies.shared``."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "mitpiv"
TOP = {"mitpiv", "cli"}  # the facade and the command line: allowed to import anything


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "mitpiv"


def package_graph() -> dict[str, set[str]]:
    """The subpackage graph: the module graph of :mod:`mitpiv` (:func:`module_graph`) with
    every module folded into its subpackage (``mitpiv.render.plugins.x`` -> ``render``)."""
    edges: dict[str, set[str]] = {}
    for src, dsts in module_graph("mitpiv").items():
        for dst in dsts:
            if _unit(dst) != _unit(src):
                edges.setdefault(_unit(src), set()).add(_unit(dst))
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


def _module_name(f: Path, root: Path) -> str:
    return ".".join(f.relative_to(root).with_suffix("").parts).removesuffix(".__init__")


def _module_imports(tree: ast.AST, module: str, is_package: bool):
    """Every name a module imports, absolute (relative imports resolved), skipping
    ``if TYPE_CHECKING:`` bodies; ``from a.b import c`` gives ``a.b.c`` (a module or a name
    in ``a.b``: :func:`module_graph` keeps the longest prefix that is a module)."""
    base = module.split(".") if is_package else module.split(".")[:-1]
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = base[: len(base) - (node.level - 1)]
                src = ".".join(parts + ([node.module] if node.module else []))
            else:
                src = node.module
            yield from (f"{src}.{a.name}" for a in node.names)
        stack.extend(ast.iter_child_nodes(node))


def module_graph(package: str, root: Path = ROOT.parent) -> dict[str, set[str]]:
    """The import graph between the modules of ``package`` (its folder under ``root``):
    module -> the modules of the package it imports (lazy imports counted)."""
    folder = root.joinpath(*package.split("."))
    files = {_module_name(f, root): f for f in folder.rglob("*.py")}
    edges: dict[str, set[str]] = {}
    for module, f in files.items():
        for name in _module_imports(ast.parse(f.read_text()), module, f.name == "__init__.py"):
            while name and name not in files:  # the longest prefix that is a module of the package
                name = name.rpartition(".")[0]
            if name and name != module:
                edges.setdefault(module, set()).add(name)
    return edges


KINDS = "mitpiv.studies.kinds"


def kind_imports(edges: dict[str, set[str]], kinds: str = KINDS) -> list[tuple[str, str]]:
    """(importer, imported) pairs where a kind's module (``kinds.X`` or below) imports another
    kind (``kinds.Y``, Y != X) or the kinds' registry (``kinds``, which imports them all)."""
    def kind(m):
        return m[len(kinds) + 1:].split(".")[0] if m.startswith(kinds + ".") else None

    return sorted((src, dst) for src, dsts in edges.items() if kind(src) for dst in dsts
                  if dst == kinds or (kind(dst) and kind(dst) != kind(src)))


def test_no_import_cycle_between_subpackages():
    edges = package_graph()
    assert _cycle(edges) is None, f"import cycle: {' -> '.join(_cycle(edges))}"


def test_layers():
    """The rooms of the design guide: physics knows no renderer, io stores but does not
    compute, render knows no reconstruction or analysis, reconstruct/analysis know no
    renderer and no study, nothing below studies imports studies, calibrate sits beside
    studies."""
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
    # calibrations that render their targets (mitpiv.calibrate) sit above render, lightfield,
    # reconstruct and analysis, beside the engine: it imports no study, only studies,
    # replications, the facade and the CLI import it
    assert not edges.get("calibrate", set()) & {"studies", "replications"}
    for pkg, dst in edges.items():
        if pkg not in TOP | {"studies", "replications", "calibrate"}:
            assert "calibrate" not in dst, pkg


def test_no_import_cycle_inside_studies():
    """The experiment engine, module by module: the runner, sweeps, reports, export and the
    kinds import downwards (kinds -> report / export -> shared -> schema)."""
    edges = module_graph("mitpiv.studies")
    assert _cycle(edges) is None, f"import cycle in mitpiv/studies: {' -> '.join(_cycle(edges))}"


def test_no_kind_imports_another_kind():
    assert kind_imports(module_graph("mitpiv.studies")) == []


def test_no_import_cycle_inside_physics():
    edges = module_graph("mitpiv.physics")
    assert _cycle(edges) is None, f"import cycle in mitpiv/physics: {' -> '.join(_cycle(edges))}"


def test_the_module_checker_finds_a_planted_cycle(tmp_path):
    """A lazy import inside a function and a relative import close a cycle; an import under
    ``if TYPE_CHECKING:`` does not; a kind importing another kind is named."""
    pkg = tmp_path / "pkg" / "studies"
    (pkg / "kinds").mkdir(parents=True)
    files = {"__init__.py": "", "a.py": "def f():\n    from pkg.studies import b\n",
             "b.py": "from . import c\n", "c.py": "import pkg.studies.a\n",
             "d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.studies import a\n",
             "kinds/__init__.py": "", "kinds/x.py": "from pkg.studies.kinds.y import Y\n", "kinds/y.py": "Y = 1\n"}
    for name, text in files.items():
        (pkg / name).write_text(text)
    edges = module_graph("pkg.studies", tmp_path)
    assert _cycle(edges) == ["pkg.studies.a", "pkg.studies.b", "pkg.studies.c", "pkg.studies.a"]
    assert "pkg.studies.d" not in edges
    assert kind_imports(edges, "pkg.studies.kinds") == [("pkg.studies.kinds.x", "pkg.studies.kinds.y")]
    (pkg / "a.py").write_text("")
    assert _cycle(module_graph("pkg.studies", tmp_path)) is None


def test_the_checker_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}}) is None
