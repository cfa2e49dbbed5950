"""Every mitpiv module and name the README, the documentation pages and the example scripts
use is on an API page: a user who reads ``from mitpiv.X import Y``, ``mitpiv.X.Y`` or
``rc.mart(...)`` (after ``from mitpiv import reconstruct as rc``) finds it in the reference.

The API pages are read as text: their ``automodule`` directives with their ``:members:``
lists, and ``autofunction`` / ``autoclass`` / ``autodata`` directives. A bare ``:members:``
documents what Sphinx's autodoc would: the names of ``__all__`` where the module has one,
else the public functions and classes defined in the module, each only with a docstring,
and module constants with a ``#:`` comment. A name counts as documented where it is defined
(``mitpiv.studies.run_experiment`` is documented as ``mitpiv.studies.runner.run_experiment``)
or where it is re-exported."""

import importlib
import inspect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
ALL = object()  # a bare :members:


def api_pages() -> list[Path]:
    return [DOCS / "api.md", *sorted((DOCS / "api").glob("*.md"))]


def sources() -> list[Path]:
    """What a user reads: the README, the hand-written pages, the example scripts."""
    return [ROOT / "README.md", *sorted(DOCS.glob("*.md")), *sorted((ROOT / "examples").glob("[!_]*.py"))]


# ------------------------------------------------------------------ what the API pages document
def parse_api(text: str) -> tuple[dict[str, object], set[str]]:
    """``{module: ALL or set of member names}`` of the automodule directives, and the full
    names of the autofunction / autoclass / autodata / ... directives."""
    modules: dict[str, object] = {}
    objects: set[str] = set()
    blocks = re.split(r"^\s*(?=\.\. auto)", text, flags=re.M)
    for block in blocks:
        m = re.match(r"\.\. auto(\w+):: ([\w.]+)", block)
        if not m:
            continue
        kind, name = m.groups()
        if kind != "module":
            objects.add(name)
            continue
        mem = re.search(r"^\s+:members:(.*(?:\n\s{4,}[^:\s].*)*)", block, re.M)
        if mem is None:
            modules.setdefault(name, set())
        elif not mem.group(1).strip():
            modules[name] = ALL
        elif modules.get(name) is not ALL:
            listed = {n.strip() for n in mem.group(1).replace("\n", " ").split(",") if n.strip()}
            modules[name] = modules.get(name, set()) | listed
    return modules, objects


def _attr_docs(module: str) -> set[str]:
    from sphinx.pycode import ModuleAnalyzer

    try:
        return {name for (scope, name) in ModuleAnalyzer.for_module(module).find_attr_docs() if scope == ""}
    except Exception:
        return set()


def _is_code(obj) -> bool:
    """A function (decorated ones included) or a class: what autodoc checks the home module of."""
    return inspect.isclass(obj) or inspect.isroutine(obj) or inspect.isfunction(inspect.unwrap(obj))


def autodoc_documents(module: str, name: str) -> bool:
    """Whether ``.. automodule:: module`` with a bare ``:members:`` documents ``name``."""
    if name.startswith("_"):
        return False
    mod = importlib.import_module(module)
    if not hasattr(mod, name):
        return False
    obj = getattr(mod, name)
    public = getattr(mod, "__all__", None)
    if public is not None and name not in public:
        return False
    if _is_code(obj):
        if public is None and obj.__module__ != module:
            return False  # imported, not defined here
        return bool(inspect.getdoc(obj))
    if inspect.ismodule(obj):
        return False
    return name in _attr_docs(module)


def documented(full: str, modules: dict[str, object], objects: set[str]) -> bool:
    """Whether the module or module-level name ``full`` is on the API pages."""
    if full in objects or full in modules:
        return True
    module, _, name = full.rpartition(".")
    listed = modules.get(module)
    if listed is ALL:
        return autodoc_documents(module, name)
    return listed is not None and name in listed


# ------------------------------------------------------------------ what the pages use
def _import_names(spec: str) -> list[tuple[str, str]]:
    """``a, b as c`` (or parenthesised, over lines) -> [(a, a), (b, c)]."""
    out = []
    for part in spec.replace("(", " ").replace(")", " ").replace("\\\n", " ").split(","):
        part = part.split("#")[0].strip()
        if not part:
            continue
        m = re.fullmatch(r"(\w+)(?:\s+as\s+(\w+))?", part)
        if m:
            out.append((m.group(1), m.group(2) or m.group(1)))
    return out


