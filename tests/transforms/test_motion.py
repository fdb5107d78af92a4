"""The global shift of a sequence: frame_shifts leaves its frames as they were."""

from __future__ import annotations

import numpy as np

from vtsbench.transforms.motion import frame_shifts


def test_frame_shifts_keeps_its_inputs_and_finds_a_shift() -> None:
    """OpenCV's phaseCorrelate windows its inputs in place: frame 0 must be windowed once per
    pair, not once more for every later frame, and the caller's frames stay unchanged."""
    import cv2

    rng = np.random.default_rng(1)
    base = cv2.GaussianBlur(rng.random((300, 380)).astype(np.float32), (0, 0), 3)
    frames = [base[20:260, 20 + t:340 + t].copy() for t in range(6)]
    kept = [f.copy() for f in frames]
    window = cv2.createHanningWindow((320, 240), cv2.CV_32F)
    shifts, peaks = frame_shifts(frames, window)
    assert all(np.array_equal(a, b) for a, b in zip(frames, kept, strict=True))
    fresh = [cv2.phaseCorrelate(kept[0].copy(), kept[t].copy(), window)[0][0]
             for t in range(1, 6)]
    assert np.array_equal(shifts[1:, 0], fresh)
    assert np.allclose(np.abs(shifts[:, 0]), np.arange(6), atol=0.15)
    assert (peaks > 0.2).all()
