"""Names and layout of the Hugging Face copy (hf/): its configs and splits, the files an export
wrote, the YAML of its configs and its section of the dataset card; the paths of the episodes'
subtree (hf/episodes/, laid out as LeRobot v2.1 lays out a dataset's meta files and data)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...atomic import write_bytes_atomic
from ..build.card import HubCard, card_text, plan_of
from ..format.info import DatasetInfo
from ..format.layout import CARD_PATH, HUB_DIR, KINDS
from .hub_rows import HUB_VERSION

#: Parts of a split scheme -> split names of `datasets` (train, validation, test; folds as is).
SPLIT_NAMES = {"val": "validation"}

#: The episodes of a dataset in the hub copy: LeRobot v2.1's tree (meta files, then one parquet
#: file per episode in chunks of CHUNKS_SIZE episodes), relative to the dataset.
EPISODES_HUB = f"{HUB_DIR}/episodes"
#: The meta files, relative to EPISODES_HUB, under LeRobot's names.
EPISODES_META = {"info": "meta/info.json", "episodes": "meta/episodes.jsonl",
                 "tasks": "meta/tasks.jsonl", "stats": "meta/episodes_stats.jsonl"}
#: An episode's parquet file, relative to EPISODES_HUB (LeRobot's `data_path` template).
EPISODE_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
#: Episodes per chunk folder (LeRobot's `chunks_size`).
CHUNKS_SIZE = 1000
#: The config of every frame of every episode, and the glob of its files.
EPISODES_CONFIG = "episodes"
EPISODES_GLOB = f"{EPISODES_HUB}/data/*/*.parquet"


def episode_file(episode_index: int) -> str:
    """`hf/episodes/data/chunk-CCC/episode_NNNNNN.parquet`: an episode's frames."""
    return f"{EPISODES_HUB}/" + EPISODE_DATA_PATH.format(
        episode_chunk=episode_index // CHUNKS_SIZE, episode_index=episode_index)


def config_name(kind: str, scheme: str) -> str:
    """The `datasets` config of a split scheme: `<kind>_<scheme>`, without repeating the kind
    (static_sessions stays static_sessions)."""
    return scheme if scheme.startswith(f"{kind}_") else f"{kind}_{scheme}"


def split_name(part: str) -> str:
    """The `datasets` split of a part: val -> validation; train, test, foldK unchanged; any
    character datasets refuses in a split name (not a letter, digit or _) becomes _."""
    return re.sub(r"\W", "_", SPLIT_NAMES.get(part, part), flags=re.ASCII)


@dataclass
class HubFile:
    """One written parquet file: its path (relative to the dataset), cell and rows."""

    path: str
    cell: int
    rows: int
    nbytes: int


@dataclass
class EpisodesHub:
    """What export wrote of the episodes: one file per episode (`cell`: its episode index,
    `rows`: its frames), the meta files, and per config, split -> files (or a glob)."""

    files: list[HubFile]
    meta: list[str]
    configs: dict[str, dict[str, list[str]]]
    parts: dict[str, dict[str, list[int]]]  # config -> split -> episode indices

    def nbytes(self) -> int:
        return sum(f.nbytes for f in self.files)


@dataclass
class HubLayout:
    """What export wrote: the files of each kind and, per config, split -> files; the
    episodes' subtree when the dataset has episodes."""

    files: dict[str, list[HubFile]]
    configs: dict[str, dict[str, list[str]]]
    kinds: dict[str, str]  # config -> kind
    episodes: EpisodesHub | None = None

    def nbytes(self) -> int:
        own = self.episodes.nbytes() if self.episodes is not None else 0
        return own + sum(f.nbytes for fs in self.files.values() for f in fs)

    def all_configs(self) -> dict[str, dict[str, list[str]]]:
        """Every config of the card: the samples' ones, then the episodes' ones."""
        return {**self.configs, **(self.episodes.configs if self.episodes else {})}


def configs_yaml(layout: HubLayout, default: str | None) -> list[str]:
    """YAML lines of the hub configs (to go under `configs:`)."""
    lines = []
    for name, splits in layout.all_configs().items():
        lines += [f"- config_name: {name}", "  data_files:"]
        for split, paths in splits.items():
            lines += [f"  - split: {split}", "    path:"]
            lines += [f"    - {p}" for p in paths]
        if name == default:
            lines.append("  default: true")
    return lines


def default_config(layout: HubLayout) -> str | None:
    """The config the Hub shows first: slip_unseen_objects (the headline benchmark), else the
    first config."""
    names = list(layout.all_configs())
    return "slip_unseen_objects" if "slip_unseen_objects" in names else (names or [None])[0]


def hub_section(info: DatasetInfo, hub: HubLayout) -> str:
    """The card's section on the parquet copy under hf/ and its configs: the samples' (unless
    the dataset holds episodes alone), then the episodes'."""
    has_samples = any(hub.files.values())
    out = _samples_section(info, hub) if has_samples or hub.episodes is None else ""
    return out + (episodes_section(info, hub.episodes) if hub.episodes is not None else "")


def _samples_section(info: DatasetInfo, hub: HubLayout) -> str:
    """The card's section on the samples' parquet files and their configs."""
    n_rows = {f.path: f.rows for fs in hub.files.values() for f in fs}
    rows = "\n".join(f"| `{name}` | {hub.kinds[name]} | "
                     f"{', '.join(f'{s} {sum(n_rows[p] for p in fs)}' for s, fs in splits.items())}"
                     " |" for name, splits in hub.configs.items())
    first = default_config(hub) or ""
    first_split = next(iter(hub.configs.get(first, {"train": []})), "train")
    depth = f"""\
`depth` holds 16-bit TIFFs of the stored int16 depth counts (their bits as uint16): view them as
int16 and multiply by {info.depth_scale_mm} (in float32) for **millimetres** of indentation into
the gel (positive into the gel), exactly what `vtsbench.load` returns; `contact` is the contact
mask as 1-bit PNG images (bool in numpy); `depth_preview` is the depth colour-mapped for viewing
(viridis, from 0 to the sample's maximum or 0.05 mm, whichever is larger), left encoded by
`datasets` (`Image(decode=False)`: cast it to `Image()` to decode it).""" if (
        info.has_depth) else "This dataset has no depth: `rgb` and the labels only."
    scale = info.depth_scale_mm
    convert = ("\ndepth_mm = row[\"depth\"].view(np.int16).astype(np.float32) * "
               f"np.float32({scale})  # mm") if info.has_depth else ""
    return f"""## Hugging Face datasets

Every sample is in `{HUB_DIR}/` as parquet, once: a file holds the samples that share their part
in every split scheme, so each config below is a list of whole files per split. Layout version
{HUB_VERSION}: every frame is an `Image` that `datasets` decodes when a row is read, so the Arrow
cache `load_dataset` builds holds the encoded bytes and is no larger than the parquet. `rgb` holds
the frames as lossless TIFFs (zstd; a list of {info.frames_per_sequence} for a slip sample) that
decode to exactly the stored uint8 pixels; `object`, `state` and `direction` are `ClassLabel`s
with the project's names. {depth}

| config | kind | samples per split |
|---|---|---|
{rows}

Read rows with `.with_format("numpy")`: arrays, not PIL images (a slip sample's frames stacked).

```python
import datasets
import numpy as np
train = datasets.load_dataset("path/to/this/folder", "{first}", split="{first_split}")
row = train.with_format("numpy")[0]  # rgb uint8 (T, H, W, 3), contact bool{convert}
stream = datasets.load_dataset("path/to/this/folder", "{first}", split="{first_split}",
                               streaming=True).with_format("numpy")
names = train.features["object"].names
```

"""


def episodes_section(info: DatasetInfo, hub: EpisodesHub) -> str:
    """The card's section on the episodes' subtree (hf/episodes/) and its configs."""
    frames = sum(f.rows for f in hub.files)
    rows = "\n".join(f"| `{name}` | " + ", ".join(
        f"{s} {len(hub.parts[name][s])}" for s in splits) + " |"
        for name, splits in hub.configs.items())
    images = "`observation.images.rgb` (lossless TIFF, uint8 RGB)"
    convert = ""
    if info.has_depth:
        images += (", `observation.images.depth` (16-bit TIFF of the int16 depth counts: view "
                   f"as int16, x {info.depth_scale_mm} = mm) and `observation.images.contact` "
                   "(1-bit PNG, bool)")
        convert = ("\nmm = row[\"observation.images.depth\"].view(np.int16).astype(np.float32) "
                   f"* np.float32({info.depth_scale_mm})")
    return f"""## Episodes

Every episode (a continuous take, stored once) is in `{EPISODES_HUB}/`, laid out as a LeRobot
v2.1 dataset is: `{EPISODES_META["info"]}` (features, totals, fps, `data_path`),
`{EPISODES_META["episodes"]}`, `{EPISODES_META["tasks"]}` (a task per object),
`{EPISODES_META["stats"]}`, and one parquet file per episode, `{EPISODE_DATA_PATH}`;
{len(hub.files)} episodes, {frames} frames. One row per frame: `episode_index`, `frame_index`,
`timestamp` (seconds from the episode's start), `index` (the frame's row over all episodes),
`task_index`, `state` and `direction` (`ClassLabel`s, -1 where unknown), the frames' own
values, and {images}. Not LeRobot's own files: no `codebase_version` is claimed (the images
are TIFF and PNG, the timestamps float64); vtsbench's metadata (object, session, sensor, slip
onset, splits of episodes) is under the `vtsbench` keys.

| config | episodes per split |
|---|---|
{rows}

```python
import datasets
import numpy as np
frames = datasets.load_dataset("path/to/this/folder", "{EPISODES_CONFIG}", split="full")
row = frames.with_format("numpy")[0]  # observation.images.rgb uint8 (H, W, 3){convert}
```

"""


#: The config of index/episodes.parquet in a card with a hub copy (`episodes` reads the frames).
EPISODES_INDEX_CONFIG = "episodes_index"


def episodes_card(info: DatasetInfo, hub: HubLayout, license: str) -> str:
    """README.md of a dataset of episodes (vtsbench.create) with its hub copy: the writer's card
    with the license, the hub configs first (the writer's `episodes` config of the episode
    index renamed `episodes_index`, none of its own the default) and the hub section before
    its arrays."""
    from ..build.episode_finish import card_text as writer_card

    _, head, body = writer_card(info).split("---\n", 2)
    lines = head.splitlines()
    at = lines.index("configs:")
    keys = ["license: " + license if ln.startswith("license:") else ln for ln in lines[:at]]
    own = [f"- config_name: {EPISODES_INDEX_CONFIG}" if ln == f"- config_name: {EPISODES_CONFIG}"
           else ln for ln in lines[at + 1:] if ln.strip() != "default: true"]
    yaml = [*keys, "configs:", *configs_yaml(hub, default_config(hub)), *own]
    section = hub_section(info, hub)
    mark = "## Arrays\n"
    body = body.replace(mark, section + mark, 1) if mark in body else body + "\n" + section
    return "---\n" + "\n".join(yaml) + "\n---\n" + body


def write_hub_card(root: Path, ds: Any, hub: HubLayout, license: str) -> None:
    """README.md of a dataset with its hub copy (export-hf): the build's card, or for a dataset
    of episodes the writer's, with the hub configs and section."""
    if ds.info.episodes is not None:
        text = episodes_card(ds.info, hub, license)
    else:
        plan = plan_of(ds.info, {k: ds.view(k).index for k in KINDS})
        extra = HubCard(configs_yaml(hub, default_config(hub)), hub_section(ds.info, hub))
        text = card_text(ds.info, plan, extra, license)
    write_bytes_atomic(root / CARD_PATH, text.encode("utf-8"))
