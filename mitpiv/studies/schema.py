"""The typed experiment schema: one frozen pydantic model per TOML table, unknown keys
rejected with the nearest valid name, values range-checked, the whole experiment validated
before any stage runs. The same models generate the CLI's ``--set table.field=value``
handling, its typed flags, and the ``mitpiv schema`` reference.

pydantic (v2) does the validation; this module only builds models from the signatures of
the physics functions a table feeds (flows, droplet fields, the sensor model), so that a
table and the function it configures cannot drift apart, and turns pydantic's errors into
one message that names the table, the key, the bad value and the valid choices.
"""

from __future__ import annotations

import difflib
import inspect
import json
import tomllib
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import annotated_types
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model

from mitpiv.errors import ConfigError

__all__ = ["Table", "Vec3", "model_from_signature", "validate", "format_errors", "parse_value", "set_dotted",
           "apply_overrides", "describe", "read_toml", "discriminated", "models_in", "LOADER_DEFAULTS"]


class Table(BaseModel):
    """Base of every experiment table: frozen, unknown keys forbidden, numbers finite (no
    NaN or infinity). :func:`validate` checks types strictly (a string is not a number, a
    fractional number not an integer, a boolean neither)."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, allow_inf_nan=False)


Vec3 = Annotated[tuple[float, float, float], Field(description="three numbers (x, y, z)")]


def read_toml(path, what: str = "experiment") -> dict:
    """Read a TOML file; a missing or malformed file is a :class:`ConfigError` naming it."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} file {str(path)!r} does not exist.")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8-sig"))  # -sig: a UTF-8 byte-order mark (Notepad's) is skipped
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{what} file {str(path)!r} is not valid TOML: {e}.") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{what} file {str(path)!r} is not a TOML text file (byte {e.start} is not UTF-8 text); "
                          f"give the experiment's .toml file.") from None


# ------------------------------------------------------------------ models from signatures
def _annotation_for(param: inspect.Parameter, hints: dict) -> Any:
    ann = hints.get(param.name, inspect.Parameter.empty)
    default = param.default
    if ann is inspect.Parameter.empty or ann is Any:
        if isinstance(default, bool):
            ann = bool
        elif isinstance(default, int | float):
            ann = float
        elif isinstance(default, str):
            ann = str
        elif isinstance(default, tuple | list):
            flat = default
            if flat and all(isinstance(x, tuple | list) for x in flat):
                ann = tuple[tuple[float, ...], ...]
            else:
                ann = Vec3 if len(flat) == 3 else tuple[float, ...]
        elif default is None:
            ann = float | tuple[float, ...] | None
        else:
            ann = Any
    return ann


def model_from_signature(name: str, fn: Callable, *, skip: tuple[str, ...] = (), extra_fields: Mapping | None = None,
                         doc: str | None = None, base: type[BaseModel] = Table) -> type[BaseModel]:
    """A frozen pydantic model whose fields are the keyword parameters of ``fn`` (a function,
    class or dataclass), typed from the annotations or, where there are none, from the
    defaults. ``skip`` leaves parameters out (e.g. ``seed``, which the experiment supplies);
    ``extra_fields`` adds ``name: (type, FieldInfo)`` pairs."""
    target = fn
    sig = inspect.signature(target)
    try:
        hints = typing.get_type_hints(target.__init__ if inspect.isclass(target) else target)
    except Exception:  # noqa: BLE001 - unresolvable annotations fall back to the defaults
        hints = {}
    fields: dict[str, Any] = {}
    meanings = docstring_meanings(inspect.getdoc(fn) or "")
    for p in sig.parameters.values():
        if p.name in skip or p.name == "self" or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        ann = _annotation_for(p, hints)
        desc = meanings.get(p.name)
        if p.default is inspect.Parameter.empty:
            fields[p.name] = (ann, Field(..., description=desc))
        else:
            fields[p.name] = (ann, Field(p.default, description=desc))
    fields.update(extra_fields or {})
    model = create_model(name, __base__=base, __doc__=doc or (inspect.getdoc(fn) or "").split("\n\n")[0], **fields)
    return model


