"""User-facing errors: one line naming the file and the reason, shown without a traceback."""

from __future__ import annotations


class VtsError(Exception):
    """An error caused by user input; the CLI prints it as one line and exits 2."""

    def __init__(self, message: str, path: object | None = None) -> None:
        self.path = None if path is None else str(path)
        super().__init__(f"{self.path}: {message}" if self.path else message)
