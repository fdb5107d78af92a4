"""Moved to vtsbench.dataset.format.provenance; re-exported here so that imports of the old path
keep working."""

from .format.provenance import dist_version, package_version, sha256_file, versions

__all__ = [
    "dist_version",
    "package_version",
    "sha256_file",
    "versions",
]