def docstring_meanings(doc: str) -> dict[str, str]:
    """Each parameter's description in a docstring's ``Parameters`` or ``Attributes``
    section (numpydoc layout: ``name[, name] : type`` at the section's indentation, the
    description on the more indented lines below), joined into one line; a parameter with
    no description lines gives its type. Written by hand: numpydoc parses the same layout
    but is a documentation dependency (it needs Sphinx), not a run-time one."""
    out: dict[str, str] = {}
    described: set[str] = set()
    lines = doc.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].strip() in ("Parameters", "Attributes") and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}:
            i += 2
            names: list[str] = []
            while i < len(lines) and lines[i].strip() and not (i + 1 < len(lines) and lines[i + 1].strip()
                                                                and set(lines[i + 1].strip()) == {"-"}):
                line = lines[i]
                if not line[:1].isspace() and " : " in line:
                    head, text = line.split(" : ", 1)
                    names = [n.strip() for n in head.split(",") if n.strip()]
                    for n in names:
                        out[n] = text.strip()
                elif line[:1].isspace() and names:
                    for n in names:
                        out[n] = f"{out[n] if n in described else ''} {line.strip()}".strip()
                        described.add(n)
                i += 1
        i += 1
    return out


def discriminated(models: Mapping[str, type[BaseModel]], *, key: str = "kind") -> Any:
    """An ``Annotated`` union of ``models`` told apart by the literal field ``key``: each
    model gets a ``key: Literal[name]`` field."""
    tagged = []
    for tag, m in models.items():
        tagged.append(create_model(m.__name__, __base__=m, __doc__=m.__doc__,
                                   **{key: (Literal[tag], Field(..., description=f"{key} of this table"))}))
    return Annotated[Union[tuple(tagged)], Field(discriminator=key)]  # noqa: UP007 - a runtime-built union


# ------------------------------------------------------------------------ validation errors
def _field_names(model: type[BaseModel] | None) -> list[str]:
    return list(model.model_fields) if model is not None else []


def _submodel(model: type[BaseModel] | None, loc: tuple, raw: Any) -> tuple[type[BaseModel] | None, Any]:
    """Walk ``loc`` through nested models (and a discriminated union, by the raw kind)."""
    cur, val = model, raw
    for part in loc:
        if cur is None or not isinstance(part, str) or part not in cur.model_fields:
            return None, None
        ann = cur.model_fields[part].annotation
        val = val.get(part) if isinstance(val, Mapping) else None
        cur = _model_of(ann, val)
    return cur, val


def _model_of(ann, raw) -> type[BaseModel] | None:
    if inspect.isclass(ann) and issubclass(ann, BaseModel):
        return ann
    for arg in typing.get_args(ann):
        m = _model_of(arg, raw)
        if m is None:
            continue
        kind_field = m.model_fields.get("kind")
        if kind_field is not None and isinstance(raw, Mapping):
            allowed = typing.get_args(kind_field.annotation)
            if raw.get("kind") not in allowed:
                continue
        return m
    return None


def _where(loc: tuple) -> tuple[str, str]:
    parts = [str(p) for p in loc]
    if not parts:  # a check across tables (a model validator of the whole experiment)
        return "", "tables"
    if len(parts) == 1:
        return "", parts[0]
    # a discriminated union inserts the tag as a loc element: drop it
    return "[" + ".".join(parts[:-1]) + "]", parts[-1]


