"""Every ```python block of README.md and docs/*.md runs as pasted, against a tiny dataset and
small simulated recordings made by the tests.

Blocks of one page run in order in one namespace (a page's later examples use its earlier
ones), in a temporary folder holding the paths the examples name: data/dataset,
demo-data/dataset and data/ds (the test dataset), rec/ball (simulated ball presses) and
dataPack.npz (a Taxim-style pack of three presses). A block
that cannot run here is preceded by `<!-- no-test: REASON -->`; NO_TEST_MAX keeps that list
short.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from tests.fixtures.data import ROOT

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"(?:<!--\s*no-test:\s*(?P<why>.*?)\s*-->\n)?```python\n(?P<code>.*?)```",
                   re.S)
#: At most this many blocks may be left out (each with its reason in the markdown).
NO_TEST_MAX = 3


def blocks(page: Path) -> list[tuple[int, str, str | None]]:
    """(line, code, reason to skip or None) of each python block of a page."""
    text = page.read_text(encoding="utf-8")
    return [(text[:m.start("code")].count("\n"), m.group("code"), m.group("why"))
            for m in BLOCK.finditer(text)]


def test_few_blocks_are_left_out_and_each_says_why() -> None:
    left_out = [(p.name, line, why) for p in PAGES for line, _c, why in blocks(p) if why]
    assert len(left_out) <= NO_TEST_MAX, left_out
    assert all(len(why) > 10 for _p, _l, why in left_out)
    assert sum(len(blocks(p)) for p in PAGES) >= 20  # the extraction finds the examples


@pytest.fixture(scope="module")
def workdir(vts_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.fixtures.calibration import sim_folder

    work = tmp_path_factory.mktemp("docs")
    (work / "data").mkdir()
    shutil.copytree(vts_dataset, work / "data" / "dataset")  # export_hf writes into it
    (work / "data" / "ds").symlink_to(vts_dataset)
    (work / "demo-data").mkdir()
    (work / "demo-data" / "dataset").symlink_to(vts_dataset)
    (work / "rec").mkdir()
    (work / "rec" / "ball").symlink_to(sim_folder(tmp_path_factory))
    import numpy as np  # a Taxim-style data pack of three presses (depth.md)

    rng = np.random.default_rng(0)
    np.savez(work / "dataPack.npz", f0=rng.integers(0, 255, (12, 16, 3), dtype=np.uint8),
             imgs=rng.integers(0, 255, (3, 12, 16, 3), dtype=np.uint8),
             touch_center=np.array([[5.0, 6.0], [7.0, 6.5], [8.0, 4.0]]),
             touch_radius=np.array([3.0, 4.0, 3.5]))
    return work


@pytest.mark.parametrize("page", [p for p in PAGES if blocks(p)], ids=lambda p: p.name)
def test_page_examples_run(page: Path, workdir: Path, tmp_path: Path,
                           monkeypatch: pytest.MonkeyPatch) -> None:
    todo = [(line, code) for line, code, why in blocks(page) if why is None]
    if not todo:
        pytest.skip("every block of this page is marked no-test")
    if any("torch" in code for _l, code in todo):
        pytest.importorskip("torch")
    run = tmp_path / "run"
    shutil.copytree(workdir, run, symlinks=True)
    monkeypatch.chdir(run)
    import fsspec

    memory = fsspec.filesystem("memory")
    before = set(memory.store)
    namespace: dict[str, object] = {"__name__": "docs_example"}
    try:
        for line, code in todo:
            exec(compile(code, f"{page.relative_to(ROOT)}:{line + 1}", "exec"), namespace)
    finally:
        for key in set(memory.store) - before:
            memory.store.pop(key, None)
        memory.pseudo_dirs[:] = [d for d in memory.pseudo_dirs if not d.startswith("/copy")]
        import matplotlib.pyplot as plt

        plt.close("all")
