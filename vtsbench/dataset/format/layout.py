"""Every path and file name of a dataset folder, and the constants of its arrays, named once.

A dataset folder holds `meta/info.json` (versions, shapes, counts, checksums: format/info.py),
`meta/build_report.json`, `meta/splits/<name>.json` (one per split scheme), the indexes
`index/<kind>.parquet` (format/index.py), the Zarr v3 arrays `data/<kind>.zarr/`
(format/arrays.py), the preview `preview/<kind>.parquet`, the card `README.md` and, after
`vtsbench export-hf`, the Hugging Face copy under `hf/`. Format 1.2 adds episodes (continuous
takes stored once, format/episodes.py): the frames store `data/episodes.zarr` and the indexes
`index/episodes.parquet` and `index/frames.parquet`. Paths are relative, '/'-separated.
"""

from __future__ import annotations

#: The two kinds of sample: single frames and sequences of T frames.
KINDS = ("static", "slip")
#: The arrays of a dataset, and of one built without depth (`vtsbench build --no-depth`).
ARRAYS = ("rgb", "depth", "contact")
RGB_ONLY = ("rgb",)
#: dtypes of the arrays as stored in Zarr, and as a reader gives them (depth in mm).
STORED_DTYPES = {"rgb": "uint8", "depth": "int16", "contact": "bool"}
DECODED_DTYPES = {"rgb": "uint8", "depth": "float32", "contact": "bool"}
DEPTH_DTYPE = STORED_DTYPES["depth"]
#: Depth is stored as int16 counts of this many mm: +-32.767 mm in 1 um steps.
DEPTH_SCALE_MM = 0.001

META_DIR = "meta"
#: Where a dataset keeps its info.json (every reader takes it from here).
INFO_PATH = f"{META_DIR}/info.json"
BUILD_REPORT_PATH = f"{META_DIR}/build_report.json"
SPLITS_DIR = f"{META_DIR}/splits"
INDEX_DIR = "index"
DATA_DIR = "data"
PREVIEW_DIR = "preview"
CARD_PATH = "README.md"
#: Folder of the Hugging Face copy's parquet files (`vtsbench export-hf`).
HUB_DIR = "hf"
#: The folders whose files dataset_sha256 covers (the content; not the card or previews).
CHECKSUMMED = (f"{DATA_DIR}/", f"{INDEX_DIR}/", f"{SPLITS_DIR}/")


def index_path(kind: str) -> str:
    """`index/<kind>.parquet`."""
    return f"{INDEX_DIR}/{kind}.parquet"


def group_path(kind: str) -> str:
    """`data/<kind>.zarr`, the Zarr group of a kind's arrays."""
    return f"{DATA_DIR}/{kind}.zarr"


def split_file_name(name: str) -> str:
    """`<name>.json`, a split's file in SPLITS_DIR."""
    return f"{name}.json"


def split_path(name: str) -> str:
    """`meta/splits/<name>.json`."""
    return f"{SPLITS_DIR}/{split_file_name(name)}"


def preview_path(kind: str) -> str:
    """`preview/<kind>.parquet`."""
    return f"{PREVIEW_DIR}/{kind}.parquet"


#: Episodes (format 1.2): continuous takes stored once, every frame of every episode in one
#: store, windows chosen when reading (format/episodes.py).
EPISODES = "episodes"
#: `data/episodes.zarr`: every frame of every episode, in episode order, one frame per chunk.
EPISODES_GROUP = group_path(EPISODES)
#: `index/episodes.parquet`: one row per episode.
EPISODES_INDEX = index_path(EPISODES)
#: `index/frames.parquet`: one row per frame (timestamp and labels), in store order.
FRAMES_INDEX = index_path("frames")
#: `data/videos/`: the episodes' RGB as one video file each, in a dataset written with
#: `vtsbench.create(..., video=...)` (format/episode_video.py).
VIDEOS_DIR = f"{DATA_DIR}/videos"


def episode_video_path(episode_index: int, suffix: str) -> str:
    """`data/videos/episode-<index, 6 digits><suffix>` (suffix: the codec's container, .mkv or
    .mp4): episode k's RGB as video, named by its index (an episode id may hold any
    character, a path separator included)."""
    return f"{VIDEOS_DIR}/episode-{int(episode_index):06d}{suffix}"
