"""Small reference files for the tests, each with its provenance.

Every file here other than Python carries where its numbers come from (publication and
table, program and version, how it was produced): a CSV or text file in its first line,
``# provenance: ...``; a JSON file in a top-level ``"provenance"`` string.
tests/test_reference_data.py enforces this. Keep the files small (kilobytes).
"""

import csv
import json
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
PROVENANCE_PREFIX = "# provenance:"
TEXT_SUFFIXES = (".csv", ".tsv", ".txt")


def provenance(name: str | Path) -> str:
    """The provenance text of a data file (empty if it has none)."""
    path = DATA_DIR / name
    if path.suffix == ".json":
        value = json.loads(path.read_text(encoding="utf-8")).get("provenance", "")
        return value.strip() if isinstance(value, str) else ""
    if path.suffix in TEXT_SUFFIXES:
        with path.open(encoding="utf-8") as fh:
            first = fh.readline()
        return first[len(PROVENANCE_PREFIX):].strip() if first.startswith(PROVENANCE_PREFIX) else ""
    return ""


def read_table(name: str) -> list[dict[str, str]]:
    """Rows of a CSV file in tests/data as dicts of strings (comment lines skipped)."""
    with (DATA_DIR / name).open(encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def read_json(name: str) -> dict:
    """A JSON file in tests/data (its "provenance" key included)."""
    return json.loads((DATA_DIR / name).read_text(encoding="utf-8"))
