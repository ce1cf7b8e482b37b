from mapapi._pb.mapapi.v1 import core_pb2 as _core_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Envelope(_message.Message):
    __slots__ = ("request_id", "sender", "lamport", "kind", "error", "ping", "pong", "ack", "holders_query", "holders", "chord_find_successor", "chord_hop", "chord_get_neighbours", "chord_neighbours", "chord_notify", "chord_leave", "chord_add", "chord_remove", "chord_get", "chord_values", "chord_store", "chunk_list_query", "chunk_list", "trigger_push", "hello", "welcome", "bye", "control_call", "control_result", "raft_batch", "raft_propose", "raft_proposed", "chain_head", "group_join", "group_leave", "group_changed")
    class Kind(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        KIND_UNSPECIFIED: _ClassVar[Envelope.Kind]
        KIND_REQUEST: _ClassVar[Envelope.Kind]
        KIND_REPLY: _ClassVar[Envelope.Kind]
        KIND_NOTIFY: _ClassVar[Envelope.Kind]
    KIND_UNSPECIFIED: Envelope.Kind
    KIND_REQUEST: Envelope.Kind
    KIND_REPLY: Envelope.Kind
    KIND_NOTIFY: Envelope.Kind
    REQUEST_ID_FIELD_NUMBER: _ClassVar[int]
    SENDER_FIELD_NUMBER: _ClassVar[int]
    LAMPORT_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    ERROR_FIELD_NUMBER: _ClassVar[int]
    PING_FIELD_NUMBER: _ClassVar[int]
    PONG_FIELD_NUMBER: _ClassVar[int]
    ACK_FIELD_NUMBER: _ClassVar[int]
    HOLDERS_QUERY_FIELD_NUMBER: _ClassVar[int]
    HOLDERS_FIELD_NUMBER: _ClassVar[int]
    CHORD_FIND_SUCCESSOR_FIELD_NUMBER: _ClassVar[int]
    CHORD_HOP_FIELD_NUMBER: _ClassVar[int]
    CHORD_GET_NEIGHBOURS_FIELD_NUMBER: _ClassVar[int]
    CHORD_NEIGHBOURS_FIELD_NUMBER: _ClassVar[int]
    CHORD_NOTIFY_FIELD_NUMBER: _ClassVar[int]
    CHORD_LEAVE_FIELD_NUMBER: _ClassVar[int]
    CHORD_ADD_FIELD_NUMBER: _ClassVar[int]
    CHORD_REMOVE_FIELD_NUMBER: _ClassVar[int]
    CHORD_GET_FIELD_NUMBER: _ClassVar[int]
    CHORD_VALUES_FIELD_NUMBER: _ClassVar[int]
    CHORD_STORE_FIELD_NUMBER: _ClassVar[int]
    CHUNK_LIST_QUERY_FIELD_NUMBER: _ClassVar[int]
    CHUNK_LIST_FIELD_NUMBER: _ClassVar[int]
    TRIGGER_PUSH_FIELD_NUMBER: _ClassVar[int]
    HELLO_FIELD_NUMBER: _ClassVar[int]
    WELCOME_FIELD_NUMBER: _ClassVar[int]
    BYE_FIELD_NUMBER: _ClassVar[int]
    CONTROL_CALL_FIELD_NUMBER: _ClassVar[int]
    CONTROL_RESULT_FIELD_NUMBER: _ClassVar[int]
    RAFT_BATCH_FIELD_NUMBER: _ClassVar[int]
    RAFT_PROPOSE_FIELD_NUMBER: _ClassVar[int]
    RAFT_PROPOSED_FIELD_NUMBER: _ClassVar[int]
    CHAIN_HEAD_FIELD_NUMBER: _ClassVar[int]
    GROUP_JOIN_FIELD_NUMBER: _ClassVar[int]
    GROUP_LEAVE_FIELD_NUMBER: _ClassVar[int]
    GROUP_CHANGED_FIELD_NUMBER: _ClassVar[int]
    request_id: int
    sender: bytes
    lamport: int
    kind: Envelope.Kind
    error: ErrorReply
    ping: Ping
    pong: Pong
    ack: Ack
    holders_query: HoldersQuery
    holders: Holders
    chord_find_successor: ChordFindSuccessor
    chord_hop: ChordHop
    chord_get_neighbours: ChordGetNeighbours
    chord_neighbours: ChordNeighbours
    chord_notify: ChordNotify
    chord_leave: ChordLeave
    chord_add: ChordAdd
    chord_remove: ChordRemove
    chord_get: ChordGet
    chord_values: ChordValues
    chord_store: ChordStore
    chunk_list_query: ChunkListQuery
    chunk_list: ChunkList
    trigger_push: TriggerPush
    hello: Hello
    welcome: Welcome
    bye: Bye
    control_call: ControlCall
    control_result: ControlResult
    raft_batch: RaftBatch
    raft_propose: RaftPropose
    raft_proposed: RaftProposed
    chain_head: ChainHead
    group_join: GroupJoin
    group_leave: GroupLeave
    group_changed: GroupChanged
    def __init__(self, request_id: _Optional[int] = ..., sender: _Optional[bytes] = ..., lamport: _Optional[int] = ..., kind: _Optional[_Union[Envelope.Kind, str]] = ..., error: _Optional[_Union[ErrorReply, _Mapping]] = ..., ping: _Optional[_Union[Ping, _Mapping]] = ..., pong: _Optional[_Union[Pong, _Mapping]] = ..., ack: _Optional[_Union[Ack, _Mapping]] = ..., holders_query: _Optional[_Union[HoldersQuery, _Mapping]] = ..., holders: _Optional[_Union[Holders, _Mapping]] = ..., chord_find_successor: _Optional[_Union[ChordFindSuccessor, _Mapping]] = ..., chord_hop: _Optional[_Union[ChordHop, _Mapping]] = ..., chord_get_neighbours: _Optional[_Union[ChordGetNeighbours, _Mapping]] = ..., chord_neighbours: _Optional[_Union[ChordNeighbours, _Mapping]] = ..., chord_notify: _Optional[_Union[ChordNotify, _Mapping]] = ..., chord_leave: _Optional[_Union[ChordLeave, _Mapping]] = ..., chord_add: _Optional[_Union[ChordAdd, _Mapping]] = ..., chord_remove: _Optional[_Union[ChordRemove, _Mapping]] = ..., chord_get: _Optional[_Union[ChordGet, _Mapping]] = ..., chord_values: _Optional[_Union[ChordValues, _Mapping]] = ..., chord_store: _Optional[_Union[ChordStore, _Mapping]] = ..., chunk_list_query: _Optional[_Union[ChunkListQuery, _Mapping]] = ..., chunk_list: _Optional[_Union[ChunkList, _Mapping]] = ..., trigger_push: _Optional[_Union[TriggerPush, _Mapping]] = ..., hello: _Optional[_Union[Hello, _Mapping]] = ..., welcome: _Optional[_Union[Welcome, _Mapping]] = ..., bye: _Optional[_Union[Bye, _Mapping]] = ..., control_call: _Optional[_Union[ControlCall, _Mapping]] = ..., control_result: _Optional[_Union[ControlResult, _Mapping]] = ..., raft_batch: _Optional[_Union[RaftBatch, _Mapping]] = ..., raft_propose: _Optional[_Union[RaftPropose, _Mapping]] = ..., raft_proposed: _Optional[_Union[RaftProposed, _Mapping]] = ..., chain_head: _Optional[_Union[ChainHead, _Mapping]] = ..., group_join: _Optional[_Union[GroupJoin, _Mapping]] = ..., group_leave: _Optional[_Union[GroupLeave, _Mapping]] = ..., group_changed: _Optional[_Union[GroupChanged, _Mapping]] = ...) -> None: ...

class ErrorReply(_message.Message):
    __slots__ = ("code", "message", "conflicts", "seen_at")
    CODE_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    CONFLICTS_FIELD_NUMBER: _ClassVar[int]
    SEEN_AT_FIELD_NUMBER: _ClassVar[int]
    code: int
    message: str
    conflicts: _containers.RepeatedCompositeFieldContainer[_core_pb2.Conflict]
    seen_at: int
    def __init__(self, code: _Optional[int] = ..., message: _Optional[str] = ..., conflicts: _Optional[_Iterable[_Union[_core_pb2.Conflict, _Mapping]]] = ..., seen_at: _Optional[int] = ...) -> None: ...

class Ping(_message.Message):
    __slots__ = ("payload",)
    PAYLOAD_FIELD_NUMBER: _ClassVar[int]
    payload: bytes
    def __init__(self, payload: _Optional[bytes] = ...) -> None: ...

class Pong(_message.Message):
    __slots__ = ("payload",)
    PAYLOAD_FIELD_NUMBER: _ClassVar[int]
    payload: bytes
    def __init__(self, payload: _Optional[bytes] = ...) -> None: ...

class Ack(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class Member(_message.Message):
    __slots__ = ("id", "address", "name")
    ID_FIELD_NUMBER: _ClassVar[int]
    ADDRESS_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    id: bytes
    address: str
    name: str
    def __init__(self, id: _Optional[bytes] = ..., address: _Optional[str] = ..., name: _Optional[str] = ...) -> None: ...

class HoldersQuery(_message.Message):
    __slots__ = ("chunk", "item")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    ITEM_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    item: bytes
    def __init__(self, chunk: _Optional[bytes] = ..., item: _Optional[bytes] = ...) -> None: ...

class Holders(_message.Message):
    __slots__ = ("chunk", "table", "holders")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    HOLDERS_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    table: str
    holders: _containers.RepeatedCompositeFieldContainer[Member]
    def __init__(self, chunk: _Optional[bytes] = ..., table: _Optional[str] = ..., holders: _Optional[_Iterable[_Union[Member, _Mapping]]] = ...) -> None: ...

class ChordPeer(_message.Message):
    __slots__ = ("key", "address")
    KEY_FIELD_NUMBER: _ClassVar[int]
    ADDRESS_FIELD_NUMBER: _ClassVar[int]
    key: bytes
    address: str
    def __init__(self, key: _Optional[bytes] = ..., address: _Optional[str] = ...) -> None: ...

class ChordFindSuccessor(_message.Message):
    __slots__ = ("key", "avoid")
    KEY_FIELD_NUMBER: _ClassVar[int]
    AVOID_FIELD_NUMBER: _ClassVar[int]
    key: bytes
    avoid: _containers.RepeatedScalarFieldContainer[bytes]
    def __init__(self, key: _Optional[bytes] = ..., avoid: _Optional[_Iterable[bytes]] = ...) -> None: ...

class ChordHop(_message.Message):
    __slots__ = ("node", "final")
    NODE_FIELD_NUMBER: _ClassVar[int]
    FINAL_FIELD_NUMBER: _ClassVar[int]
    node: ChordPeer
    final: bool
    def __init__(self, node: _Optional[_Union[ChordPeer, _Mapping]] = ..., final: _Optional[bool] = ...) -> None: ...

class ChordGetNeighbours(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ChordNeighbours(_message.Message):
    __slots__ = ("predecessor", "successors")
    PREDECESSOR_FIELD_NUMBER: _ClassVar[int]
    SUCCESSORS_FIELD_NUMBER: _ClassVar[int]
    predecessor: _containers.RepeatedCompositeFieldContainer[ChordPeer]
    successors: _containers.RepeatedCompositeFieldContainer[ChordPeer]
    def __init__(self, predecessor: _Optional[_Iterable[_Union[ChordPeer, _Mapping]]] = ..., successors: _Optional[_Iterable[_Union[ChordPeer, _Mapping]]] = ...) -> None: ...

class ChordNotify(_message.Message):
    __slots__ = ("node",)
    NODE_FIELD_NUMBER: _ClassVar[int]
    node: ChordPeer
    def __init__(self, node: _Optional[_Union[ChordPeer, _Mapping]] = ...) -> None: ...

class ChordLeave(_message.Message):
    __slots__ = ("node", "predecessor", "successors")
    NODE_FIELD_NUMBER: _ClassVar[int]
    PREDECESSOR_FIELD_NUMBER: _ClassVar[int]
    SUCCESSORS_FIELD_NUMBER: _ClassVar[int]
    node: ChordPeer
    predecessor: _containers.RepeatedCompositeFieldContainer[ChordPeer]
    successors: _containers.RepeatedCompositeFieldContainer[ChordPeer]
    def __init__(self, node: _Optional[_Union[ChordPeer, _Mapping]] = ..., predecessor: _Optional[_Iterable[_Union[ChordPeer, _Mapping]]] = ..., successors: _Optional[_Iterable[_Union[ChordPeer, _Mapping]]] = ...) -> None: ...

class ChordAdd(_message.Message):
    __slots__ = ("key", "member", "ttl", "replica")
    KEY_FIELD_NUMBER: _ClassVar[int]
    MEMBER_FIELD_NUMBER: _ClassVar[int]
    TTL_FIELD_NUMBER: _ClassVar[int]
    REPLICA_FIELD_NUMBER: _ClassVar[int]
    key: bytes
    member: bytes
    ttl: float
    replica: bool
    def __init__(self, key: _Optional[bytes] = ..., member: _Optional[bytes] = ..., ttl: _Optional[float] = ..., replica: _Optional[bool] = ...) -> None: ...

class ChordRemove(_message.Message):
    __slots__ = ("key", "member", "replica")
    KEY_FIELD_NUMBER: _ClassVar[int]
    MEMBER_FIELD_NUMBER: _ClassVar[int]
    REPLICA_FIELD_NUMBER: _ClassVar[int]
    key: bytes
    member: bytes
    replica: bool
    def __init__(self, key: _Optional[bytes] = ..., member: _Optional[bytes] = ..., replica: _Optional[bool] = ...) -> None: ...

class ChordGet(_message.Message):
    __slots__ = ("key", "filter", "argument")
    KEY_FIELD_NUMBER: _ClassVar[int]
    FILTER_FIELD_NUMBER: _ClassVar[int]
    ARGUMENT_FIELD_NUMBER: _ClassVar[int]
    key: bytes
    filter: str
    argument: bytes
    def __init__(self, key: _Optional[bytes] = ..., filter: _Optional[str] = ..., argument: _Optional[bytes] = ...) -> None: ...

class ChordValues(_message.Message):
    __slots__ = ("members",)
    MEMBERS_FIELD_NUMBER: _ClassVar[int]
    members: _containers.RepeatedScalarFieldContainer[bytes]
    def __init__(self, members: _Optional[_Iterable[bytes]] = ...) -> None: ...

class ChordEntry(_message.Message):
    __slots__ = ("key", "member", "ttl")
    KEY_FIELD_NUMBER: _ClassVar[int]
    MEMBER_FIELD_NUMBER: _ClassVar[int]
    TTL_FIELD_NUMBER: _ClassVar[int]
    key: bytes
    member: bytes
    ttl: float
    def __init__(self, key: _Optional[bytes] = ..., member: _Optional[bytes] = ..., ttl: _Optional[float] = ...) -> None: ...

class ChordStore(_message.Message):
    __slots__ = ("entries", "replicate")
    ENTRIES_FIELD_NUMBER: _ClassVar[int]
    REPLICATE_FIELD_NUMBER: _ClassVar[int]
    entries: _containers.RepeatedCompositeFieldContainer[ChordEntry]
    replicate: bool
    def __init__(self, entries: _Optional[_Iterable[_Union[ChordEntry, _Mapping]]] = ..., replicate: _Optional[bool] = ...) -> None: ...

class TriggerPush(_message.Message):
    __slots__ = ("subscription", "record", "revisions", "tables")
    SUBSCRIPTION_FIELD_NUMBER: _ClassVar[int]
    RECORD_FIELD_NUMBER: _ClassVar[int]
    REVISIONS_FIELD_NUMBER: _ClassVar[int]
    TABLES_FIELD_NUMBER: _ClassVar[int]
    subscription: bytes
    record: _core_pb2.CommitRecord
    revisions: _containers.RepeatedCompositeFieldContainer[_core_pb2.Revision]
    tables: _containers.RepeatedCompositeFieldContainer[_core_pb2.TableDescriptor]
    def __init__(self, subscription: _Optional[bytes] = ..., record: _Optional[_Union[_core_pb2.CommitRecord, _Mapping]] = ..., revisions: _Optional[_Iterable[_Union[_core_pb2.Revision, _Mapping]]] = ..., tables: _Optional[_Iterable[_Union[_core_pb2.TableDescriptor, _Mapping]]] = ...) -> None: ...

class ChunkListQuery(_message.Message):
    __slots__ = ("table",)
    TABLE_FIELD_NUMBER: _ClassVar[int]
    table: str
    def __init__(self, table: _Optional[str] = ...) -> None: ...

class ChunkSummary(_message.Message):
    __slots__ = ("chunk", "table", "items")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    ITEMS_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    table: str
    items: int
    def __init__(self, chunk: _Optional[bytes] = ..., table: _Optional[str] = ..., items: _Optional[int] = ...) -> None: ...

class ChunkList(_message.Message):
    __slots__ = ("chunks",)
    CHUNKS_FIELD_NUMBER: _ClassVar[int]
    chunks: _containers.RepeatedCompositeFieldContainer[ChunkSummary]
    def __init__(self, chunks: _Optional[_Iterable[_Union[ChunkSummary, _Mapping]]] = ...) -> None: ...

class Hello(_message.Message):
    __slots__ = ("member", "index")
    MEMBER_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    member: Member
    index: str
    def __init__(self, member: _Optional[_Union[Member, _Mapping]] = ..., index: _Optional[str] = ...) -> None: ...

class Welcome(_message.Message):
    __slots__ = ("members",)
    MEMBERS_FIELD_NUMBER: _ClassVar[int]
    members: _containers.RepeatedCompositeFieldContainer[Member]
    def __init__(self, members: _Optional[_Iterable[_Union[Member, _Mapping]]] = ...) -> None: ...

class Bye(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ControlCall(_message.Message):
    __slots__ = ("op", "args_json", "token")
    OP_FIELD_NUMBER: _ClassVar[int]
    ARGS_JSON_FIELD_NUMBER: _ClassVar[int]
    TOKEN_FIELD_NUMBER: _ClassVar[int]
    op: str
    args_json: str
    token: str
    def __init__(self, op: _Optional[str] = ..., args_json: _Optional[str] = ..., token: _Optional[str] = ...) -> None: ...

class ControlResult(_message.Message):
    __slots__ = ("json",)
    JSON_FIELD_NUMBER: _ClassVar[int]
    json: str
    def __init__(self, json: _Optional[str] = ...) -> None: ...

class RaftEntry(_message.Message):
    __slots__ = ("term", "index", "kind", "data")
    TERM_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    term: int
    index: int
    kind: int
    data: bytes
    def __init__(self, term: _Optional[int] = ..., index: _Optional[int] = ..., kind: _Optional[int] = ..., data: _Optional[bytes] = ...) -> None: ...

class RaftMessage(_message.Message):
    __slots__ = ("chunk", "kind", "sender", "to", "term", "log_term", "index", "entries", "commit", "reject", "reject_hint", "has_snapshot", "snap_index", "snap_term", "snap_config", "snap_data", "context")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    SENDER_FIELD_NUMBER: _ClassVar[int]
    TO_FIELD_NUMBER: _ClassVar[int]
    TERM_FIELD_NUMBER: _ClassVar[int]
    LOG_TERM_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    ENTRIES_FIELD_NUMBER: _ClassVar[int]
    COMMIT_FIELD_NUMBER: _ClassVar[int]
    REJECT_FIELD_NUMBER: _ClassVar[int]
    REJECT_HINT_FIELD_NUMBER: _ClassVar[int]
    HAS_SNAPSHOT_FIELD_NUMBER: _ClassVar[int]
    SNAP_INDEX_FIELD_NUMBER: _ClassVar[int]
    SNAP_TERM_FIELD_NUMBER: _ClassVar[int]
    SNAP_CONFIG_FIELD_NUMBER: _ClassVar[int]
    SNAP_DATA_FIELD_NUMBER: _ClassVar[int]
    CONTEXT_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    kind: int
    sender: int
    to: int
    term: int
    log_term: int
    index: int
    entries: _containers.RepeatedCompositeFieldContainer[RaftEntry]
    commit: int
    reject: bool
    reject_hint: int
    has_snapshot: bool
    snap_index: int
    snap_term: int
    snap_config: bytes
    snap_data: bytes
    context: bytes
    def __init__(self, chunk: _Optional[bytes] = ..., kind: _Optional[int] = ..., sender: _Optional[int] = ..., to: _Optional[int] = ..., term: _Optional[int] = ..., log_term: _Optional[int] = ..., index: _Optional[int] = ..., entries: _Optional[_Iterable[_Union[RaftEntry, _Mapping]]] = ..., commit: _Optional[int] = ..., reject: _Optional[bool] = ..., reject_hint: _Optional[int] = ..., has_snapshot: _Optional[bool] = ..., snap_index: _Optional[int] = ..., snap_term: _Optional[int] = ..., snap_config: _Optional[bytes] = ..., snap_data: _Optional[bytes] = ..., context: _Optional[bytes] = ...) -> None: ...

class RaftBatch(_message.Message):
    __slots__ = ("messages",)
    MESSAGES_FIELD_NUMBER: _ClassVar[int]
    messages: _containers.RepeatedCompositeFieldContainer[RaftMessage]
    def __init__(self, messages: _Optional[_Iterable[_Union[RaftMessage, _Mapping]]] = ...) -> None: ...

class RaftPropose(_message.Message):
    __slots__ = ("chunk", "proposal")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    PROPOSAL_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    proposal: bytes
    def __init__(self, chunk: _Optional[bytes] = ..., proposal: _Optional[bytes] = ...) -> None: ...

class RaftProposed(_message.Message):
    __slots__ = ("record", "revisions", "prepared", "busy", "decided", "commit", "time")
    RECORD_FIELD_NUMBER: _ClassVar[int]
    REVISIONS_FIELD_NUMBER: _ClassVar[int]
    PREPARED_FIELD_NUMBER: _ClassVar[int]
    BUSY_FIELD_NUMBER: _ClassVar[int]
    DECIDED_FIELD_NUMBER: _ClassVar[int]
    COMMIT_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    record: _core_pb2.CommitRecord
    revisions: _containers.RepeatedCompositeFieldContainer[_core_pb2.Revision]
    prepared: int
    busy: bool
    decided: bool
    commit: bool
    time: int
    def __init__(self, record: _Optional[_Union[_core_pb2.CommitRecord, _Mapping]] = ..., revisions: _Optional[_Iterable[_Union[_core_pb2.Revision, _Mapping]]] = ..., prepared: _Optional[int] = ..., busy: _Optional[bool] = ..., decided: _Optional[bool] = ..., commit: _Optional[bool] = ..., time: _Optional[int] = ...) -> None: ...

class ChainHead(_message.Message):
    __slots__ = ("chunk", "count", "link")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    COUNT_FIELD_NUMBER: _ClassVar[int]
    LINK_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    count: int
    link: bytes
    def __init__(self, chunk: _Optional[bytes] = ..., count: _Optional[int] = ..., link: _Optional[bytes] = ...) -> None: ...

class GroupJoin(_message.Message):
    __slots__ = ("chunk",)
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    def __init__(self, chunk: _Optional[bytes] = ...) -> None: ...

class GroupLeave(_message.Message):
    __slots__ = ("chunk",)
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    def __init__(self, chunk: _Optional[bytes] = ...) -> None: ...

class GroupChanged(_message.Message):
    __slots__ = ("index", "members", "leader", "added")
    INDEX_FIELD_NUMBER: _ClassVar[int]
    MEMBERS_FIELD_NUMBER: _ClassVar[int]
    LEADER_FIELD_NUMBER: _ClassVar[int]
    ADDED_FIELD_NUMBER: _ClassVar[int]
    index: int
    members: _containers.RepeatedScalarFieldContainer[bytes]
    leader: bytes
    added: bool
    def __init__(self, index: _Optional[int] = ..., members: _Optional[_Iterable[bytes]] = ..., leader: _Optional[bytes] = ..., added: _Optional[bool] = ...) -> None: ...
