"""`python -m vtsbench` runs the command line."""

from .cli import main

main()