def used_names(text: str) -> set[str]:
    """The dotted mitpiv names a text uses: its imports, its ``mitpiv.X.Y`` references, and
    the attributes of the modules it imported under a name (``rc.mart`` -> mitpiv.reconstruct.mart)."""
    names: set[str] = set()
    aliases: dict[str, str] = {}
    for m in re.finditer(r"\bfrom (mitpiv(?:\.\w+)*) import (\([^)]*\)|[^\n]*)", text):
        for name, alias in _import_names(m.group(2)):
            names.add(f"{m.group(1)}.{name}")
            aliases[alias] = f"{m.group(1)}.{name}"
    for m in re.finditer(r"^\s*import (mitpiv(?:\.\w+)*)(?: as (\w+))?", text, re.M):
        names.add(m.group(1))
        if m.group(2):
            aliases[m.group(2)] = m.group(1)
    names.update(re.findall(r"(?<![\w./-])mitpiv(?:\.[A-Za-z_]\w*)+", text))
    for alias, target in aliases.items():
        if alias != "mitpiv":
            names.update(f"{target}.{attr}" for attr in re.findall(rf"(?<![\w.]){alias}\.([A-Za-z_]\w*)", text))
    return names


def _code_names(module: str) -> dict[str, str]:
    """The public functions and classes of a module and of its direct submodules: bare name ->
    full name (the package's own, re-exported ones first)."""
    import pkgutil

    pkg = importlib.import_module(module)
    mods = [pkg] + [importlib.import_module(f"{module}.{info.name}") for info in
                    pkgutil.iter_modules(getattr(pkg, "__path__", [])) if not info.name.startswith("_")]
    names: dict[str, str] = {}
    for mod in mods:
        for name in dir(mod):
            obj = getattr(mod, name)
            if not name.startswith("_") and _is_code(obj) and getattr(obj, "__module__", "").startswith("mitpiv"):
                names.setdefault(name, f"{mod.__name__}.{name}")
    return names


def section_names(text: str) -> set[str]:
    """The functions and classes named bare (``mart(...)``, ``place_camera``) in a section whose
    heading names its modules (``## Physics (`mitpiv.physics`)``): the guide's tour by room."""
    names: set[str] = set()
    for section in re.split(r"^(?=#{2,3} )", text, flags=re.M):
        heading = section.partition("\n")[0]
        modules = re.findall(r"`(mitpiv(?:\.\w+)*)`", heading) if heading.startswith("#") else []
        if not modules:
            continue
        known: dict[str, str] = {}
        for module in modules:
            for name, full in _code_names(module).items():
                known.setdefault(name, full)
        words = set(re.findall(r"`([A-Za-z_]\w*)(?:\(|`)", section))
        words |= set(re.findall(r"`[^`\n]*?\b([A-Za-z_]\w*)\(", section))
        names.update(known[w] for w in words if w in known)
    return names


def resolve(full: str) -> list[str] | None:
    """The names under which ``full`` may be documented (the module, or the module-level object
    where it is re-exported and where it is defined); None when it does not exist. A name
    deeper than module level (a method) stands for its module-level owner."""
    parts = full.split(".")
    for i in range(len(parts), 0, -1):
        module = ".".join(parts[:i])
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        if i == len(parts):
            return [module]
        name = parts[i]
        if not hasattr(mod, name):
            return None
        obj = getattr(mod, name)
        if inspect.ismodule(obj):
            return [obj.__name__]
        where = [f"{module}.{name}"]
        home = getattr(obj, "__module__", None)
        if _is_code(obj) and home and home != module:
            where.append(f"{home}.{obj.__qualname__.split('.')[0]}")
        return where
    return None


def missing(texts: dict[str, str], api_text: str) -> list[str]:
    """Each used name that does not exist or is not on the API pages, with where it is used."""
    modules, objects = parse_api(api_text)
    problems = []
    for source, text in texts.items():
        for full in sorted(used_names(text) | section_names(text)):
            if any(p.startswith("_") for p in full.split(".")):
                continue  # private: not part of the API
            where = resolve(full)
            if where is None:
                problems.append(f"{source}: {full} does not exist")
            elif not any(documented(w, modules, objects) for w in where):
                problems.append(f"{source}: {full} is not on the API pages (looked for {', '.join(where)})")
    return problems


