"""``python -m oaraim``: the ``oaraim`` command line, where the console script is not on PATH."""

from oaraim.cli import main

main()
