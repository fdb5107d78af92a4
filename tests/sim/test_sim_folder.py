"""The simulated recordings folder: schema, layout, determinism across workers, bad input."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from vtsbench.errors import VtsError
from vtsbench.labels import direction_class, label_motion
from vtsbench.recordings.manifest import load_manifest
from vtsbench.recordings.media import read_frames, read_image
from vtsbench.recordings.truth import read_truth
from vtsbench.sim.simulate import simulate

SMALL = {"n_static": 4, "n_sequences": 6, "n_presses": 3, "n_objects": 15, "size": (96, 128),
         "frames": 4, "n_sessions": 2, "mm_per_px": 0.1}


def digests(folder: Path) -> dict[str, str]:
    """sha256 of every file under a folder, by relative path."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "rec"
    simulate(out, seed=3, workers=1, **SMALL)
    return out


def test_same_seed_same_bytes_with_any_number_of_workers(sim: Path, tmp_path: Path) -> None:
    simulate(tmp_path / "w2", seed=3, workers=2, **SMALL)
    a, b = digests(sim), digests(tmp_path / "w2")
    assert a == b
    assert len(a) > 20


def test_different_seeds_differ(sim: Path, tmp_path: Path) -> None:
    simulate(tmp_path / "other", seed=4, workers=1, **SMALL)
    a, b = digests(sim), digests(tmp_path / "other")
    assert a.keys() == b.keys()
    assert sum(a[k] != b[k] for k in a) >= len(a) - 1


def test_folder_validates_and_every_file_is_there(sim: Path) -> None:
    m = load_manifest(sim)
    assert [s.id for s in m.sessions] == ["s00", "s01"]
    assert len(m.entries) == 4 + 6 + 3
    assert {e.session for e in m.entries} == {"s00", "s01"}
    for s in m.sessions:
        assert s.sensor == "vtsbench-sim" and s.resolution == (96, 128) and s.fps == 30.0
        assert read_image(sim / s.background).shape == (96, 128, 3)
    for e in m.entries:
        src = sim / e.source.path
        frames = read_frames(src, e.source.start or 0, e.source.stop)
        t = read_truth(sim / e.truth)
        n = 4 if e.kind == "sequence" else 1
        assert frames.shape == (n, 96, 128, 3)
        assert t.depth_mm.shape == (n, 96, 128) and t.depth_mm.dtype == np.float32
        assert t.grad.shape == (n, 96, 128, 2) and t.grad.dtype == np.float32
        assert t.contact.shape == (n, 96, 128) and t.contact.dtype == bool
        assert t.motion_px.shape == (n, 2)
    ids = [e.id for e in m.entries]
    assert ids[0] == "static-00001" and ids[4] == "seq-00001" and ids[-1] == "press-00003"


def test_sequence_labels_come_from_label_motion(sim: Path) -> None:
    m = load_manifest(sim)
    seqs = [e for e in m.entries if e.kind == "sequence"]
    assert [e.meta["intended_state"] for e in seqs] == ["static", "press", "slip"] * 2
    for e in seqs:
        dx, dy = e.labels.motion_mm
        dz = e.labels.press_depth_mm - e.meta["depth0_mm"]
        lab = label_motion(dx, dy, dz)
        assert (e.labels.state, e.labels.direction) == (lab.state, lab.direction)
        assert e.labels.state == e.meta["intended_state"]
        if e.labels.state == "slip":
            assert e.labels.direction == direction_class(dx, dy)
        else:
            assert e.labels.direction is None and (dx, dy) == (0.0, 0.0)
        # The truth's motion between the first and last frames in contact is the labelled one
        # (pixels, y down; a window may make or lose contact).
        t = read_truth(sim / e.truth)
        touch = np.flatnonzero(t.contact.any(axis=(1, 2)))
        np.testing.assert_allclose(t.motion_px[touch[-1]] - t.motion_px[touch[0]],
                                   (dx / 0.1, -dy / 0.1), atol=1e-3)


def test_presses_have_ball_circle_and_depth(sim: Path) -> None:
    m = load_manifest(sim)
    presses = [e for e in m.entries if e.kind == "press"]
    assert len(presses) == 3
    for e in presses:
        assert e.ball_radius_mm == 3.0 and 0.1 <= e.labels.press_depth_mm < 3.0
        c = e.circle
        assert c.r > 4 and c.r <= c.x <= 127 - c.r and c.r <= c.y <= 95 - c.r
        contact = read_truth(sim / e.truth).contact[0]
        assert abs(np.pi * c.r**2 - contact.sum()) < 1.0


def test_existing_output_is_refused_without_overwrite(sim: Path) -> None:
    with pytest.raises(VtsError, match="already exists"):
        simulate(sim, seed=3, **SMALL)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"size": (16, 128)}, "too small"),
    ({"size": (40, 40), "mm_per_px": 0.03}, "too small for a 3.0 mm ball"),
    ({"mm_per_px": 0.5}, "too coarse"),
    ({"n_objects": 16}, "--objects"),
    ({"n_objects": 0}, "--objects"),
    ({"frames": 1}, "--frames"),
])
def test_impossible_settings_are_one_line_errors(tmp_path: Path, kwargs: dict,
                                                 match: str) -> None:
    args = {**SMALL, **kwargs}
    with pytest.raises(VtsError, match=match) as err:
        simulate(tmp_path / "x", seed=0, **args)
    assert "\n" not in str(err.value)
    assert not (tmp_path / "x").exists()


def test_no_presses_allows_a_small_frame(tmp_path: Path) -> None:
    m = simulate(tmp_path / "x", seed=0, n_static=1, n_sequences=0, n_presses=0, size=(32, 40),
                 mm_per_px=0.03, n_sessions=1)
    assert len(m.entries) == 1 and not (tmp_path / "x" / "presses").exists()


def test_workers_start_cleanly_after_the_parent_used_opencv_threads(tmp_path: Path) -> None:
    # Forked workers could inherit OpenCV's thread-pool locks mid-use and hang; they are spawned.
    import subprocess
    import sys

    code = ("import cv2, numpy as np; cv2.setNumThreads(2); "
            "a = np.ones((480, 640, 3), np.float32); "
            "[cv2.GaussianBlur(a, (31, 31), 5) for _ in range(20)]; "
            "from vtsbench.sim.simulate import simulate; "
            f"simulate({str(tmp_path / 'o')!r}, seed=0, n_static=2, n_sequences=2, n_presses=2, "
            "size=(96, 128), mm_per_px=0.1, workers=2, frames=2)")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
    assert (tmp_path / "o" / "recordings.json").is_file()
