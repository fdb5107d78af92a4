"""The bounds on every size, count and string a user gives (options, metadata), in one place:
the commands state them in --help and the library functions check them before any work."""

from __future__ import annotations

from .errors import VtsError

#: Worker processes or threads of any command.
MAX_WORKERS = 256
#: A seed: numpy's classic 32-bit range.
MAX_SEED = 2**32 - 1
#: Frames of one sequence (simulate --frames, build --frames, collect --window, manifest
#: --window).
MAX_FRAMES = 1000
#: Entries of one kind that simulate writes.
MAX_SIM_ENTRIES = 10_000
#: Sessions that simulate writes.
MAX_SIM_SESSIONS = 1000
#: A frame's side in pixels (simulate --size).
MAX_SIDE_PX = 4096
#: Pixels of one simulated sequence (frames x height x width): about 20 bytes each in memory.
MAX_SEQUENCE_PIXELS = 100_000_000
#: build --shard-mb.
MIN_SHARD_MB, MAX_SHARD_MB = 0.01, 2048.0
#: Characters of a name or id (method, sensor, session, object, take, split, part, license).
MAX_NAME = 200
#: Characters of a version string (dataset_version).
MAX_VERSION = 64
#: Characters of a path, URL, address or pattern.
MAX_PATH_TEXT = 4096
#: Characters of free text (a description, notes, authors).
MAX_TEXT = 4096
#: Bytes of a submission's metadata file.
MAX_META_BYTES = 64 << 10


def check_range(option: str, value: float, low: float, high: float) -> None:
    """A one-line VtsError naming OPTION unless LOW <= VALUE <= HIGH."""
    if not low <= value <= high:
        raise VtsError(f"{option} must be between {_num(low)} and {_num(high)}, got "
                       f"{_num(value)}")


def _num(v: float) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def check_text(option: str, value: str | None, limit: int) -> None:
    """A one-line VtsError naming OPTION when VALUE has more than LIMIT characters."""
    if value is not None and len(value) > limit:
        raise VtsError(f"{option} has {len(value)} characters; at most {limit}")
#: A step in frames (manifest and collect --stride, collect --every), and frames of one take.
MAX_STRIDE = 1_000_000
MAX_TAKE_FRAMES = 100_000_000
#: A frame rate in frames per second.
MAX_FPS = 100_000.0
#: A scale in mm per pixel, a ball radius and a motion threshold in mm.
MAX_MM_PER_PX = 10.0
MAX_MM = 1000.0
#: Any other count a user gives (calibrate --holdout).
MAX_COUNT = 1_000_000
#: Characters of a split or part name (schemas/split.schema.json).
MAX_SPLIT = 64
