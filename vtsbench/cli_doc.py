"""Old path of `vtsbench.cli.doc`: `python -m vtsbench.cli_doc docs/cli.md` still writes the
command line reference."""

import sys

from .cli.doc import HEAD, IDEAS, KNOWN, _literal, commands, main, markdown

__all__ = ["HEAD", "IDEAS", "KNOWN", "_literal", "commands", "main", "markdown"]

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
