"""The scene XML reference: every parameter of mitpiv's Mitsuba plugins, read from the
*Parameters* sections of their module docstrings (``mitpiv/render/plugins/*.py``).

The docs build writes :func:`reference_page` to ``docs/_generated/scene_xml.md``, so a
parameter added to a plugin's docstring is on the page without editing the page. The
sources are read as text (:mod:`ast`), so nothing here imports Mitsuba or selects a variant.

A parameter line of a docstring reads (numpydoc, with mitpiv's segments after the type)::

    name[, name...] : type [unit][, default X][, required ...][, range R][, one of A, B]
        Description, indented.

Segments are separated by ``,`` or ``;``; a line naming several parameters gives each its
own type, unit, default and range when it lists as many (``near_clip, far_clip : float [mm];
default 0.01, 1e7``), types and units padded with the last one (``float, int`` for four
names: one float, three ints), and otherwise shares the whole text.
"""

from __future__ import annotations

import ast
import re
import textwrap
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Parameter", "PluginDoc", "module_docstring", "parse_parameters", "parse_plugin_docstring", "plugin_docs",
           "reference_page", "PLUGIN_DIR", "KIND_ORDER"]

#: Where the plugin modules live (one plugin per module; ``_``-prefixed modules are helpers).
PLUGIN_DIR = Path(__file__).resolve().parent / "plugins"
#: The page's order of plugin kinds (the XML element each is written as).
KIND_ORDER = ("sensor", "emitter", "phase", "integrator", "bsdf", "shape", "medium", "film", "rfilter", "texture")

_SEGMENT = re.compile(r"\s*[,;]\s*(?=(?:default|required|range|one of)\b)")
_REGISTER = re.compile(r"\bmi\.register_(\w+)\(\s*[\"'](\w+)[\"']")
_SECTION_RULE = re.compile(r"^-{3,}\s*$")
_ROLE = re.compile(r":(func|mod|class|meth|attr|data|obj|exc):`([^`]+)`")


@dataclass(frozen=True)
class Parameter:
    """One parameter as its docstring states it (text as written, ``None`` where not stated)."""

    name: str
    type: str
    unit: str | None
    default: str | None
    required: str | None  # "required" or "required for ..." as written
    range: str | None  # "range R" -> "R"; "one of A, B" -> "one of A, B"
    description: str


@dataclass(frozen=True)
class PluginDoc:
    """A plugin's reference: name, XML element kind, summary, parameters and XML example."""

    name: str
    kind: str | None
    module: str
    summary: str
    intro: str
    parameters: tuple[Parameter, ...]
    xml_example: str | None


# ------------------------------------------------------------------ parsing
def module_docstring(source: str) -> str:
    """The module docstring of Python ``source`` (cleaned, as :func:`inspect.cleandoc`)."""
    return ast.get_docstring(ast.parse(source)) or ""


def _split_top(text: str) -> list[str]:
    """``text`` split at the commas outside brackets and ````literals````, parts stripped."""
    parts, depth, literal, cur, i = [], 0, False, [], 0
    while i < len(text):
        if text.startswith("``", i):
            literal = not literal
            cur.append("``")
            i += 2
            continue
        c = text[i]
        if not literal and c in "([{":
            depth += 1
        elif not literal and c in ")]}":
            depth = max(depth - 1, 0)
        if c == "," and depth == 0 and not literal:
            parts.append("".join(cur).strip())
            cur = []
        else:
            cur.append(c)
        i += 1
    parts.append("".join(cur).strip())
    return [p for p in parts if p]


def _distribute(text: str | None, n: int, *, pad: bool) -> list[str | None]:
    """``text`` for each of ``n`` names: one part each when it lists ``n`` (``pad``: fewer,
    padded with the last), else the whole text for all."""
    if text is None or n == 1:
        return [text] * n
    parts = _split_top(text)
    if len(parts) == n:
        return parts
    if pad and 1 < len(parts) < n:
        return parts + [parts[-1]] * (n - len(parts))
    return [text] * n


def _section_lines(doc: str, title: str) -> list[str]:
    """The lines of the numpydoc section ``title`` (to the next section or directive)."""
    lines = doc.splitlines()
    for i in range(len(lines) - 1):
        if lines[i].strip() == title and _SECTION_RULE.match(lines[i + 1]):
            out = []
            for j in range(i + 2, len(lines)):
                line = lines[j]
                nxt = lines[j + 1] if j + 1 < len(lines) else ""
                if (line.strip() and not line[0].isspace() and _SECTION_RULE.match(nxt)) or line.startswith(".. "):
                    break
                out.append(line)
            return out
    return []


