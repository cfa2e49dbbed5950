"""Test-suite settings: progress bars off (tests run silent)."""

import os

os.environ.setdefault("MITPIV_QUIET", "1")
