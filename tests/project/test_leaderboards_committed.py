"""The published leaderboard entries (leaderboards/) follow their schema and their tables."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.fixtures.data import ROOT
from vtsbench.evaluation.leaderboard import entry_schema_errors

BOARDS = ROOT / "leaderboards"
ENTRIES = sorted(p for p in BOARDS.glob("*/*/*.json"))


@pytest.mark.skipif(not ENTRIES, reason="no published entries")
@pytest.mark.parametrize("path", ENTRIES, ids=lambda p: str(p.relative_to(BOARDS)))
def test_entry_is_valid_and_listed(path: Path) -> None:
    doc = json.loads(path.read_text())
    assert entry_schema_errors(doc) == []
    assert doc["split"] == path.parent.name and doc["id"] == path.stem
    table = (path.parent / "leaderboard.md").read_text()
    assert f"| {doc['method']} |" in table
