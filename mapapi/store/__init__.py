"""Persistence behind one `Store` protocol: SQLite (default) and memory (tests)."""

from mapapi.store.base import ChunkInfo, Store
from mapapi.store.memory import MemoryStore
from mapapi.store.sqlite import SqliteStore

__all__ = ["ChunkInfo", "MemoryStore", "SqliteStore", "Store"]
