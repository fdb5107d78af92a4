"""`vtsbench verify` of a dataset whose episodes' RGB is stored as video
(format/episode_video.py): every episode's file listed in info.json `files` (its sha256 is
checked with every file's, and dataset_sha256 covers it), probed (nothing decoded: the frames
it holds against the episode's length, its frame size against the store's, its codec against
info.json's), and no video of no episode. One line per file. (The `rgb` array of
data/episodes.zarr holds metadata and no chunk by design: verify.py's chunk check leaves it
out.)
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ...errors import VtsError
from ..format.episode_video import stored_codec
from ..format.layout import EPISODES, INFO_PATH, VIDEOS_DIR, episode_video_path

if TYPE_CHECKING:
    import pyarrow as pa

    from ..format.info import DatasetInfo
    from .verify import VerifyReport


def check_videos(root: Path, info: DatasetInfo, report: VerifyReport,
                 episodes: pa.Table | None) -> None:
    """Add the problems of the episodes' videos to the report (nothing for a dataset whose
    RGB is in Zarr). `episodes`: index/episodes.parquet as the index checks read it; None
    where it could not be read (reported with the indexes: the videos are not probed)."""
    codec = stored_codec(info)  # (a codec vtsbench cannot read: refused with info.json)
    if codec is None or episodes is None:
        return
    from ..read.episode_video import check_video_info
    from ..read.video import probe

    lengths = episodes.column("length").to_pylist()
    size = tuple(info.shapes[EPISODES]["rgb"][1:3])
    wanted = set()
    for k, length in enumerate(lengths):
        rel = episode_video_path(k, codec.suffix)
        wanted.add(rel)
        path = root / rel
        if rel not in info.files:
            report.problems.append(f"{rel}: episode {k}'s video is not listed in {INFO_PATH} "
                                   "files" + ("" if path.is_file() else " (and missing)"))
        if not path.is_file():
            continue  # missing: said by the file checks (or just above)
        try:
            check_video_info(probe(path, int(length)), size, codec, path)
        except VtsError as e:
            _replace_line(report, rel, f"{rel}: {e.reason}")
    extra = sorted(p for p in info.files if p.startswith(f"{VIDEOS_DIR}/") and p not in wanted)
    report.problems += [f"{p}: a video of no episode ({len(lengths)} episodes)" for p in extra]


def _replace_line(report: VerifyReport, rel: str, line: str) -> None:
    """One line per video: what the probe found replaces the file check's sha256 mismatch."""
    report.problems = [p for p in report.problems if not p.startswith(f"{rel}: sha256 mismatch")]
    report.problems.append(line)
