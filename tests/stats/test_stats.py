"""`vtsbench stats` on synthetic windows with known answers (a shift, a rotation, a jerk, a still
pattern), on folders it cannot measure (one clear line, never a table of NaN), and its JSON."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.data import real_dir
from vtsbench.cli import app
from vtsbench.dataset.format.records import SCHEMA_DIR
from vtsbench.recordings.manifest import Entry, Manifest, Session, Source, save_manifest
from vtsbench.recordings.media import write_png
from vtsbench.stats.window import step_statistics, window_stats

runner = CliRunner()
H, W = 192, 240


def imprint(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A textured disk imprint (float, 0 off it), 60 DN above the gel plus +-25 DN texture."""
    import cv2

    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.normal(0, 1, (h, w)).astype(np.float32), (0, 0), 2.5)
    tex *= 25 / tex.std()
    yy, xx = np.mgrid[:h, :w]
    disk = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2 < (0.25 * min(h, w)) ** 2).astype(np.float32)
    return (60 + tex) * cv2.GaussianBlur(disk, (0, 0), 1.5)


def grey3(img: np.ndarray) -> np.ndarray:
    return np.repeat(np.clip(np.rint(img), 0, 255).astype(np.uint8)[..., None], 3, -1)


def window(mats: list[np.ndarray], h: int = H, w: int = W, noise: float = 1.0,
           pattern: np.ndarray | None = None, contact: bool = True
           ) -> tuple[np.ndarray, np.ndarray]:
    """(frames, reference): the imprint moved by each 2x3 matrix on a flat gel (plus a fixed
    pattern), with fresh Gaussian noise in every frame and in the reference."""
    import cv2

    rng = np.random.default_rng(1)
    base = imprint(h, w) if contact else np.zeros((h, w), np.float32)
    fixed = 100 + (0 if pattern is None else pattern)
    frames = [grey3(fixed + cv2.warpAffine(base, m, (w, h), flags=cv2.INTER_CUBIC)
                    + rng.normal(0, noise, (h, w))) for m in mats]
    return np.stack(frames), grey3(fixed + rng.normal(0, noise, (h, w)))


def shifts(xs: list[float], ys: list[float] | None = None) -> list[np.ndarray]:
    ys = ys or [0.0] * len(xs)
    return [np.float32([[1, 0, x], [0, 1, y]]) for x, y in zip(xs, ys, strict=True)]


def test_pure_shift_is_rigid() -> None:
    s = window_stats(*window(shifts([0.5 * t for t in range(8)], [0.3 * t for t in range(8)])))
    assert s.contact and s.moving and not s.contact_change
    assert s.displacement_px == pytest.approx(np.hypot(3.5, 2.1), abs=0.1)
    assert s.translation_r2 > 0.99 and s.co_moving_share > 0.95
    assert s.rotation_deg < 0.1 and s.strain_ratio < 0.05
    assert s.largest_step_share == pytest.approx(1 / 7, abs=0.03) and s.speed_cv < 0.15
    assert s.phase_miss is False


def test_pure_rotation_is_recovered() -> None:
    import cv2

    pivot = (W / 2 - 40, H / 2)  # about a point off the contact's centre: the contact moves
    mats = [cv2.getRotationMatrix2D(pivot, 0.4 * t, 1.0) for t in range(8)]
    s = window_stats(*window(mats))
    assert s.moving
    assert s.rotation_deg == pytest.approx(2.8, abs=0.2)
    assert s.strain_ratio < 0.1 and s.translation_r2 < 0.99


def test_one_jerk_against_steady_steps() -> None:
    s = window_stats(*window(shifts([3.0 * (t >= 4) for t in range(8)])))
    assert s.moving and s.largest_step_share > 0.9 and s.speed_cv > 2.0
    steady = step_statistics(np.array([[t, 0.0] for t in range(8)]))
    assert steady == pytest.approx((1 / 7, 0.0))
    jerk = step_statistics(np.array([[3.0 * (t >= 4), 0.0] for t in range(8)]))
    assert jerk == pytest.approx((1.0, np.sqrt(6)))


def dots(h: int = H, w: int = W) -> np.ndarray:
    """A fixed grid of dark dots (a marker gel at rest)."""
    yy, xx = np.mgrid[:h, :w]
    return -50.0 * (((xx % 24 - 12) ** 2 + (yy % 24 - 12) ** 2) < 16)


def test_static_pattern_has_no_motion_and_its_noise() -> None:
    s = window_stats(*window(shifts([0.0] * 8), noise=2.0, pattern=dots(), contact=False))
    assert not s.contact and not s.moving and s.translation_r2 is None
    assert s.temporal_noise == pytest.approx(2.0, abs=0.15)
    assert s.off_contact_hp_rms > 5.0  # the fixed dots, not the noise
    held = window_stats(*window(shifts([0.0] * 8), noise=2.0))
    assert held.contact and not held.moving and held.imprint_hp_rms > 3.0


# -- folders -----------------------------------------------------------------------------------


