"""Typed 128-bit ids and 160-bit ring keys (mapapi.core.ids)."""

import hashlib

import pytest

from mapapi.core.ids import ChunkId, CommitId, Id, ItemId, PeerId, ring_key

HEX = "0123456789abcdef0123456789abcdef"


class TestId:
    def test_wraps_32_hex_digits(self) -> None:
        assert ItemId(HEX) == HEX
        assert isinstance(ItemId(HEX), str)

    def test_lowercases_upper_hex(self) -> None:
        assert ChunkId(HEX.upper()) == HEX

    @pytest.mark.parametrize(
        "bad",
        ["", "abc", HEX[:-1], HEX + "0", "g" * 32, " " + HEX[1:], HEX[:-1] + "\n", "-" * 32],
    )
    def test_rejects_anything_but_32_hex_digits(self, bad: str) -> None:
        with pytest.raises(ValueError, match="expected 32 hex digits"):
            ItemId(bad)

    def test_error_names_the_id_kind(self) -> None:
        with pytest.raises(ValueError, match="not a PeerId"):
            PeerId("nope")

    def test_new_ids_are_valid_and_distinct(self) -> None:
        ids = {CommitId.new() for _ in range(100)}
        assert len(ids) == 100
        assert all(isinstance(i, CommitId) and CommitId(i) == i for i in ids)

    @pytest.mark.parametrize("kind", [ItemId, ChunkId, PeerId, CommitId])
    def test_new_returns_the_subclass(self, kind: type[Id]) -> None:
        assert type(kind.new()) is kind

    def test_bytes_round_trip(self) -> None:
        item = ItemId(HEX)
        raw = item.to_bytes()
        assert raw == bytes.fromhex(HEX)
        assert len(raw) == 16
        assert ItemId.from_bytes(raw) == item
        assert type(ItemId.from_bytes(raw)) is ItemId

    @pytest.mark.parametrize("size", [0, 15, 17, 20])
    def test_from_bytes_needs_16_bytes(self, size: int) -> None:
        with pytest.raises(ValueError, match=f"needs 16 bytes, got {size}"):
            ChunkId.from_bytes(b"\x00" * size)

    def test_short_is_first_8_digits(self) -> None:
        assert PeerId(HEX).short == "01234567"


class TestRingKey:
    def test_is_sha1_read_big_endian(self) -> None:
        expected = int.from_bytes(hashlib.sha1(b"chunk").digest(), "big")
        assert ring_key(b"chunk") == expected

    def test_str_and_its_utf8_bytes_agree(self) -> None:
        assert ring_key("chunk-é") == ring_key("chunk-é".encode())

    def test_fits_in_160_bits_and_differs_per_input(self) -> None:
        keys = {ring_key(str(i)) for i in range(200)}
        assert len(keys) == 200
        assert all(0 <= k < 2**160 for k in keys)
