"""The Chord DHT (DESIGN §7): pure id arithmetic in `ring`, the networked node apart."""
