"""Names are drawn as written: a '$' in a sensor id, an object or a folder name is not TeX."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.calibration import copy_folder, sim_folder
from vtsbench.cli import app

#: Text matplotlib's TeX parser refuses: drawn as TeX it raises when the figure is drawn.
TEX = "gs$\\frac{a$mini"


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory):
    return sim_folder(tmp_path_factory)


def test_the_text_would_fail_as_tex() -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure()
    FigureCanvasAgg(fig)
    fig.suptitle(TEX)
    with pytest.raises(ValueError):
        fig.canvas.draw()


def test_calibration_report_and_preview_with_dollar_names(sim, tmp_path) -> None:
    folder = tmp_path / "rec$x$"
    copy_folder(sim, folder, edit=lambda e, s: (
        [replace(x, object=TEX) for x in e], [replace(x, sensor=TEX) for x in s]))
    out = tmp_path / "c.safetensors"
    res = CliRunner().invoke(app, ["calibrate", str(folder), "--out", str(out), "--holdout", "2",
                                   "--method", "lut", "--bins", "16"])
    assert res.exit_code == 0, res.output
    rep = tmp_path / "c.safetensors.report"
    assert (rep / "report.png").stat().st_size > 10_000
    assert (rep / "circles.png").stat().st_size > 10_000
    res = CliRunner().invoke(app, ["preview", str(folder), "--out", str(tmp_path / "p.png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "p.png").stat().st_size > 10_000


def test_sample_plot_with_a_dollar_title() -> None:
    from vtsbench.dataset.read.plot import plot_arrays
    from vtsbench.figures import png_bytes

    fig = plot_arrays(np.zeros((8, 8, 3), np.uint8), np.zeros((8, 8), np.float32), None, TEX)
    assert png_bytes(fig)[:4] == b"\x89PNG"


def test_print_style_draws_text_as_written() -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from vtsbench.figures import png_bytes, print_style

    with print_style():
        fig = Figure()
        FigureCanvasAgg(fig)
        fig.suptitle(TEX)
        assert png_bytes(fig)[:4] == b"\x89PNG"
