"""Names and layout of the Hugging Face copy (hf/): the folder, the files written, the configs
and their YAML for the card. No encoding here, so the card can read it without the export."""

from __future__ import annotations

from dataclasses import dataclass

#: Folder of the parquet files, relative to the dataset.
HUB_DIR = "hf"


def size_category(n: int) -> str:
    """The Hub's size_categories value for n rows."""
    for limit, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"),
                        (1_000_000, "100K<n<1M"), (10_000_000, "1M<n<10M")):
        if n < limit:
            return name
    return "n>10M"


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
