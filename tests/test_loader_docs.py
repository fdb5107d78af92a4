"""The python examples of docs/dataset.md "Loading" run as written against the test dataset."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

pytest_plugins = ["loader_conftest"]

DOC = Path(__file__).resolve().parent.parent / "docs" / "dataset.md"


def loading_blocks() -> list[str]:
    """The ```python blocks of the Loading section (up to the next level-2 heading)."""
    text = DOC.read_text(encoding="utf-8")
    start = text.index("\n## Loading\n")
    end = text.find("\n## ", start + 1)
    section = text[start:end if end > 0 else len(text)]
    return re.findall(r"```python\n(.*?)```", section, flags=re.S)


def test_loading_examples_run(vts_dataset: Path, tmp_path: Path,
                              monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("torch")
    blocks = loading_blocks()
    assert len(blocks) >= 4
    shutil.copytree(vts_dataset, tmp_path / "data" / "dataset")
    monkeypatch.chdir(tmp_path)
    import fsspec

    memory = fsspec.filesystem("memory")
    before = set(memory.store)
    namespace: dict[str, object] = {"__name__": "docs_example"}
    try:
        for k, code in enumerate(blocks):
            exec(compile(code, f"{DOC.name}:Loading block {k + 1}", "exec"), namespace)
    finally:
        for key in set(memory.store) - before:
            memory.store.pop(key, None)
        memory.pseudo_dirs[:] = [d for d in memory.pseudo_dirs if not d.startswith("/copy")]
