"""Recordings: the manifest format, media access, import from existing folders, capture
(collect), checks, previews and Taxim data packs."""

from .manifest import (
    MANIFEST_NAME,
    Circle,
    Entry,
    Labels,
    Manifest,
    Mount,
    Session,
    Source,
    load_manifest,
    save_manifest,
)

__all__ = ["MANIFEST_NAME", "Circle", "Entry", "Labels", "Manifest", "Mount", "Session", "Source",
           "load_manifest", "save_manifest"]
