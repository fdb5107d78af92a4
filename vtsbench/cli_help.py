"""Old path of `vtsbench.cli.help` (the --help layout), kept for existing imports."""

from .cli.help import install

__all__ = ["install"]
