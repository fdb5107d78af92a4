"""Images to depth: reconstruct() and the `vtsbench depth` command."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.calibration import fitted
from vtsbench.cli import app
from vtsbench.depth.calibration import save_calibration
from vtsbench.depth.metrics import plane_aligned_rmse
from vtsbench.depth.reconstruct import colourise, reconstruct
from vtsbench.errors import VtsError
from vtsbench.recordings.media import write_png
from vtsbench.recordings.truth import read_truth


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory):
    return fitted(tmp_path_factory, "poly")


@pytest.fixture(scope="module")
def cal_file(tmp_path_factory: pytest.TempPathFactory, run) -> Path:
    path = tmp_path_factory.mktemp("rec") / "poly.safetensors"
    save_calibration(run.calibration, path)
    return path


def test_depth_of_held_out_presses(run) -> None:
    cal = run.calibration
    frames = np.stack([r.press.image for r in run.held_out])
    z = reconstruct(frames, cal)
    assert z.shape == (2, 120, 160) and z.dtype == np.float32
    for k, r in enumerate(run.held_out):
        t = read_truth(r.press.truth)
        np.testing.assert_allclose(z[k], r.pred_depth, atol=1e-6)
        err = plane_aligned_rmse(z[k], t.depth_mm[0], t.contact[0])
        assert err < 0.03, (r.press.id, err)  # measured 0.0042 and 0.0067 mm
        # Depth is positive into the gel: the deepest point is near the circle's centre.
        iy, ix = np.unravel_index(np.argmax(z[k]), z[k].shape)
        assert np.hypot(ix - r.press.x, iy - r.press.y) < 0.3 * r.press.r


def test_batches_and_leading_dimensions_agree(run) -> None:
    cal = run.calibration
    frames = np.stack([r.press.image for r in run.held_out] * 2).reshape(2, 2, 120, 160, 3)
    z = reconstruct(frames, cal, batch=3)
    assert z.shape == (2, 2, 120, 160)
    np.testing.assert_allclose(z[1, 0], reconstruct(frames[1, 0], cal), atol=1e-6)


@pytest.mark.parametrize("solver", ["dct", "dst", "masked"])
def test_solvers_give_the_contact_shape(run, solver) -> None:
    r = run.held_out[1]
    t = read_truth(r.press.truth)
    z = reconstruct(r.press.image, run.calibration, solver=solver)
    assert plane_aligned_rmse(z, t.depth_mm[0], t.contact[0]) < 0.03


def test_odd_images(run) -> None:
    cal = run.calibration
    h, w = cal.resolution
    sat = np.full((h, w, 3), 255, np.uint8)
    black = np.zeros((h, w, 3), np.uint8)
    const = np.full((h, w, 3), 100.0, np.float32)
    half = cal.background.copy()
    half[:, : w // 2] = 255
    z = reconstruct(np.stack([sat, black, half]), cal)
    assert np.isfinite(z).all()
    assert np.isfinite(reconstruct(const, cal)).all()
    assert np.abs(reconstruct(cal.background.astype(np.float32), cal)).max() < 1e-6
    bad = cal.background.astype(np.float32)
    bad[3, 4, 1] = np.nan
    with pytest.raises(VtsError, match="NaN"):
        reconstruct(bad, cal)
    with pytest.raises(VtsError, match="RGB"):
        reconstruct(np.zeros((h, w), np.uint8), cal)
    with pytest.raises(VtsError, match="uint8 or float"):
        reconstruct(np.zeros((h, w, 3), bool), cal)
    with pytest.raises(VtsError, match="unknown solver"):
        reconstruct(black, cal, solver="fft")
    with pytest.raises(VtsError, match="only by the masked solver"):
        reconstruct(black, cal, mask=np.ones((h, w), bool))


def test_masked_solver_with_a_given_mask(run) -> None:
    r = run.held_out[0]
    h, w = run.calibration.resolution
    yy, xx = np.mgrid[0:h, 0:w]
    mask = np.hypot(xx - r.press.x, yy - r.press.y) < 2 * r.press.r
    z = reconstruct(r.press.image, run.calibration, solver="masked", mask=mask)
    assert (z[~mask] == 0).all() and z.max() > 0.1


def test_torch_path_matches_numpy(run) -> None:
    pytest.importorskip("torch")
    frames = np.stack([r.press.image for r in run.held_out])
    a = reconstruct(frames, run.calibration)
    b = reconstruct(frames, run.calibration, device="cpu")
    assert b.dtype == np.float32
    np.testing.assert_allclose(a, b, atol=2e-4)
    # "auto" is CUDA when present, else the numpy path.
    np.testing.assert_allclose(reconstruct(frames, run.calibration, device="auto"), a,
                               atol=2e-4)


def test_colourise_shows_negative_depth() -> None:
    d = np.linspace(-0.1, 1, 200, dtype=np.float32).reshape(10, 20)
    rgb = colourise(d)
    assert rgb.shape == (10, 20, 3) and rgb.dtype == np.uint8
    zero = colourise(np.zeros((1, 1)))[0, 0]
    assert abs(int(rgb[0, 0, 0]) - int(zero[0])) > 100  # -0.1 mm is red, not 0's violet
    # a fixed range: the same value, the same colour, whatever else is in the frame
    a = colourise(np.array([[0.5, 2.0]]), vmax=1.0, vmin=-0.2)
    b = colourise(np.array([[0.5, 0.0]]), vmax=1.0, vmin=-0.2)
    np.testing.assert_array_equal(a[0, 0], b[0, 0])
    with pytest.raises(VtsError, match="MIN < 0 < MAX"):
        colourise(d, vmax=1.0, vmin=0.5)


def test_colour_bar_and_range() -> None:
    from vtsbench.depth.reconstruct import parse_range, with_colour_bar

    rgb = colourise(np.zeros((120, 160)), 1.0, -0.2)
    out = with_colour_bar(rgb, 1.0, -0.2)
    assert out.shape[0] == 120 and out.shape[1] > 160 + 20
    np.testing.assert_array_equal(out[:, :160], rgb)
    assert parse_range("-0.2,1.5") == (-0.2, 1.5)
    for bad in ("1,2", "a,b", "-1", "nan,1", "-inf,1"):
        with pytest.raises(VtsError, match="--range"):
            parse_range(bad)


# -- the command ------------------------------------------------------------------------------


def test_cli_depth_on_image_folder_and_video(run, cal_file, tmp_path) -> None:
    import cv2

    frames = [r.press.image for r in run.held_out]
    (tmp_path / "imgs").mkdir()
    for k, f in enumerate(frames):
        write_png(tmp_path / "imgs" / f"f{k}.png", f)
    vw = cv2.VideoWriter(str(tmp_path / "take.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10.0,
                         (160, 120))
    for f in frames:
        vw.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    vw.release()
    for src, names in ((tmp_path / "imgs" / "f0.png", ["f0"]),
                       (tmp_path / "imgs", ["f0", "f1"]),
                       (tmp_path / "take.avi", ["take_00000", "take_00001"])):
        out = tmp_path / f"out-{src.stem}"
        res = CliRunner().invoke(app, ["depth", str(src), "--calibration", str(cal_file),
                                       "--out", str(out), "--device", "numpy"])
        assert res.exit_code == 0, res.output
        assert f"wrote {len(names)} depth map(s)" in res.stdout
        for n in names:
            z = np.load(out / f"{n}.npy")
            assert z.dtype == np.float32 and z.shape == (120, 160) and np.isfinite(z).all()
            assert (out / f"{n}.png").read_bytes()[:4] == b"\x89PNG"
    z = np.load(tmp_path / "out-imgs" / "f1.npy")
    np.testing.assert_allclose(z, reconstruct(frames[1], run.calibration), atol=1e-6)
    # several inputs and a glob, one fixed colour scale; progress lines per input
    res = CliRunner().invoke(app, ["depth", str(tmp_path / "imgs" / "*.png"),
                                   str(tmp_path / "take.avi"), "--calibration", str(cal_file),
                                   "--out", str(tmp_path / "many"), "--device", "numpy",
                                   "--range", "-0.2,1.5"])
    assert res.exit_code == 0, res.output
    assert "wrote 4 depth map(s)" in res.stdout and "depth: 3/3" in res.stderr
    assert (tmp_path / "many" / "f0.npy").is_file()
    assert (tmp_path / "many" / "take" / "take_00001.npy").is_file()
    res = CliRunner().invoke(app, ["depth", str(tmp_path / "nothing" / "*.png"),
                                   "--calibration", str(cal_file)])
    assert res.exit_code == 2 and "matches no file" in res.stderr


def test_cli_depth_refuses_another_resolution(cal_file, tmp_path) -> None:
    write_png(tmp_path / "big.png", np.zeros((240, 320, 3), np.uint8))
    res = CliRunner().invoke(app, ["depth", str(tmp_path / "big.png"), "--calibration",
                                   str(cal_file), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "Traceback" not in res.output
    line = res.stderr.strip()
    assert len(line.splitlines()) == 1
    assert "240x320" in line and "120x160" in line and str(cal_file) in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("what", ["missing", "not-a-calibration"])
def test_cli_depth_bad_calibration(cal_file, tmp_path, what) -> None:
    write_png(tmp_path / "a.png", np.zeros((120, 160, 3), np.uint8))
    bad = tmp_path / "bad.safetensors"
    if what == "not-a-calibration":
        bad.write_text("hello")
    res = CliRunner().invoke(app, ["depth", str(tmp_path / "a.png"), "--calibration", str(bad)])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "Traceback" not in res.output


@pytest.mark.parametrize("method", ["lut", "poly"])
def test_fast_numpy_path_gives_the_general_paths_numbers(tmp_path_factory, method) -> None:
    """reconstruct's frame-at-a-time numpy path (the build's DepthMaker) and the lut's one-take
    lookup (LutMapping.relative) give, bit for bit, what the general path computes: predict,
    minus the zero map, still pixels at 0, then poisson.integrate."""
    from vtsbench.depth.mapping import Mapping
    from vtsbench.depth.poisson import integrate

    cal = fitted(tmp_path_factory, method).calibration
    frames = np.stack([h.press.image for h in fitted(tmp_path_factory, method).held_out]
                      + [cal.background])
    diff = cal.difference(frames)
    general = Mapping.relative(cal.mapping, diff, cal.zero_map)
    assert np.array_equal(cal.gradients(frames), general)
    for solver in ("dct", "dst"):
        want = integrate(general[..., 0], general[..., 1], method=solver,
                         mm_per_px=cal.mm_per_px, dtype=np.float32)
        assert np.array_equal(reconstruct(frames, cal, solver=solver), want), solver
    assert not np.any(reconstruct(frames[-1], cal))  # the background: exactly flat