def format_errors(exc: ValidationError, model: type[BaseModel], raw: Mapping, *, source: str = "experiment") -> str:
    """One message for all of pydantic's errors: table, key, bad value, valid choices."""
    lines: list[str] = []
    grouped: dict[tuple, list[dict]] = {}
    for err in exc.errors(include_url=False):
        loc = _clean_loc(model, err["loc"][:-1], raw) + err["loc"][-1:] if err["type"] == "extra_forbidden" \
            else _clean_loc(model, err["loc"], raw)
        grouped.setdefault(loc, []).append(err)
    for loc, errs in grouped.items():
        err = errs[0]
        if len(errs) > 1 and all(e["type"] not in ("extra_forbidden", "missing") for e in errs):
            # a value that fits none of a union's forms: one line with every form's complaint
            err = {**err, "type": "value_error", "msg": " or ".join(
                dict.fromkeys(e["msg"].removeprefix("Value error, ").rstrip(".") for e in errs))}
        table, key = _where(loc)
        where = f"{table} {key}".strip() if table else key
        if len(loc) == 1 and _submodel(model, loc, raw)[0] is not None:
            where = f"[{key}]"  # an error of a whole table (its cross-field checks)
        parent, _ = _submodel(model, loc[:-1], raw)
        kind = err["type"]
        value = err.get("input")
        if kind == "extra_forbidden":
            names = _field_names(parent)
            close = difflib.get_close_matches(key, names, n=1, cutoff=0.5)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            lines.append(f"{where}: unknown key (value {value!r}).{hint} Valid keys: {', '.join(names)}.")
        elif kind == "missing":
            fi = parent.model_fields.get(key) if parent is not None else None
            desc = f" ({fi.description})" if fi is not None and fi.description else ""
            lines.append(f"{where}: required key is missing{desc}.")
        elif kind in ("literal_error", "union_tag_invalid", "enum"):
            ctx = err.get("ctx") or {}
            choices = ctx.get("expected") or ctx.get("expected_tags") or ""
            bad = value if kind != "union_tag_invalid" else ctx.get("tag")
            if kind == "union_tag_invalid":
                where = f"[{key}] {ctx.get('discriminator', 'kind').strip(chr(39))}"
            lines.append(f"{where}: {bad!r} is not a valid choice; choose one of {choices}.")
        elif kind == "union_tag_not_found":
            members = models_in(parent.model_fields[key].annotation) if parent is not None else []
            tags = [t for m in members for t in typing.get_args(m.model_fields["kind"].annotation)]
            names = sorted({n for m in members for n in m.model_fields})
            table_raw = value if isinstance(value, Mapping) else {}
            for bad in [k for k in table_raw if k not in names]:
                close = difflib.get_close_matches(bad, names, n=1, cutoff=0.5)
                hint = f" Did you mean {close[0]!r}?" if close else ""
                lines.append(f"[{key}] {bad}: unknown key (value {table_raw[bad]!r}).{hint}")
            lines.append(f"[{key}] needs kind = one of {', '.join(repr(t) for t in tags)}.")
        else:
            msg = err["msg"].removeprefix("Value error, ").rstrip(".")
            got = "" if isinstance(value, Mapping) or "got" in msg else f", got {value!r}"
            lines.append(f"{where}: {msg}{got}.")
    head = f"{source}: " if source else ""
    return head + ("invalid settings:\n  " + "\n  ".join(lines) if len(lines) > 1 else "".join(lines))


def _clean_loc(model: type[BaseModel], loc: tuple, raw: Any) -> tuple:
    """An error location as the user's keys: pydantic's union-member labels and
    discriminated-union tags removed (``("flow", "vortex_ring", "x")`` -> ``("flow", "x")``)."""
    out: list = []
    cur: type[BaseModel] | None = model
    val = raw
    for part in loc:
        if isinstance(part, int):
            out.append(part)
            cur, val = None, None
            continue
        if cur is not None and part in cur.model_fields:
            out.append(part)
            val = val.get(part) if isinstance(val, Mapping) else None
            cur = _model_of(cur.model_fields[part].annotation, val)
        elif cur is None and not out:
            out.append(part)
        elif cur is None and isinstance(part, str) and not _looks_like_label(part):
            out.append(part)
    return tuple(out)


def _looks_like_label(part: str) -> bool:
    """pydantic names union members by their type (``constrained-float``, ``tuple[...]``)."""
    return any(ch in part for ch in "[]-") or part in ("int", "float", "str", "bool", "list", "tuple", "dict")


