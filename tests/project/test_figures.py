"""Figures at print quality: 150 dpi, no text below 9 pt, and evaluation figures titled with
the method, split, part and n."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.fixtures.figures import png_dpi
from vtsbench import figures
from vtsbench.figures import MIN_FONT_PT, PRINT_DPI


def texts(fig: Any) -> list[Any]:
    """Every visible, non-empty text of a figure (titles, labels, tick labels, annotations)."""
    from matplotlib.text import Text

    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]


@pytest.fixture
def saved(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The figures save_png writes, drawn (so tick labels exist) before they are saved."""
    got: list[Any] = []
    real = figures.save_png

    def keep(fig: Any, path: str | Path, dpi: int = PRINT_DPI) -> Path:
        fig.canvas.draw()
        got.append(fig)
        return real(fig, path, dpi)

    monkeypatch.setattr(figures, "save_png", keep)
    return got


def eval_doc() -> dict[str, Any]:
    """A scored toy submission (six slip samples, both tasks)."""
    import numpy as np

    from vtsbench.evaluation.report import score
    from vtsbench.evaluation.submission import Submission, Truth
    from vtsbench.labels import DIRECTION_NAMES, STATES

    truth = Truth("toy", "1.0.0", "ab" * 32, "unseen_objects", "test", "slip",
                  [f"s{i}" for i in range(6)], list("aabbcc"),
                  {"state": np.array([2, 2, 2, 1, 0, 0]),
                   "direction": np.array([0, 7, 4, -1, -1, -1])},
                  {"state": STATES, "direction": DIRECTION_NAMES})
    preds = {"state": {0: np.array([2, 2, 1, 1, 0, 0])},
             "direction": {0: np.array([0, 6, 4, 0, 0, 0])}}
    sub = Submission(Path("toy.csv"), {"method": "toy net"}, "cd" * 32, preds)
    return score(truth, sub)


def test_eval_figures_print_quality_and_title(tmp_path: Path, saved: list[Any]) -> None:
    from vtsbench.evaluation.report import write_figures

    names = write_figures(eval_doc(), tmp_path)
    assert names == ["confusion_state.png", "confusion_direction.png"]
    for name, fig in zip(names, saved, strict=True):
        dx, dy = png_dpi(tmp_path / name)
        assert round(dx) >= PRINT_DPI and round(dy) >= PRINT_DPI, name
        w, _h = fig.get_size_inches()
        import matplotlib.image as mpimg

        img = mpimg.imread(tmp_path / name)
        assert img.shape[1] == pytest.approx(w * PRINT_DPI, abs=2)  # pixels = inches x dpi
        sizes = {t.get_text(): t.get_fontsize() for t in texts(fig)}
        small = {k: v for k, v in sizes.items() if v < MIN_FONT_PT}
        assert not small, f"{name}: text below {MIN_FONT_PT} pt: {small}"
        title = fig._suptitle.get_text()
        task = name.removeprefix("confusion_").removesuffix(".png")
        assert title == f"toy net: {task} on unseen_objects/test, n = " + \
            ("6" if task == "state" else "3")


def test_the_figure_helper_never_goes_below_print_quality(tmp_path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    with figures.print_style():
        fig = Figure(figsize=(2, 1))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        ax.set_title("t")
        ax.plot([0, 1])
        fig.canvas.draw()
        assert min(t.get_fontsize() for t in texts(fig)) >= MIN_FONT_PT
    out = figures.save_png(fig, tmp_path / "f.png", dpi=72)  # asked lower: still PRINT_DPI
    assert round(png_dpi(out)[0]) == PRINT_DPI
    assert figures.font_pt(6) == MIN_FONT_PT


def test_preview_at_print_quality(make_recordings: Any, tmp_path: Path,
                                  saved: list[Any]) -> None:
    from vtsbench.recordings.preview import write_preview

    root, _ = make_recordings()
    out = tmp_path / "sheet.png"
    write_preview(root, out, n=4)
    assert round(png_dpi(out)[0]) >= PRINT_DPI
    small = {t.get_text(): t.get_fontsize() for t in texts(saved[0])
             if t.get_fontsize() < MIN_FONT_PT}
    assert not small
