"""Lookup (DESIGN §7): the Chord ring (`dht/`), the spatial grid and index, and
where this peer's chunks lie."""
