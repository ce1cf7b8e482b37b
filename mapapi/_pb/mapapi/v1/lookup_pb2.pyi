from google.protobuf import struct_pb2 as _struct_pb2
from mapapi._pb.mapapi.v1 import maps_pb2 as _maps_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class SpatialEntry(_message.Message):
    __slots__ = ("chunk", "table", "bbox", "missions", "holder", "address")
    CHUNK_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    BBOX_FIELD_NUMBER: _ClassVar[int]
    MISSIONS_FIELD_NUMBER: _ClassVar[int]
    HOLDER_FIELD_NUMBER: _ClassVar[int]
    ADDRESS_FIELD_NUMBER: _ClassVar[int]
    chunk: bytes
    table: str
    bbox: _maps_pb2.Box3
    missions: _containers.RepeatedScalarFieldContainer[str]
    holder: bytes
    address: str
    def __init__(self, chunk: _Optional[bytes] = ..., table: _Optional[str] = ..., bbox: _Optional[_Union[_maps_pb2.Box3, _Mapping]] = ..., missions: _Optional[_Iterable[str]] = ..., holder: _Optional[bytes] = ..., address: _Optional[str] = ...) -> None: ...

class SpatialFilter(_message.Message):
    __slots__ = ("bbox", "table")
    BBOX_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    bbox: _maps_pb2.Box3
    table: str
    def __init__(self, bbox: _Optional[_Union[_maps_pb2.Box3, _Mapping]] = ..., table: _Optional[str] = ...) -> None: ...

class Subscription(_message.Message):
    __slots__ = ("id", "subscriber", "address", "region", "table", "where")
    ID_FIELD_NUMBER: _ClassVar[int]
    SUBSCRIBER_FIELD_NUMBER: _ClassVar[int]
    ADDRESS_FIELD_NUMBER: _ClassVar[int]
    REGION_FIELD_NUMBER: _ClassVar[int]
    TABLE_FIELD_NUMBER: _ClassVar[int]
    WHERE_FIELD_NUMBER: _ClassVar[int]
    id: bytes
    subscriber: bytes
    address: str
    region: _maps_pb2.Box3
    table: str
    where: _containers.RepeatedCompositeFieldContainer[FieldFilter]
    def __init__(self, id: _Optional[bytes] = ..., subscriber: _Optional[bytes] = ..., address: _Optional[str] = ..., region: _Optional[_Union[_maps_pb2.Box3, _Mapping]] = ..., table: _Optional[str] = ..., where: _Optional[_Iterable[_Union[FieldFilter, _Mapping]]] = ...) -> None: ...

class FieldFilter(_message.Message):
    __slots__ = ("field", "equals")
    FIELD_FIELD_NUMBER: _ClassVar[int]
    EQUALS_FIELD_NUMBER: _ClassVar[int]
    field: str
    equals: _struct_pb2.Value
    def __init__(self, field: _Optional[str] = ..., equals: _Optional[_Union[_struct_pb2.Value, _Mapping]] = ...) -> None: ...
