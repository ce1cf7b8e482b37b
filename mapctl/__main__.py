"""`python -m mapctl`."""

from mapctl.cli import main

main()
