"""media.chroma_subsampling: which files store colour at a lower resolution than brightness
(the header as FFmpeg probes it), and the calibration's warning for a marker gel so recorded."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vtsbench.depth.calibration import subsampled_colour_note
from vtsbench.recordings.media import chroma_subsampling


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    import av
    import cv2

    d = tmp_path_factory.mktemp("chroma")
    img = np.random.default_rng(0).integers(0, 256, (48, 64, 3), np.uint8)
    j = cv2.IMWRITE_JPEG_SAMPLING_FACTOR
    out = {"png": d / "a.png", "420": d / "a420.jpg", "422": d / "a422.jpg",
           "444": d / "a444.jpg", "junk": d / "junk.jpg", "video": d / "take.mkv",
           "folder": d / "frames"}
    cv2.imwrite(str(out["png"]), img)
    cv2.imwrite(str(out["420"]), img)  # libjpeg's default
    cv2.imwrite(str(out["422"]), img, [j, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422])
    cv2.imwrite(str(out["444"]), img, [j, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444])
    out["junk"].write_bytes(b"\xff\xd8\xff not a JPEG")
    out["folder"].mkdir()
    cv2.imwrite(str(out["folder"] / "000.jpg"), img)
    with av.open(str(out["video"]), "w") as c:
        s = c.add_stream("ffv1", rate=25)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        for _ in range(2):
            for pkt in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(pkt)
        for pkt in s.encode():
            c.mux(pkt)
    return out


@pytest.mark.parametrize(("kind", "want"), [
    ("png", None), ("420", "4:2:0"), ("422", "4:2:2"), ("444", None), ("junk", None),
    ("video", "4:2:0"), ("folder", "4:2:0")])
def test_chroma_subsampling_of_each_kind_of_file(files: dict[str, Path], kind: str,
                                                 want: str | None) -> None:
    assert chroma_subsampling(files[kind]) == want


def test_the_note_names_a_subsampled_file_and_stays_quiet_otherwise(
        files: dict[str, Path]) -> None:
    assert subsampled_colour_note({"a": files["png"], "b": files["444"]}) is None
    # half the colour across only costs a marker gel what full colour does: no warning
    assert subsampled_colour_note({"a": files["422"]}) is None
    note = subsampled_colour_note({"a": files["png"], "b": files["420"], "c": files["420"]})
    assert note is not None and "4:2:0" in note and "1 of 2 press files" in note
    assert "a420.jpg" in note and "\n" not in note
