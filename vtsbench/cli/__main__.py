"""`python -m vtsbench.cli` runs the command line, as `python -m vtsbench` does."""

from . import main

main()
