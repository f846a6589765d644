"""The documentation's page generator (docs/gen_pages.py), loaded once for the tests that check a
generated page: the site builds these pages, so the facts the README used to hold are checked there."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def gen_pages():
    """The module docs/gen_pages.py (the one instance per process, as docs/hooks.py loads it)."""
    if "gen_pages" not in sys.modules:
        spec = importlib.util.spec_from_file_location("gen_pages", ROOT / "docs" / "gen_pages.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules["gen_pages"] = module
        spec.loader.exec_module(module)
    return sys.modules["gen_pages"]
