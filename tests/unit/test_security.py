"""Keys, addresses and the trust list of a secure peer, and how a link's
handshake events are judged (DESIGN §10). No sockets."""

from __future__ import annotations

from pathlib import Path

import pytest
import zmq
from zmq.utils import z85

from mapapi.core.errors import CorruptRepoError, UsageError
from mapapi.net.curve import LinkWatch
from mapapi.net.security import (
    Security,
    TrustList,
    key_text,
    keyed_address,
    load_keys,
    own_address,
    parse_key,
    split_address,
)

KEY = bytes(range(32))
OTHER = bytes(range(1, 33))


class TestKeys:
    def test_a_key_reads_as_hex_or_z85_and_shows_as_hex(self) -> None:
        assert parse_key(KEY.hex()) == KEY
        assert parse_key(KEY.hex().upper()) == KEY
        assert parse_key(z85.encode(KEY).decode()) == KEY
        assert key_text(KEY) == KEY.hex()

    @pytest.mark.parametrize("text", ["", "abc", KEY.hex()[:-1], "g" * 64, "tcp://x:1"])
    def test_anything_else_is_a_usage_error(self, text: str) -> None:
        with pytest.raises(UsageError, match="not a public key"):
            parse_key(text)

    def test_a_new_keypair_is_private_and_loads_back(self, tmp_path: Path) -> None:
        made = Security.create(tmp_path)
        folder = tmp_path / "curve"
        assert folder.stat().st_mode & 0o777 == 0o700
        assert (folder / "peer.key_secret").stat().st_mode & 0o777 == 0o600
        loaded = load_keys(folder)
        assert loaded == made.keys
        assert zmq.curve_public(z85.encode(loaded.secret)) == z85.encode(loaded.public)
        assert loaded.secret.hex() not in repr(loaded)
        assert made.trust.current() == frozenset()

    def test_a_secret_key_others_can_read_is_refused(self, tmp_path: Path) -> None:
        Security.create(tmp_path)
        (tmp_path / "curve" / "peer.key_secret").chmod(0o644)
        with pytest.raises(CorruptRepoError, match="chmod 600"):
            Security.load(tmp_path)

    def test_a_missing_secret_key_is_a_clear_error(self, tmp_path: Path) -> None:
        Security.create(tmp_path)
        (tmp_path / "curve" / "peer.key_secret").unlink()
        with pytest.raises(CorruptRepoError, match=r"secret key .* cannot be read"):
            Security.load(tmp_path)

    def test_a_second_keypair_is_refused(self, tmp_path: Path) -> None:
        first = Security.create(tmp_path)
        with pytest.raises(UsageError, match="holds a keypair already"):
            Security.create(tmp_path)
        assert Security.load(tmp_path).keys == first.keys


class TestAddresses:
    def test_the_key_rides_in_the_address(self) -> None:
        address = keyed_address("tcp://10.0.0.5:7000", KEY)
        assert address == f"tcp://10.0.0.5:7000#curve={KEY.hex()}"
        assert split_address(address) == ("tcp://10.0.0.5:7000", KEY)
        assert split_address("tcp://10.0.0.5:7000") == ("tcp://10.0.0.5:7000", None)

    def test_a_malformed_key_part_is_a_usage_error(self) -> None:
        with pytest.raises(UsageError, match="bad key"):
            split_address("tcp://10.0.0.5:7000#curve=abc")

    def test_a_peer_announces_its_own_key(self, tmp_path: Path) -> None:
        security = Security.create(tmp_path)
        mine = keyed_address("tcp://h:1", security.keys.public)
        assert own_address("tcp://h:1", security) == mine
        assert own_address(mine, security) == mine
        assert own_address("tcp://h:1", None) == "tcp://h:1"
        with pytest.raises(UsageError, match="not this peer's"):
            own_address(keyed_address("tcp://h:1", KEY), security)
        with pytest.raises(UsageError, match="not this peer's"):
            own_address(mine, None)


