"""Deterministic simulation of Raft groups (DESIGN §13): one thread, a seeded network and clock."""
