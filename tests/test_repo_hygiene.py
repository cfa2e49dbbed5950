"""The repository's text files carry no leftover merge-conflict markers (one slipped into
README.md once and read as documentation)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SUFFIXES = {".py", ".md", ".toml", ".xml", ".txt", ".cfg", ".yaml", ".yml", ".json", ".rst"}
SKIP = {".venv", ".git", "out", "build", "_build", "node_modules", "__pycache__", "work"}
MARKER = re.compile(r"^(<{7} |>{7} |={7}$)", re.M)


def _files():
    for p in ROOT.rglob("*"):
        if p.suffix in SUFFIXES and p.is_file() and not (set(p.relative_to(ROOT).parts) & SKIP):
            yield p


def test_no_merge_conflict_markers():
    files = list(_files())
    assert any(p.name == "README.md" for p in files)  # the walk reaches the files that matter
    bad = [f"{p.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1}"
           for p in files for text in [p.read_text(errors="replace")] for m in MARKER.finditer(text)]
    assert not bad, f"merge-conflict markers left in: {bad}"
