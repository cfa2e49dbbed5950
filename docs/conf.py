"""Sphinx configuration of the mitpiv documentation (``make docs``: HTML in docs/_build/html,
warnings are errors).

Pages written in Markdown (MyST); the API reference from the numpydoc docstrings (autodoc +
numpydoc). Some pages are generated at build time into ``_generated/`` (not kept in git) so
they cannot drift from the code and the files they show:

- ``schema.md``: the experiment schema of every kind, :func:`mitpiv.studies.schema.describe`
  (the same text as ``mitpiv schema``);
- ``scene_xml.md``: every parameter of every Mitsuba plugin (type, unit, default, range) and
  its XML example, read from the plugins' module docstrings by
  :func:`mitpiv.render.plugin_reference.reference_page`, with the placement figure
  ``docs/figures/placement.png`` (made by ``.venv/bin/python docs/figures/make_placement_figure.py``);
- ``examples.md``: every script in ``examples/``, its docstring, its source below the docstring
  and its figure (``docs/examples/<script>.png``, made by ``.venv/bin/python examples/<script>.py``);
- ``replications.md``, ``studies.md`` and ``benchmarks.md``: whatever exists under ``docs/replications/``,
  ``docs/studies/`` and
  ``docs/benchmarks.md`` (and the accuracy-versus-time report in ``docs/accuracy-time/``).
"""

import ast
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MITPIV_QUIET", "1")

import mitpiv  # noqa: E402

