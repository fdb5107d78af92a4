"""Shared fixtures: small recordings folders made by the tests, and the optional real data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vtsbench.recordings.manifest import (
    Circle,
    Entry,
    Labels,
    Manifest,
    Session,
    Source,
    save_manifest,
)
from vtsbench.recordings.media import write_png

# the shared dataset fixtures and helpers, imported by test modules: rewrite their asserts
pytest.register_assert_rewrite("loader_conftest")

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def real_dir(name: str) -> Path:
    """A folder of ../shared/data/real, or skip the test when it is absent."""
    p = REAL / name
    if not p.is_dir():
        pytest.skip(f"real data {p} not present")
    return p


def frame(h: int = 48, w: int = 64, seed: int = 0) -> np.ndarray:
    """A small deterministic RGB frame."""
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


def write_video(path: Path, n: int, h: int = 48, w: int = 64) -> None:
    """An MJPG .avi of n frames."""
    import cv2

    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (w, h))
    assert vw.isOpened()
    for i in range(n):
        vw.write(frame(h, w, i))
    vw.release()


@pytest.fixture
def make_recordings(tmp_path: Path):
    """Factory: a valid recordings folder with a static frame, a video sequence, an image-folder
    sequence and a press; returns (folder, manifest)."""

    def make(h: int = 48, w: int = 64) -> tuple[Path, Manifest]:
        root = tmp_path / "rec"
        (root / "seqdir").mkdir(parents=True)
        write_png(root / "bg.png", frame(h, w, 100))
        write_png(root / "static.png", frame(h, w, 1))
        write_png(root / "press.png", frame(h, w, 2))
        for i in range(8):
            write_png(root / "seqdir" / f"{i:03d}.png", frame(h, w, 10 + i))
        write_video(root / "take.avi", 12, h, w)
        m = Manifest(
            sessions=[Session("s0", "test-sensor", (h, w), (0.03, 0.03), 25.0, "bg.png")],
            entries=[
                Entry("st-1", "static", "s0", Source("static.png"), object="cube",
                      labels=Labels(press_depth_mm=0.5)),
                Entry("seq-1", "sequence", "s0", Source("take.avi", start=0, stop=8),
                      object="gear", labels=Labels("slip", 2, (0.0, 0.4), 0.6)),
                Entry("seq-2", "sequence", "s0", Source("seqdir", start=0, stop=8),
                      object="gear", labels=Labels("press", None, (0.0, 0.0), 0.8)),
                Entry("pr-1", "press", "s0", Source("press.png"), ball_radius_mm=3.0,
                      circle=Circle(30.0, 20.0, 8.0), labels=Labels(press_depth_mm=0.4)),
            ],
            name="tiny",
        )
        save_manifest(root, m)
        return root, m

    return make
