"""User-facing errors: one line naming the file and the reason, shown without a traceback."""

from __future__ import annotations

#: The most characters of one error line's reason, and of the path it names; a longer value (a
#: 5 MB method name, a 200 KB version) is cut with an ellipsis and its length.
MAX_MESSAGE = 1000
MAX_PATH = 300
#: Line breaks and other control characters, which would split an error over several lines or
#: drive the terminal: shown escaped, as Python writes them in a string literal.
_CONTROL = {c: ascii(chr(c))[1:-1] for c in (*range(0x20), *range(0x7F, 0xA0), 0x2028, 0x2029)}


def one_line(text: object, limit: int = MAX_MESSAGE) -> str:
    """TEXT on one line (control characters escaped) and at most about LIMIT characters."""
    s = str(text).translate(_CONTROL)
    if len(s) <= limit:
        return s
    return f"{s[:limit]}... ({len(s)} characters)"


class VtsError(Exception):
    """An error caused by user input; the CLI prints it as one line and exits 2.

    `path` is the file as given; `reason` the message alone. The text is always one line of
    bounded length, whatever values the message quotes."""

    def __init__(self, message: str, path: object | None = None) -> None:
        self.path = None if path is None else str(path)
        self.reason = one_line(message)
        shown = one_line(self.path, MAX_PATH) if self.path else None
        super().__init__(f"{shown}: {self.reason}" if shown else self.reason)