project = "mitpiv"
author = "the mitpiv developers"
copyright = f"2026, {author}"
release = version = mitpiv.__version__ if hasattr(mitpiv, "__version__") else "0.1.0"
extensions = ["myst_parser", "sphinx.ext.autodoc", "numpydoc", "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
exclude_patterns = ["_build", "examples/*.md", "replications/**", "studies/**", "accuracy-time/**", "benchmarks.md", "demo/**"]
html_theme = "alabaster"
html_title = "mitpiv"
html_theme_options = {"description": "physically based rendering testbed for volumetric PIV", "page_width": "1100px",
                      "sidebar_width": "230px"}
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the numpydoc sections carry types and units
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()
nitpicky = False


# ------------------------------------------------------------------ generated pages
def _write(name: str, text: str) -> None:
    out = DOCS / "_generated"
    out.mkdir(exist_ok=True)
    f = out / name
    if not f.is_file() or f.read_text() != text:  # unchanged files keep Sphinx's cache
        f.write_text(text)


def _schema_page() -> str:
    from mitpiv.studies.kinds import KINDS, get_kind
    from mitpiv.studies.schema import describe

    parts = ["# Experiment schema", "",
             "Every key of every table of an experiment TOML file, with its unit (in the key's name), "
             "default and valid range, generated from the schema the runner validates against "
             "(`mitpiv schema` prints the same; `mitpiv run EXP --check` validates a file). "
             "`kind = \"...\"` at the top of a file picks the table set.", ""]
    for name in KINDS:
        k = get_kind(name)
        text = describe(k.schema, title=f"Experiment kind `{k.name}`: {k.describe}")
        # one level down: the kind is a section of this page
        parts.append("\n".join(("#" + line) if line.startswith("#") else line for line in text.splitlines()))
    return "\n".join(parts) + "\n"


def _scene_xml_page() -> str:
    from mitpiv.render.plugin_reference import reference_page

    return reference_page(figure="../figures/placement.png")


def _examples_page() -> str:
    parts = ["# Examples", "",
             "Short scripts to copy from, in `examples/` (each runs in under a minute at its default size; "
             "`--small` is the quick size the test suite runs). Run them from the repository root with the "
             "virtual environment's Python (`make setup` makes it), e.g. "
             "`.venv/bin/python examples/tomo_experiment.py`; they write into `out/examples/<name>/`.", ""]
    for script in sorted((ROOT / "examples").glob("*.py")):
        if script.name.startswith("_"):
            continue
        source = script.read_text()
        tree = ast.parse(source)
        doc = ast.get_docstring(tree) or script.stem
        first, _, rest = doc.partition("\n")
        # the docstring is the prose above; the listing starts at the code after it
        start = 1
        if ast.get_docstring(tree) is not None:
            lines = source.splitlines()
            start = tree.body[0].end_lineno + 1
            while start <= len(lines) and not lines[start - 1].strip():
                start += 1
        parts += [f"## {script.stem.replace('_', ' ')}", "", first.strip(), rest.strip(), ""]
        fig = DOCS / "examples" / f"{script.stem}.png"
        if fig.is_file():
            parts += [f"![{script.stem}](../examples/{fig.name})", ""]
        parts += ["```{literalinclude} " + f"../../examples/{script.name}", ":language: python",
                  f":lines: {start}-", "```", ""]
    return "\n".join(parts)


def _include(path: Path, *, heading_shift: bool = False, start_line: int = 0) -> list[str]:
    rel = os.path.relpath(path, DOCS / "_generated")
    opts = [":relative-docs: ..", ":relative-images:"] + ([":heading-offset: 1"] if heading_shift else []) \
        + ([f":start-line: {start_line}"] if start_line else [])
    return ["```{include} " + rel, *opts, "```", ""]


def _include_report(path: Path, *, name: str = "") -> list[str]:
    """A report one heading level down. A replication report opens with its physics-row tally,
    then its title: here the title comes first, then the tally, then the rest of the report.
    ``name`` goes into the title (two studies of one kind share their report's title, and the
    table of contents would list the same title twice)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    suffix = f" (`{name}`)" if name else ""
    if len(lines) > 2 and lines[2].startswith("# "):
        return ["#" + lines[2] + suffix, "", lines[0], "", *_include(path, heading_shift=True, start_line=3)]
    if name and lines and lines[0].startswith("# "):
        return ["#" + lines[0] + suffix, "", *_include(path, heading_shift=True, start_line=1)]
    return _include(path, heading_shift=True)


def _replications_page() -> str:
    parts = ["# Replication reports", "",
             "Published results reproduced with mitpiv (`mitpiv replicate NAME`), each against the paper's "
             "numbers with its tolerance; the reports below are the files under `docs/replications/`.", ""]
    reports = sorted(f for f in (DOCS / "replications").glob("**/*.md") if "work" not in f.relative_to(DOCS).parts) \
        if (DOCS / "replications").is_dir() else []
    if not reports:
        parts += ["No replication report has been committed yet.", ""]
    for r in reports:
        parts += _include_report(r)
    return "\n".join(parts)


def _studies_page() -> str:
    parts = ["# Study reports", "",
             "Sweeps whose results are committed (`mitpiv sweep STUDY --tracking-results DIR` and the like); the "
             "reports below are the files under `docs/studies/`.", ""]
    reports = sorted((DOCS / "studies").glob("**/*.md")) if (DOCS / "studies").is_dir() else []
    if not reports:
        parts += ["No study report has been committed yet.", ""]
    for r in reports:
        parts += _include_report(r, name=r.parent.relative_to(DOCS / "studies").as_posix())
    return "\n".join(parts)


def _benchmarks_page() -> str:
    parts = ["# Benchmarks", "", "Measured wall times and accuracies (`make bench`, `mitpiv bench accuracy-time`).",
             ""]
    found = False
    for f in (DOCS / "benchmarks.md", DOCS / "accuracy-time" / "accuracy_time.md"):
        if f.is_file():
            parts += _include(f, heading_shift=True)
            found = True
    if not found:
        parts += ["No benchmark report has been committed yet.", ""]
    return "\n".join(parts)


def _generate(app) -> None:
    _write("schema.md", _schema_page())
    _write("scene_xml.md", _scene_xml_page())
    _write("examples.md", _examples_page())
    _write("replications.md", _replications_page())
    _write("studies.md", _studies_page())
    _write("benchmarks.md", _benchmarks_page())


def setup(app):
    app.connect("builder-inited", _generate)