def validate(model: type[BaseModel], raw: Mapping, *, source: str = "experiment") -> BaseModel:
    """``raw`` validated against ``model`` in pydantic's strict mode (as JSON: a TOML array
    is a tuple where the field is one), with pydantic's errors turned into one
    :class:`ConfigError`. Strict: ``"0.1"`` is not a number, ``2.5`` or ``true`` not an
    integer, ``1`` not a boolean; an integer is a valid number."""

    def plain(value, where: str):
        if isinstance(value, Mapping):
            return {k: plain(v, f"{where}.{k}" if where else str(k)) for k, v in value.items()}
        if isinstance(value, list | tuple):
            return [plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if value is None or isinstance(value, str | int | float | bool):
            return value
        raise ConfigError(f"{source}: {where} = {value!r} is a {type(value).__name__}; experiment values are "
                          f"numbers, strings, booleans, arrays or tables (no dates or times).")

    try:
        text = json.dumps(plain(raw, ""), allow_nan=True)
        return model.model_validate_json(text, strict=True)
    except ValidationError as e:
        raise ConfigError(format_errors(e, model, raw, source=source)) from None


# --------------------------------------------------------------------------- overrides
def parse_value(text: str) -> Any:
    """A ``--set`` value: a TOML value (``5``, ``0.1``, ``[1, 2]``, ``true``, ``"x"``), else
    the bare text as a string (``--set reconstruction.method=smart``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_dotted(cfg: dict, key: str, value) -> None:
    """Set ``cfg["a"]["b"]["c"] = value`` for key "a.b.c", creating tables on the way."""
    parts = str(key).split(".")
    if not all(parts):
        raise ConfigError(f"parameter name {key!r} is not a dotted key like 'reconstruction.iterations'.")
    node = cfg
    for p in parts[:-1]:
        nxt = node.setdefault(p, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"parameter {key!r}: {p!r} is a value, not a table.")
        node = nxt
    node[parts[-1]] = value


def apply_overrides(cfg: dict, overrides: Mapping | None) -> dict:
    """``cfg`` with every dotted-key override set (a deep copy: ``cfg`` is not changed)."""
    import copy

    out = copy.deepcopy(cfg)
    for k, v in (overrides or {}).items():
        set_dotted(out, k, v)
    return out


# ------------------------------------------------------------------------------ reference
def _type_name(ann) -> str:
    origin = typing.get_origin(ann)
    if origin is Annotated:
        return _type_name(typing.get_args(ann)[0])
    if origin is Literal:
        return " | ".join(repr(a) for a in typing.get_args(ann))
    if origin in (Union, types.UnionType):
        return " | ".join(_type_name(a) for a in typing.get_args(ann))
    if origin in (tuple, list):
        args = [a for a in typing.get_args(ann) if a is not Ellipsis]
        if len(typing.get_args(ann)) == 2 and typing.get_args(ann)[1] is Ellipsis:
            return f"[{_type_name(args[0])}, ...]"
        return "[" + ", ".join(_type_name(a) for a in args) + "]"
    if ann is type(None):
        return "none"
    if inspect.isclass(ann) and issubclass(ann, BaseModel):
        return "table"
    return getattr(ann, "__name__", str(ann))


def _range(fi) -> str:
    out = []
    for m in fi.metadata:
        for attr, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            v = getattr(m, attr, None)
            if v is not None and isinstance(m, annotated_types.BaseMetadata):
                out.append(f"{sym} {v}")
        if isinstance(m, annotated_types.MinLen):
            out.append(f"len >= {m.min_length}")
        if isinstance(m, annotated_types.MaxLen):
            out.append(f"len <= {m.max_length}")
    return ", ".join(out)


#: Top-level experiment keys that a kind's model requires but an experiment file may leave
#: out, because the loader fills them in before validating
#: (:func:`mitpiv.studies.runner.load_experiment`: ``name`` from the file's name); each with
#: the default the reference shows instead of "required".
LOADER_DEFAULTS: dict[str, str] = {"name": "(the file name)"}


def _default(fi, loader_default: str | None = None) -> str:
    from pydantic_core import PydanticUndefined

    if fi.is_required():
        return loader_default or "required"
    d = fi.default if fi.default is not PydanticUndefined else (fi.default_factory() if fi.default_factory else None)
    if isinstance(d, BaseModel):
        return "(table)"
    return "none" if d is None else repr(d)


def describe(model: type[BaseModel], *, title: str | None = None) -> str:
    """A Markdown reference of ``model``: a section per table with every field's type,
    default, range and meaning (units are in the field names)."""
    lines = [f"# {title or model.__name__}", "", (model.__doc__ or "").strip(), ""]
    top = []
    sections = []
    for name, fi in model.model_fields.items():
        sub = [m for m in models_in(fi.annotation)]
        if sub:
            for m in sub:
                tag = m.model_fields.get("kind")
                label = f"[{name}]" + (f" kind = {typing.get_args(tag.annotation)[0]!r}"
                                       if tag is not None and typing.get_origin(tag.annotation) is Literal else "")
                sections.append((label, m, fi))
        else:
            top.append((name, fi))
    lines += ["| key | type | default | range | meaning |", "|---|---|---|---|---|"]
    lines += [_row(n, f, LOADER_DEFAULTS.get(n)) for n, f in top]
    for label, m, fi in sections:
        lines += ["", f"## {label}", "", ((fi.description or m.__doc__ or "").strip().split("\n")[0]), "",
                  "| key | type | default | range | meaning |", "|---|---|---|---|---|"]
        lines += [_row(n, f) for n, f in m.model_fields.items()]
    return "\n".join(lines) + "\n"


def _row(name, fi, loader_default: str | None = None) -> str:
    desc = (fi.description or "").replace("|", "/").replace("\n", " ")
    default = _default(fi, loader_default).replace("|", "/")
    return f"| `{name}` | {_type_name(fi.annotation).replace('|', '/')} | {default} | " \
           f"{_range(fi)} | {desc} |"


def models_in(ann) -> list[type[BaseModel]]:
    """The pydantic models in an annotation (a model, an optional one, a union's members)."""
    if inspect.isclass(ann) and issubclass(ann, BaseModel):
        return [ann]
    out = []
    for a in typing.get_args(ann):
        out += models_in(a)
    return out
