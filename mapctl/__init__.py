"""mapctl: the command line over mapapi."""