def _parse_spec(spec: str) -> dict:
    head, *segments = _SEGMENT.split(spec.strip())
    if re.match(r"(default|required|range|one of)\b", head):  # no type: the spec opens with a segment
        head, segments = "", [head, *segments]
    m = re.search(r"\[([^\]]*)\]", head)
    unit = m.group(1).strip() if m else None
    typ = (head[:m.start()] + head[m.end():] if m else head).strip().strip(",;").strip()
    out = {"type": typ, "unit": unit, "default": None, "required": None, "range": None}
    for seg in segments:
        seg = seg.strip().rstrip(".")
        if seg.startswith("default"):
            out["default"] = seg[len("default"):].strip()
        elif seg.startswith("required"):
            out["required"] = seg
        elif seg.startswith("range"):
            out["range"] = seg[len("range"):].strip()
        elif seg.startswith("one of"):
            out["range"] = seg
    return out


def parse_parameters(doc: str) -> list[Parameter]:
    """The parameters of the *Parameters* section of a (cleaned) docstring, in order, one
    :class:`Parameter` per name (a line naming several gives several)."""
    items: list[tuple[str, list[str]]] = []
    for line in _section_lines(doc, "Parameters"):
        if line.strip() and not line[0].isspace():
            items.append((line.strip(), []))
        elif items and line.strip():
            items[-1][1].append(line.strip())
        elif items and items[-1][1]:
            items[-1][1].append("")  # a paragraph break inside a description
    params = []
    for header, body in items:
        names_text, sep, spec = header.partition(" : ")
        names = [n.strip().strip("`") for n in _split_top(names_text)] if sep else [header]
        s = _parse_spec(spec) if sep else {"type": "", "unit": None, "default": None, "required": None, "range": None}
        n = len(names)
        types = _distribute(s["type"], n, pad=True)
        units = _distribute(s["unit"], n, pad=True)
        defaults = _distribute(s["default"], n, pad=False)
        ranges = _distribute(s["range"], n, pad=False)
        text = re.sub(r"\s*\n\s*\n\s*", "\n\n", "\n".join(body).strip())
        description = "\n\n".join(" ".join(p.split()) for p in text.split("\n\n"))
        for k, name in enumerate(names):
            params.append(Parameter(name=name, type=types[k] or "", unit=units[k], default=defaults[k],
                                    required=s["required"], range=ranges[k], description=description))
    return params


def _xml_example(doc: str) -> str | None:
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        if re.match(r"\.\. code-block::\s*xml\s*$", line.strip()) and not line[0].isspace():
            block = []
            for nxt in lines[i + 1:]:
                if nxt.strip() and not nxt[0].isspace():
                    break
                block.append(nxt)
            return textwrap.dedent("\n".join(block)).strip("\n") or None
    return None


def parse_plugin_docstring(doc: str, *, module: str, kind: str | None = None) -> PluginDoc:
    """A plugin's :class:`PluginDoc` from its module docstring, whose first line is the
    plugin's name as a literal, a colon and a summary."""
    paragraphs = doc.split("\n\nParameters\n")[0].strip().split("\n\n")
    first = " ".join(paragraphs[0].split())
    m = re.match(r"``(\w+)``\s*:\s*(.*)$", first)
    name, summary = (m.group(1), m.group(2)) if m else (module, first)
    intro = "\n\n".join(" ".join(p.split()) for p in paragraphs[1:] if p.strip())
    return PluginDoc(name=name, kind=kind, module=module, summary=summary, intro=intro,
                     parameters=tuple(parse_parameters(doc)), xml_example=_xml_example(doc))


def plugin_docs(plugin_dir: Path | str = PLUGIN_DIR) -> list[PluginDoc]:
    """Every plugin module of ``plugin_dir`` (those that call ``mi.register_<kind>``), by kind
    (:data:`KIND_ORDER`) then name."""
    docs = []
    for path in sorted(Path(plugin_dir).glob("*.py")):
        if path.name.startswith("_"):
            continue
        src = path.read_text(encoding="utf-8")
        reg = _REGISTER.search(src)
        if reg is None:
            continue
        doc = parse_plugin_docstring(module_docstring(src), module=path.stem, kind=reg.group(1))
        docs.append(doc if doc.name == reg.group(2) else PluginDoc(**{**doc.__dict__, "name": reg.group(2)}))
    order = {k: i for i, k in enumerate(KIND_ORDER)}
    return sorted(docs, key=lambda d: (order.get(d.kind, len(order)), d.name))


# ------------------------------------------------------------------ the page
def _md(text: str | None, *, cell: bool = True) -> str:
    """reStructuredText inline markup as MyST Markdown (literals, cross-references), with
    table-cell pipes escaped."""
    if not text:
        return ""
    out = text.replace("``", "`")
    out = _ROLE.sub(lambda m: "{py:" + m.group(1) + "}`" + m.group(2) + "`", out)
    if cell:
        out = out.replace("|", "\\|").replace("\n\n", " ")
    return out


def _label(d: PluginDoc) -> str:
    return "scene-xml-" + d.name.replace("_", "-")