def folder(root: Path, windows: list[tuple[np.ndarray, np.ndarray]], sizes_ok: bool = True
           ) -> Path:
    """A recordings folder: one image-folder sequence per window, the reference as background."""
    root.mkdir(parents=True)
    frames0, ref = windows[0]
    write_png(root / "bg.png", ref)
    entries = []
    for i, (frames, _) in enumerate(windows):
        d = root / f"seq{i}"
        d.mkdir()
        for t, f in enumerate(frames):
            write_png(d / f"{t:03d}.png", f if sizes_ok or t < 3 else f[:-8])
        entries.append(Entry(f"seq-{i}", "sequence", "s0", Source(f"seq{i}")))
    h, w = frames0.shape[1:3]
    save_manifest(root, Manifest([Session("s0", "synthetic", (h, w), None, 30.0, "bg.png")],
                                 entries))
    return root


def test_cli_table_json_and_compare(tmp_path: Path) -> None:
    import jsonschema

    slip = folder(tmp_path / "slip", [window(shifts([0.5 * t for t in range(8)])),
                                      window(shifts([3.0 * (t >= 4) for t in range(8)]))])
    held = folder(tmp_path / "held", [window(shifts([0.0] * 8), noise=2.0)])
    out = tmp_path / "stats.json"
    res = runner.invoke(app, ["stats", str(slip), "--compare", str(held), "--out", str(out)],
                        env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    assert "translation fits" in res.output and str(held) in res.output
    assert "no moving windows" in res.output and "nan" not in res.output.lower()
    doc = json.loads(out.read_text())
    jsonschema.validate(doc, json.loads((SCHEMA_DIR / "stats.schema.json").read_text()))
    a, b = doc["folders"]
    assert (a["n_moving"], b["n_moving"], b["n_static"]) == (2, 0, 1)
    assert a["distributions"]["translation_r2"]["median"] > 0.99
    assert a["windows"][1]["largest_step_share"] > 0.9 > 0.2 > a["windows"][0]["largest_step_share"]
    assert b["distributions"]["translation_r2"] == {"n": 0, "median": None, "q25": None,
                                                    "q75": None}
    assert b["distributions"]["temporal_noise"]["median"] == pytest.approx(2.0, abs=0.15)


def test_no_contact_is_one_line_not_a_table_of_nan(tmp_path: Path) -> None:
    root = folder(tmp_path / "flat", [window(shifts([0.0] * 8), contact=False)])
    res = runner.invoke(app, ["stats", str(root)], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    assert "no contact in any window" in res.output and "nan" not in res.output.lower()
    assert "translation fits" not in res.output and "temporal noise" in res.output


def test_one_frame_and_mixed_sizes_are_one_line_errors(tmp_path: Path) -> None:
    one = tmp_path / "one"
    one.mkdir()
    frames, _ = window(shifts([0.0]))
    write_png(one / "f.png", frames[0])
    save_manifest(one, Manifest([Session("s0", "synthetic", (H, W))],
                                [Entry("st", "static", "s0", Source("f.png"))]))
    res = runner.invoke(app, ["stats", str(one)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert "no sequence of 2 frames or more" in res.output
    assert len(res.output.strip().splitlines()) == 1

    mixed = folder(tmp_path / "mixed", [window(shifts([0.5 * t for t in range(8)]))],
                   sizes_ok=False)
    res = runner.invoke(app, ["stats", str(mixed)])
    assert res.exit_code == 2 and "frames of two sizes: 000.png is" in res.output
    assert res.output.startswith("error: ") and len(res.output.strip().splitlines()) == 1


def test_simulated_folder_and_window_cap(tmp_path: Path) -> None:
    from vtsbench.sim.simulate import simulate
    from vtsbench.stats import folder_stats

    out = tmp_path / "sim"
    simulate(out, seed=0, n_static=2, n_sequences=6, n_presses=0, n_objects=4, size=(96, 128),
             frames=8, n_sessions=1, mm_per_px=0.06, workers=1, overwrite=False, progress=False)
    f = folder_stats(out, max_windows=4)
    assert (f.n_windows, f.n_sampled, f.frames_per_window) == (6, 4, 8)
    assert f.n_contact >= 3 and f.n_moving + f.n_static == 4
    assert [w["entry"] for w in f.windows] == [w["entry"] for w in folder_stats(
        out, max_windows=4).windows]  # the same windows every run


def test_real_marker_video_windows(tmp_path: Path) -> None:
    from vtsbench.stats import folder_stats

    video = real_dir("incipient_slip_sample") / "blue_mug" / "exp_num_1" / "camera_0.avi"
    if not video.is_file():
        pytest.skip(f"{video} not present")
    root = tmp_path / "real"
    root.mkdir()
    path = os.path.relpath(video, root).replace(os.sep, "/")
    entries = [Entry(f"w{a}", "sequence", "s0", Source(path, start=a, stop=a + 8))
               for a in (40, 80, 120)]
    save_manifest(root, Manifest([Session("s0", "gsmini", (240, 320), None, 25.0)], entries))
    f = folder_stats(root)
    assert f.n_sampled == 3 and f.n_contact == 3
    for w in f.windows:
        assert w["temporal_noise"] is None or w["temporal_noise"] < 1.0  # compressed video
