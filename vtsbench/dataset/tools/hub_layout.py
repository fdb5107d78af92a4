"""Names and layout of the Hugging Face copy (hf/): its configs and splits, the files an export
wrote, the YAML of its configs and its section of the dataset card."""

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
class HubLayout:
    """What export wrote: the files of each kind and, per config, split -> files."""

    files: dict[str, list[HubFile]]
    configs: dict[str, dict[str, list[str]]]
    kinds: dict[str, str]  # config -> kind

    def nbytes(self) -> int:
        return sum(f.nbytes for fs in self.files.values() for f in fs)


def configs_yaml(layout: HubLayout, default: str | None) -> list[str]:
    """YAML lines of the hub configs (to go under `configs:`)."""
    lines = []
    for name, splits in layout.configs.items():
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
    names = list(layout.configs)
    return "slip_unseen_objects" if "slip_unseen_objects" in names else (names or [None])[0]


def hub_section(info: DatasetInfo, hub: HubLayout) -> str:
    """The card's section on the parquet copy under hf/ and its configs."""
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


def write_hub_card(root: Path, ds: Any, hub: HubLayout, license: str) -> None:
    """README.md of a dataset with its hub copy (export-hf)."""
    plan = plan_of(ds.info, {k: ds.view(k).index for k in KINDS})
    extra = HubCard(configs_yaml(hub, default_config(hub)), hub_section(ds.info, hub))
    write_bytes_atomic(root / CARD_PATH, card_text(ds.info, plan, extra, license).encode("utf-8"))