def _texts() -> dict[str, str]:
    return {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8") for p in sources()}


def _api_text() -> str:
    return "\n".join(p.read_text(encoding="utf-8") for p in api_pages() if p.is_file())


# ------------------------------------------------------------------ the tests
def test_every_name_the_docs_use_is_on_the_api_pages():
    texts = _texts()
    used = set().union(*(used_names(t) for t in texts.values()))
    # the extraction finds what the pages use, aliases included
    assert {"mitpiv.studies.run_experiment", "mitpiv.reconstruct.mlos", "mitpiv.reconstruct.mart",
            "mitpiv.render_scene", "mitpiv.io.read_exr", "mitpiv.lightfield", "mitpiv.holography"} <= used, used
    # and the functions the guide's rooms name bare (`mart(...)` under `mitpiv.reconstruct`)
    guide = section_names(texts["docs/guide.md"])
    assert {"mitpiv.reconstruct.mart", "mitpiv.physics.camera.place_camera", "mitpiv.imaging.apply_sensor"} <= guide
    problems = missing(texts, _api_text())
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("name", [
    # what a new user looked for and did not find (issue 54, item 5)
    "mitpiv.reconstruct.mart", "mitpiv.reconstruct.mlos", "mitpiv.render_scene", "mitpiv.set_variant",
    "mitpiv.physics.camera.place_camera", "mitpiv.tracking", "mitpiv.lightfield", "mitpiv.imaging",
    "mitpiv.render.plugins.distorted_pinhole", "mitpiv.render.plugins.plenoptic", "mitpiv.render.plugins.laser_sheet",
    "mitpiv.render.plugins.tracer_particles", "mitpiv.render.plugins.mie_phase", "mitpiv.render.plugins.particle_tracer",
])
def test_names_a_user_looked_for_are_on_the_api_pages(name):
    modules, objects = parse_api(_api_text())
    assert any(documented(w, modules, objects) for w in resolve(name)), name


def test_every_flow_class_is_on_the_api_pages():
    from mitpiv.physics.flows import FLOW_KINDS

    modules, objects = parse_api(_api_text())
    classes = {cls for cls in FLOW_KINDS.values() if inspect.isclass(cls)}
    assert classes
    for cls in classes:
        assert documented(f"{cls.__module__}.{cls.__name__}", modules, objects), cls


def test_the_check_fails_on_what_is_missing():
    """The checker is not vacuous: a name that does not exist, a module the pages lack, a name
    left out of a :members: list and an undocumented alias use are each reported."""
    api = (".. automodule:: mitpiv.reconstruct.tomo\n   :members: mlos\n\n"
           ".. automodule:: mitpiv.io.exr\n   :members:\n")
    text = ("from mitpiv import reconstruct as rc\nfrom mitpiv.io import read_exr\n"
            "vol = rc.mart(x)\nvol = rc.mlos(x)\nmitpiv.reconstruct.no_such_function\nimport mitpiv.tracking\n")
    problems = "\n".join(missing({"page": text}, api))
    assert "mitpiv.reconstruct.mart is not on the API pages" in problems
    assert "mitpiv.reconstruct.no_such_function does not exist" in problems
    assert "mitpiv.tracking is not on the API pages" in problems
    assert "mlos" not in problems and "read_exr" not in problems and "mitpiv.reconstruct is" in problems
    # a function named bare in a room of the tour, its module on the API page without it
    room = "## Physics (`mitpiv.physics`)\n\nCameras are placed by `place_camera(...)`.\n"
    assert "place_camera is not on the API pages" in "\n".join(
        missing({"page": room}, ".. automodule:: mitpiv.physics.camera\n   :members: Camera\n"))
    # a module listed with members, but the member asked for is not among them
    assert missing({"page": "from mitpiv.io.exr import read_exr"}, ".. automodule:: mitpiv.io.exr\n   :members: write_exr\n")


# ------------------------------------------------------------------ commands that work as written
#: A command a reader copies that starts with a program only the virtual environment has (no
#: `python`, `mitpiv` or `pip` is on PATH after `make setup`): an indented code line, or inline
#: code `python ...` / `pip ...` (inline `mitpiv NAME` in prose names a subcommand).
CODE_LINE = re.compile(r"^\s{4,}(?:\$ )?(?:python3?|mitpiv|pip) (?!-m venv)\S.*$", re.M)
INLINE = re.compile(r"`(?:python3?|pip) (?!-m venv)[^`]*`")


def bare_commands(text: str) -> list[str]:
    return [m.group(0).strip() for m in CODE_LINE.finditer(text)] + INLINE.findall(text)


def test_example_commands_work_from_a_fresh_clone():
    """The commands in the README, the pages, the scenes' READMEs and the examples' docstrings
    call `.venv/bin/python` / `.venv/bin/mitpiv`, which `make setup` makes, so each works as
    written from the repository root without an activated environment (docs/benchmarks.md is
    left out: its blocks record the command each benchmark ran, written by the benchmarks)."""
    import ast

    pages = [ROOT / "README.md", *sorted(p for p in DOCS.glob("*.md") if p.name != "benchmarks.md"),
             *sorted((ROOT / "scenes").glob("*/README.md"))]
    found = [f"{page.relative_to(ROOT)}: {c}" for page in pages for c in bare_commands(page.read_text(encoding="utf-8"))]
    for script in sorted((ROOT / "examples").glob("[!_]*.py")):
        doc = ast.get_docstring(ast.parse(script.read_text())) or ""
        found += [f"{script.relative_to(ROOT)}: {c}" for c in bare_commands(doc)]
    assert not found, "\n".join(found)
    # the check itself
    assert bare_commands("    python examples/sweep.py --small\n") == ["python examples/sweep.py --small"]
    assert bare_commands("    mitpiv run exp.toml --out x\nrun `pip install x`") == ["mitpiv run exp.toml --out x",
                                                                                  "`pip install x`"]
    assert not bare_commands("    .venv/bin/python examples/sweep.py\n`python3 -m venv .venv`; `mitpiv schema` lists")
