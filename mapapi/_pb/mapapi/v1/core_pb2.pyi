from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Revision(_message.Message):
    __slots__ = ("item_id", "table", "chunk_id", "data", "insert_time", "update_time", "removed", "author", "commit_id")
    ITEM_ID_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    CHUNK_ID_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    INSERT_TIME_FIELD_NUMBER: _ClassVar[int]
    UPDATE_TIME_FIELD_NUMBER: _ClassVar[int]
    REMOVED_FIELD_NUMBER: _ClassVar[int]
    AUTHOR_FIELD_NUMBER: _ClassVar[int]
    COMMIT_ID_FIELD_NUMBER: _ClassVar[int]
    item_id: bytes
    table: str
    chunk_id: bytes
    data: bytes
    insert_time: int
    update_time: int
    removed: bool
    author: bytes
    commit_id: bytes
    def __init__(self, item_id: _Optional[bytes] = ..., table: _Optional[str] = ..., chunk_id: _Optional[bytes] = ..., data: _Optional[bytes] = ..., insert_time: _Optional[int] = ..., update_time: _Optional[int] = ..., removed: _Optional[bool] = ..., author: _Optional[bytes] = ..., commit_id: _Optional[bytes] = ...) -> None: ...

class CommitRecord(_message.Message):
    __slots__ = ("id", "time", "author", "message", "chunks", "author_name", "view")
    ID_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    AUTHOR_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    CHUNKS_FIELD_NUMBER: _ClassVar[int]
    AUTHOR_NAME_FIELD_NUMBER: _ClassVar[int]
    VIEW_FIELD_NUMBER: _ClassVar[int]
    id: bytes
    time: int
    author: bytes
    message: str
    chunks: _containers.RepeatedScalarFieldContainer[bytes]
    author_name: str
    view: str
    def __init__(self, id: _Optional[bytes] = ..., time: _Optional[int] = ..., author: _Optional[bytes] = ..., message: _Optional[str] = ..., chunks: _Optional[_Iterable[bytes]] = ..., author_name: _Optional[str] = ..., view: _Optional[str] = ...) -> None: ...

class TableDescriptor(_message.Message):
    __slots__ = ("name", "type_name")
    NAME_FIELD_NUMBER: _ClassVar[int]
    TYPE_NAME_FIELD_NUMBER: _ClassVar[int]
    name: str
    type_name: str
    def __init__(self, name: _Optional[str] = ..., type_name: _Optional[str] = ...) -> None: ...