class TestTrustList:
    def test_add_and_remove_say_whether_they_changed_anything(self, tmp_path: Path) -> None:
        trust = TrustList(tmp_path / "trusted.keys")
        assert trust.current() == frozenset()  # no file: nobody
        assert trust.add(KEY) is True
        assert trust.add(KEY) is False
        assert trust.add(OTHER) is True
        assert KEY in trust
        assert trust.remove(KEY) is True
        assert trust.remove(KEY) is False
        assert trust.current() == {OTHER}
        assert (tmp_path / "trusted.keys").stat().st_mode & 0o777 == 0o600

    def test_a_change_by_another_process_is_seen_at_the_next_read(self, tmp_path: Path) -> None:
        path = tmp_path / "trusted.keys"
        running = TrustList(path)  # the running peer's
        running.create()
        assert KEY not in running
        TrustList(path).add(KEY)  # `mapctl trust add` in another process
        assert KEY in running
        TrustList(path).remove(KEY)
        assert KEY not in running

    def test_comments_and_blank_lines_are_ignored(self, tmp_path: Path) -> None:
        path = tmp_path / "trusted.keys"
        path.write_text(f"# robots\n\n{KEY.hex()}  # robot2\n", encoding="utf-8")
        assert TrustList(path).current() == {KEY}

    def test_a_damaged_line_names_the_file_and_line(self, tmp_path: Path) -> None:
        path = tmp_path / "trusted.keys"
        path.write_text(f"{KEY.hex()}\nnot-a-key\n", encoding="utf-8")
        with pytest.raises(CorruptRepoError, match="line 2 is not a key"):
            TrustList(path).current()

    def test_own_key_is_always_trusted(self, tmp_path: Path) -> None:
        security = Security.create(tmp_path)
        assert security.trusts(security.keys.public)
        assert not security.trusts(KEY)
        security.trust.add(KEY)
        assert security.trusts(KEY)


SUCCEEDED = int(zmq.EVENT_HANDSHAKE_SUCCEEDED)
AUTH = int(zmq.EVENT_HANDSHAKE_FAILED_AUTH)
PROTOCOL = int(zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL)
CUT = int(zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL)
MISMATCH = int(zmq.PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH)
CRYPTO = int(zmq.PROTOCOL_ERROR_ZMTP_CRYPTOGRAPHIC)


@pytest.fixture
def security(tmp_path: Path) -> Security:
    return Security.create(tmp_path)


class TestLinkWatch:
    def test_a_refused_key_is_final_and_names_the_key(self, security: Security) -> None:
        error = LinkWatch("tcp://h:1", security).on_event(AUTH, 400)
        assert error is not None
        assert f"mapctl trust add {key_text(security.keys.public)}" in str(error)

    def test_a_mechanism_mismatch_tells_each_side_what_the_other_is(
        self, security: Security
    ) -> None:
        as_open = LinkWatch("tcp://h:1", None).on_event(PROTOCOL, MISMATCH)
        as_secure = LinkWatch("tcp://h:1", security).on_event(PROTOCOL, MISMATCH)
        assert "is a secure swarm and this peer is open" in str(as_open)
        assert "mapctl init --secure" in str(as_open)
        assert "is an open swarm and this peer is secure" in str(as_secure)

    def test_a_wrong_server_key(self, security: Security) -> None:
        error = LinkWatch("tcp://h:1", security).on_event(PROTOCOL, CRYPTO)
        assert "does not hold the key its address names" in str(error)

    def test_cut_handshakes_on_a_new_link_count_twice(self, security: Security) -> None:
        for mine in (None, security):
            watch = LinkWatch("tcp://h:1", mine)
            assert watch.on_event(CUT, 32) is None  # one: perhaps a peer that just died
            error = watch.on_event(CUT, 32)
            assert error is not None
            assert "cut every handshake" in str(error)

    def test_a_link_that_worked_is_never_refused_for_cut_handshakes(self) -> None:
        watch = LinkWatch("tcp://h:1", None)
        assert watch.on_event(SUCCEEDED, 0) is None
        assert all(watch.on_event(CUT, 32) is None for _ in range(10))  # a restarting peer

    def test_a_completed_handshake_resets_the_count(self) -> None:
        watch = LinkWatch("tcp://h:1", None)
        assert watch.on_event(CUT, 32) is None
        assert watch.on_event(SUCCEEDED, 0) is None
        assert watch.failures == 0
