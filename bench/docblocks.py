"""Generated blocks in hand-written Markdown pages: the benchmarks write their tables into
docs/benchmarks.md between ``<!-- begin NAME -->`` and ``<!-- end NAME -->`` markers, and the
README's performance table is regenerated from those blocks, so a rerun replaces its own
numbers and leaves the prose around them (the profiles, the goals) alone.

Written by hand: a dozen lines of string handling that no Markdown library offers as such.
"""

from __future__ import annotations

import re
from pathlib import Path


def markers(name):
    if not re.fullmatch(r"[a-z0-9_.:-]+", name):
        raise ValueError(f"block name {name!r}: use lower-case letters, digits and _ . : - only")
    return f"<!-- begin {name} -->", f"<!-- end {name} -->"


def read_block(text, name):
    """The text between NAME's markers (without them), or None when the page has no such block."""
    begin, end = markers(name)
    i = text.find(begin)
    if i < 0:
        return None
    j = text.find(end, i)
    if j < 0:
        raise ValueError(f"block {name!r}: '{begin}' has no '{end}' after it; add the end marker")
    return text[i + len(begin):j].strip("\n")


def replace_block(text, name, body, heading=None):
    """TEXT with NAME's block replaced by BODY. A page without the block gets it appended
    (under HEADING when given), so the first run of a new benchmark adds its section."""
    begin, end = markers(name)
    new = f"{begin}\n{body.strip(chr(10))}\n{end}"
    i = text.find(begin)
    if i < 0:
        sep = "" if not text or text.endswith("\n\n") else ("\n" if text.endswith("\n") else "\n\n")
        return text + sep + (f"## {heading}\n\n" if heading else "") + new + "\n"
    j = text.find(end, i)
    if j < 0:
        raise ValueError(f"block {name!r}: '{begin}' has no '{end}' after it; add the end marker")
    return text[:i] + new + text[j + len(end):]


def update_file(path, name, body, heading=None):
    """Replace NAME's block in the file at PATH (created when missing), written atomically
    (:func:`mitpiv.io.atomic.atomic_path`)."""
    from mitpiv.io.atomic import atomic_path

    path = Path(path)
    old = path.read_text() if path.exists() else ""
    new = replace_block(old, name, body, heading)
    with atomic_path(path) as tmp:
        tmp.write_text(new)


def table_rows(block):
    """The data rows of the first Markdown table in BLOCK, as lists of stripped cells."""
    rows = []
    seen_rule = False
    for line in (block or "").splitlines():
        s = line.strip()
        if not s.startswith("|"):
            if seen_rule:
                break
            continue
        cells = [c.strip() for c in s.strip("|").split("|")]
        if all(re.fullmatch(r":?-{3,}:?", c) for c in cells):
            seen_rule = True
            continue
        if seen_rule:
            rows.append(cells)
    return rows