class Change(_message.Message):
    __slots__ = ("op", "table", "item_id", "chunk_id", "data")
    class Op(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        OP_UNSPECIFIED: _ClassVar[Change.Op]
        INSERT: _ClassVar[Change.Op]
        UPDATE: _ClassVar[Change.Op]
        REMOVE: _ClassVar[Change.Op]
    OP_UNSPECIFIED: Change.Op
    INSERT: Change.Op
    UPDATE: Change.Op
    REMOVE: Change.Op
    OP_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    ITEM_ID_FIELD_NUMBER: _ClassVar[int]
    CHUNK_ID_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    op: Change.Op
    table: str
    item_id: bytes
    chunk_id: bytes
    data: bytes
    def __init__(self, op: _Optional[_Union[Change.Op, str]] = ..., table: _Optional[str] = ..., item_id: _Optional[bytes] = ..., chunk_id: _Optional[bytes] = ..., data: _Optional[bytes] = ...) -> None: ...

class Conflict(_message.Message):
    __slots__ = ("table", "item_id", "base", "ours", "theirs")
    TABLE_FIELD_NUMBER: _ClassVar[int]
    ITEM_ID_FIELD_NUMBER: _ClassVar[int]
    BASE_FIELD_NUMBER: _ClassVar[int]
    OURS_FIELD_NUMBER: _ClassVar[int]
    THEIRS_FIELD_NUMBER: _ClassVar[int]
    table: str
    item_id: bytes
    base: Revision
    ours: Change
    theirs: Revision
    def __init__(self, table: _Optional[str] = ..., item_id: _Optional[bytes] = ..., base: _Optional[_Union[Revision, _Mapping]] = ..., ours: _Optional[_Union[Change, _Mapping]] = ..., theirs: _Optional[_Union[Revision, _Mapping]] = ...) -> None: ...

class Scope(_message.Message):
    __slots__ = ("table", "chunk")
    TABLE_FIELD_NUMBER: _ClassVar[int]
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    table: str
    chunk: bytes
    def __init__(self, table: _Optional[str] = ..., chunk: _Optional[bytes] = ...) -> None: ...

class ViewState(_message.Message):
    __slots__ = ("name", "begin_time", "isolation", "changes", "conflicts", "read_set", "scopes", "stale")
    NAME_FIELD_NUMBER: _ClassVar[int]
    BEGIN_TIME_FIELD_NUMBER: _ClassVar[int]
    ISOLATION_FIELD_NUMBER: _ClassVar[int]
    CHANGES_FIELD_NUMBER: _ClassVar[int]
    CONFLICTS_FIELD_NUMBER: _ClassVar[int]
    READ_SET_FIELD_NUMBER: _ClassVar[int]
    SCOPES_FIELD_NUMBER: _ClassVar[int]
    STALE_FIELD_NUMBER: _ClassVar[int]
    name: str
    begin_time: int
    isolation: str
    changes: _containers.RepeatedCompositeFieldContainer[Change]
    conflicts: _containers.RepeatedCompositeFieldContainer[Conflict]
    read_set: _containers.RepeatedScalarFieldContainer[bytes]
    scopes: _containers.RepeatedCompositeFieldContainer[Scope]
    stale: bool
    def __init__(self, name: _Optional[str] = ..., begin_time: _Optional[int] = ..., isolation: _Optional[str] = ..., changes: _Optional[_Iterable[_Union[Change, _Mapping]]] = ..., conflicts: _Optional[_Iterable[_Union[Conflict, _Mapping]]] = ..., read_set: _Optional[_Iterable[bytes]] = ..., scopes: _Optional[_Iterable[_Union[Scope, _Mapping]]] = ..., stale: _Optional[bool] = ...) -> None: ...

class CommitProposal(_message.Message):
    __slots__ = ("commit_id", "time", "author", "author_name", "view", "message", "begin_time", "isolation", "changes", "since", "read_set", "scopes", "participants")
    COMMIT_ID_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    AUTHOR_FIELD_NUMBER: _ClassVar[int]
    AUTHOR_NAME_FIELD_NUMBER: _ClassVar[int]
    VIEW_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    BEGIN_TIME_FIELD_NUMBER: _ClassVar[int]
    ISOLATION_FIELD_NUMBER: _ClassVar[int]
    CHANGES_FIELD_NUMBER: _ClassVar[int]
    SINCE_FIELD_NUMBER: _ClassVar[int]
    READ_SET_FIELD_NUMBER: _ClassVar[int]
    SCOPES_FIELD_NUMBER: _ClassVar[int]
    PARTICIPANTS_FIELD_NUMBER: _ClassVar[int]
    commit_id: bytes
    time: int
    author: bytes
    author_name: str
    view: str
    message: str
    begin_time: int
    isolation: str
    changes: _containers.RepeatedCompositeFieldContainer[Change]
    since: _containers.RepeatedCompositeFieldContainer[ItemSince]
    read_set: _containers.RepeatedScalarFieldContainer[bytes]
    scopes: _containers.RepeatedCompositeFieldContainer[Scope]
    participants: _containers.RepeatedScalarFieldContainer[bytes]
    def __init__(self, commit_id: _Optional[bytes] = ..., time: _Optional[int] = ..., author: _Optional[bytes] = ..., author_name: _Optional[str] = ..., view: _Optional[str] = ..., message: _Optional[str] = ..., begin_time: _Optional[int] = ..., isolation: _Optional[str] = ..., changes: _Optional[_Iterable[_Union[Change, _Mapping]]] = ..., since: _Optional[_Iterable[_Union[ItemSince, _Mapping]]] = ..., read_set: _Optional[_Iterable[bytes]] = ..., scopes: _Optional[_Iterable[_Union[Scope, _Mapping]]] = ..., participants: _Optional[_Iterable[bytes]] = ...) -> None: ...

class TxDecision(_message.Message):
    __slots__ = ("commit_id", "commit", "time")
    COMMIT_ID_FIELD_NUMBER: _ClassVar[int]
    COMMIT_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    commit_id: bytes
    commit: bool
    time: int
    def __init__(self, commit_id: _Optional[bytes] = ..., commit: _Optional[bool] = ..., time: _Optional[int] = ...) -> None: ...

class TimeFloor(_message.Message):
    __slots__ = ("time",)
    TIME_FIELD_NUMBER: _ClassVar[int]
    time: int
    def __init__(self, time: _Optional[int] = ...) -> None: ...

class ChunkLogEntry(_message.Message):
    __slots__ = ("proposal", "decision", "floor")
    PROPOSAL_FIELD_NUMBER: _ClassVar[int]
    DECISION_FIELD_NUMBER: _ClassVar[int]
    FLOOR_FIELD_NUMBER: _ClassVar[int]
    proposal: CommitProposal
    decision: TxDecision
    floor: TimeFloor
    def __init__(self, proposal: _Optional[_Union[CommitProposal, _Mapping]] = ..., decision: _Optional[_Union[TxDecision, _Mapping]] = ..., floor: _Optional[_Union[TimeFloor, _Mapping]] = ...) -> None: ...

class ChunkSnapshot(_message.Message):
    __slots__ = ("table", "type_name", "time", "revisions", "commits", "txs", "replication", "compacted")
    TABLE_FIELD_NUMBER: _ClassVar[int]
    TYPE_NAME_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    REVISIONS_FIELD_NUMBER: _ClassVar[int]
    COMMITS_FIELD_NUMBER: _ClassVar[int]
    TXS_FIELD_NUMBER: _ClassVar[int]
    REPLICATION_FIELD_NUMBER: _ClassVar[int]
    COMPACTED_FIELD_NUMBER: _ClassVar[int]
    table: str
    type_name: str
    time: int
    revisions: _containers.RepeatedCompositeFieldContainer[Revision]
    commits: _containers.RepeatedCompositeFieldContainer[CommitRecord]
    txs: _containers.RepeatedCompositeFieldContainer[TxState]
    replication: int
    compacted: _containers.RepeatedCompositeFieldContainer[ChainLink]
    def __init__(self, table: _Optional[str] = ..., type_name: _Optional[str] = ..., time: _Optional[int] = ..., revisions: _Optional[_Iterable[_Union[Revision, _Mapping]]] = ..., commits: _Optional[_Iterable[_Union[CommitRecord, _Mapping]]] = ..., txs: _Optional[_Iterable[_Union[TxState, _Mapping]]] = ..., replication: _Optional[int] = ..., compacted: _Optional[_Iterable[_Union[ChainLink, _Mapping]]] = ...) -> None: ...

class ChainLink(_message.Message):
    __slots__ = ("commit_id", "link")
    COMMIT_ID_FIELD_NUMBER: _ClassVar[int]
    LINK_FIELD_NUMBER: _ClassVar[int]
    commit_id: bytes
    link: bytes
    def __init__(self, commit_id: _Optional[bytes] = ..., link: _Optional[bytes] = ...) -> None: ...

class TxState(_message.Message):
    __slots__ = ("commit_id", "state", "time", "data")
    COMMIT_ID_FIELD_NUMBER: _ClassVar[int]
    STATE_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    commit_id: bytes
    state: str
    time: int
    data: bytes
    def __init__(self, commit_id: _Optional[bytes] = ..., state: _Optional[str] = ..., time: _Optional[int] = ..., data: _Optional[bytes] = ...) -> None: ...

class ItemSince(_message.Message):
    __slots__ = ("item_id", "time")
    ITEM_ID_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    item_id: bytes
    time: int
    def __init__(self, item_id: _Optional[bytes] = ..., time: _Optional[int] = ...) -> None: ...
