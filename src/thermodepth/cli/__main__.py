"""``python -m thermodepth.cli``: the command line."""

from . import main

main()
