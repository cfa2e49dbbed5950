"""Reference files in tests/data/ carry their provenance and stay small.

A CSV or text file names its source in its first line (``# provenance: ...``), a JSON file in
a top-level ``"provenance"`` string (see tests/data/__init__.py). Any other kind of file is
refused: reference data this small is kept as text, so that a reviewer can read it.
"""

import json

import pytest

from tests.data import DATA_DIR, PROVENANCE_PREFIX, TEXT_SUFFIXES, provenance, read_table

MAX_BYTES = 100_000  # small reference files (kilobytes), not data sets
MIN_PROVENANCE_CHARS = 40  # a source named precisely, not a placeholder


def _data_files():
    return sorted(p for p in DATA_DIR.rglob("*")
                  if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts)


def test_there_is_reference_data_to_check():
    assert _data_files(), f"no reference files in {DATA_DIR}"


@pytest.mark.parametrize("path", _data_files(), ids=lambda p: str(p.relative_to(DATA_DIR)))
def test_every_reference_file_names_its_source(path):
    assert path.suffix in TEXT_SUFFIXES + (".json",), (
        f"{path.name}: reference data must be CSV/TSV/text (first line '{PROVENANCE_PREFIX} ...') or JSON "
        f"(a \"provenance\" key)")
    text = provenance(path)
    assert len(text) >= MIN_PROVENANCE_CHARS, f"{path.name}: missing or too short provenance: {text!r}"
    assert path.stat().st_size <= MAX_BYTES, f"{path.name}: {path.stat().st_size} bytes; keep reference files small"


def test_the_checker_refuses_files_without_provenance(tmp_path):
    (tmp_path / "bare.csv").write_text("j,n,m\n1,0,0\n")
    (tmp_path / "late.csv").write_text("j,n,m\n# provenance: a line that is not the first one, Table 1\n")
    (tmp_path / "bare.json").write_text(json.dumps({"values": [1, 2]}))
    (tmp_path / "typed.json").write_text(json.dumps({"provenance": ["not", "a", "string"]}))
    (tmp_path / "good.json").write_text(json.dumps({"provenance": "Some et al. (1999), Table 2, typed by hand"}))
    for name in ("bare.csv", "late.csv", "bare.json", "typed.json"):
        assert provenance(tmp_path / name) == "", name
    assert provenance(tmp_path / "good.json").startswith("Some et al.")


def test_tables_read_without_their_comment_lines():
    rows = read_table("zernike_indices.csv")
    assert rows and set(rows[0]) == {"convention", "j", "n", "m"}
    assert {r["convention"] for r in rows} == {"noll", "ansi"}
