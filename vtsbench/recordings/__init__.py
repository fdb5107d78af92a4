"""Recordings: the manifest format, media access, import from existing folders and checks."""

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