_PLACEMENT = """\
## Camera placement

Both cameras (`distorted_pinhole`, `plenoptic`) are posed either by `to_world` (Mitsuba's
transform; with `<lookat origin="..." target="..." up="..."/>` the camera at `origin` looks
at `target` and the image's up is `up` projected on the image plane) or by a placement
around a target, as {py:func}`mitpiv.physics.camera.place_camera` computes it: the angles
are measured in the laser-sheet frame, `e1` = `laser_direction` (default (1, 0, 0)), `e3` =
`sheet_normal` (default (0, 0, 1), made orthogonal to `e1`) and `e2 = e3 x e1` in the sheet
plane. The camera sits at

$$
\\mathbf{c} = \\mathbf{t} + d\\,(\\cos\\epsilon\\cos\\alpha\\,\\mathbf{e}_1
+ \\cos\\epsilon\\sin\\alpha\\,\\mathbf{e}_2 + \\sin\\epsilon\\,\\mathbf{e}_3)
$$

with `t` = `target` [mm], `d` = `distance_mm`, `alpha` = `azimuth_deg` (from `e1` towards
`e2`) and `epsilon` = `elevation_deg` (out of the sheet plane towards `e3`). Its optical
axis points from the camera to the target, so `distance_mm` is the target's distance along
the optical axis (what a pinhole's PSF magnification `f / (d - f)` is derived from). The
image's up is `e3` projected on the image plane, or `e2` when the camera looks within
8.1 deg of `e3` (`|sin(elevation)| >= 0.99`). Azimuth 0, elevation 0 is a camera on the
laser axis downstream (forward scatter, scattering angle 0), azimuth 180 a backward-scatter
camera; the scattering angle is `acos(cos(elevation) cos(azimuth))`.

```xml
<sensor type="distorted_pinhole" id="cam0">
    <point name="target" value="0, 0, 0"/>
    <float name="azimuth_deg" value="35"/>
    <float name="elevation_deg" value="40"/>
    <float name="distance_mm" value="1000"/>
    <float name="focal_length_mm" value="85"/>
    ...
</sensor>
```
"""


def reference_page(docs: list[PluginDoc] | None = None, *, figure: str | None = "../figures/placement.png") -> str:
    """The scene XML reference as MyST Markdown: the placement (with ``figure``, a path
    relative to the page) and, per plugin, its summary, a table of its parameters (type,
    unit, default, range, description) and its XML example."""
    docs = plugin_docs() if docs is None else docs
    parts = ["# Scene XML reference", "",
             "The parameters of mitpiv's Mitsuba plugins, as a scene file writes them "
             "(`<float name=\"focal_length_mm\" value=\"85\"/>` inside `<sensor type=\"distorted_pinhole\">`). "
             "Generated at the docs build from the plugins' module docstrings "
             "(`mitpiv/render/plugins/*.py`, {py:mod}`mitpiv.render.plugin_reference`); the same tables, with "
             "each plugin's notes, are on the {doc}`/api` page. Lengths are in millimetres unless the name or the "
             "unit column says otherwise. A parameter a plugin does not know is refused when the scene loads.",
             "", "The XML element of each type: `float`, `integer`, `boolean` and `string` as named; `point` and "
             "`vector` are `<point>` / `<vector>` with `value=\"x, y, z\"`; `transform` is "
             "`<transform name=\"to_world\">`; `reference` is `<ref name=\"...\" id=\"...\"/>`.", ""]
    parts += ["Plugins: " + ", ".join(f"{{ref}}`{d.name} <{_label(d)}>` ({d.kind})" for d in docs) + ".", ""]
    parts += [_PLACEMENT]
    if figure:
        parts += [f"![The placement angles: azimuth in the sheet plane from the laser direction, elevation out of it, "
                  f"the camera at distance_mm from the target, looking at it, the image's up vector]({figure})", ""]
    for d in docs:
        kind = f" ({d.kind})" if d.kind else ""
        summary = d.summary[:1].upper() + d.summary[1:]
        parts += [f"({_label(d)})=", f"## `{d.name}`{kind}", "", _md(summary, cell=False), ""]
        if d.intro:
            parts += [_md(d.intro, cell=False), ""]
        parts += [f"Module {{py:mod}}`mitpiv.render.plugins.{d.module}`; {len(d.parameters)} parameters.", ""]
        parts += ["| Parameter | Type | Unit | Default | Range | Description |", "|---|---|---|---|---|---|"]
        for p in d.parameters:
            unit = "" if p.unit in (None, "--") else p.unit
            default = p.default if p.default is not None else (p.required or "")
            parts.append(f"| `{p.name}` | {_md(p.type)} | {_md(unit)} | {_md(default)} | {_md(p.range)} | "
                         f"{_md(p.description)} |")
        parts.append("")
        if d.xml_example:
            parts += ["```xml", d.xml_example, "```", ""]
    return "\n".join(parts)
