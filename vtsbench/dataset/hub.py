"""Moved to vtsbench.dataset.tools (hub, hub_layout, hub_rows, hub_write); re-exported here so that
imports of the old path keep working."""

from .tools.hub import EXPORT_WORK, ExportResult, export_hf, export_stage, hub_configs
from .tools.hub_layout import HUB_DIR, SPLIT_NAMES, HubFile, HubLayout, config_name, split_name
from .tools.hub_rows import (
    PLAIN_COLUMNS,
    SLIP_PLAIN,
    arrow_schema,
    extra_columns,
    features_doc,
    mask_png,
)
from .tools.hub_write import (
    FILE_BYTES,
    ROW_GROUP_BYTES,
    Cell,
    cells,
    schemes_of,
    write_failed,
    write_kind,
)

__all__ = [
    "EXPORT_WORK",
    "FILE_BYTES",
    "HUB_DIR",
    "PLAIN_COLUMNS",
    "ROW_GROUP_BYTES",
    "SLIP_PLAIN",
    "SPLIT_NAMES",
    "Cell",
    "ExportResult",
    "HubFile",
    "HubLayout",
    "arrow_schema",
    "cells",
    "config_name",
    "export_hf",
    "export_stage",
    "extra_columns",
    "features_doc",
    "hub_configs",
    "mask_png",
    "schemes_of",
    "split_name",
    "write_failed",
    "write_kind",
]
