from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Box3(_message.Message):
    __slots__ = ("xmin", "ymin", "zmin", "xmax", "ymax", "zmax")
    XMIN_FIELD_NUMBER: _ClassVar[int]
    YMIN_FIELD_NUMBER: _ClassVar[int]
    ZMIN_FIELD_NUMBER: _ClassVar[int]
    XMAX_FIELD_NUMBER: _ClassVar[int]
    YMAX_FIELD_NUMBER: _ClassVar[int]
    ZMAX_FIELD_NUMBER: _ClassVar[int]
    xmin: float
    ymin: float
    zmin: float
    xmax: float
    ymax: float
    zmax: float
    def __init__(self, xmin: _Optional[float] = ..., ymin: _Optional[float] = ..., zmin: _Optional[float] = ..., xmax: _Optional[float] = ..., ymax: _Optional[float] = ..., zmax: _Optional[float] = ...) -> None: ...

class Point3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Pose3(_message.Message):
    __slots__ = ("x", "y", "z", "qx", "qy", "qz", "qw")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    QX_FIELD_NUMBER: _ClassVar[int]
    QY_FIELD_NUMBER: _ClassVar[int]
    QZ_FIELD_NUMBER: _ClassVar[int]
    QW_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    qx: float
    qy: float
    qz: float
    qw: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., qx: _Optional[float] = ..., qy: _Optional[float] = ..., qz: _Optional[float] = ..., qw: _Optional[float] = ...) -> None: ...

class Mission(_message.Message):
    __slots__ = ("name", "robot", "frame", "bbox", "chunks", "tiles")
    class ChunksEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: str
        def __init__(self, key: _Optional[str] = ..., value: _Optional[str] = ...) -> None: ...
    NAME_FIELD_NUMBER: _ClassVar[int]
    ROBOT_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    BBOX_FIELD_NUMBER: _ClassVar[int]
    CHUNKS_FIELD_NUMBER: _ClassVar[int]
    TILES_FIELD_NUMBER: _ClassVar[int]
    name: str
    robot: str
    frame: str
    bbox: Box3
    chunks: _containers.ScalarMap[str, str]
    tiles: _containers.RepeatedCompositeFieldContainer[Tile]
    def __init__(self, name: _Optional[str] = ..., robot: _Optional[str] = ..., frame: _Optional[str] = ..., bbox: _Optional[_Union[Box3, _Mapping]] = ..., chunks: _Optional[_Mapping[str, str]] = ..., tiles: _Optional[_Iterable[_Union[Tile, _Mapping]]] = ...) -> None: ...

class Tile(_message.Message):
    __slots__ = ("bbox", "vertices", "edges", "vertex_count", "edge_count")
    BBOX_FIELD_NUMBER: _ClassVar[int]
    VERTICES_FIELD_NUMBER: _ClassVar[int]
    EDGES_FIELD_NUMBER: _ClassVar[int]
    VERTEX_COUNT_FIELD_NUMBER: _ClassVar[int]
    EDGE_COUNT_FIELD_NUMBER: _ClassVar[int]
    bbox: Box3
    vertices: str
    edges: str
    vertex_count: int
    edge_count: int
    def __init__(self, bbox: _Optional[_Union[Box3, _Mapping]] = ..., vertices: _Optional[str] = ..., edges: _Optional[str] = ..., vertex_count: _Optional[int] = ..., edge_count: _Optional[int] = ...) -> None: ...

class VertexRef(_message.Message):
    __slots__ = ("mission", "index")
    MISSION_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    mission: str
    index: int
    def __init__(self, mission: _Optional[str] = ..., index: _Optional[int] = ...) -> None: ...

class Vertex(_message.Message):
    __slots__ = ("mission", "index", "pose", "timestamp", "origin")
    MISSION_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    POSE_FIELD_NUMBER: _ClassVar[int]
    TIMESTAMP_FIELD_NUMBER: _ClassVar[int]
    ORIGIN_FIELD_NUMBER: _ClassVar[int]
    mission: str
    index: int
    pose: Pose3
    timestamp: float
    origin: Origin
    def __init__(self, mission: _Optional[str] = ..., index: _Optional[int] = ..., pose: _Optional[_Union[Pose3, _Mapping]] = ..., timestamp: _Optional[float] = ..., origin: _Optional[_Union[Origin, _Mapping]] = ...) -> None: ...

class Origin(_message.Message):
    __slots__ = ("line", "text", "digits")
    LINE_FIELD_NUMBER: _ClassVar[int]
    TEXT_FIELD_NUMBER: _ClassVar[int]
    DIGITS_FIELD_NUMBER: _ClassVar[int]
    line: int
    text: str
    digits: bytes
    def __init__(self, line: _Optional[int] = ..., text: _Optional[str] = ..., digits: _Optional[bytes] = ...) -> None: ...

class Edge(_message.Message):
    __slots__ = ("mission", "from_vertex", "to_vertex", "relative", "information", "kind", "origin", "information_at")
    class Kind(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        KIND_UNSPECIFIED: _ClassVar[Edge.Kind]
        ODOMETRY: _ClassVar[Edge.Kind]
        LOOP: _ClassVar[Edge.Kind]
        INTER_ROBOT: _ClassVar[Edge.Kind]
        LANDMARK: _ClassVar[Edge.Kind]
    KIND_UNSPECIFIED: Edge.Kind
    ODOMETRY: Edge.Kind
    LOOP: Edge.Kind
    INTER_ROBOT: Edge.Kind
    LANDMARK: Edge.Kind
    MISSION_FIELD_NUMBER: _ClassVar[int]
    FROM_VERTEX_FIELD_NUMBER: _ClassVar[int]
    TO_VERTEX_FIELD_NUMBER: _ClassVar[int]
    RELATIVE_FIELD_NUMBER: _ClassVar[int]
    INFORMATION_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    ORIGIN_FIELD_NUMBER: _ClassVar[int]
    INFORMATION_AT_FIELD_NUMBER: _ClassVar[int]
    mission: str
    from_vertex: VertexRef
    to_vertex: VertexRef
    relative: Pose3
    information: _containers.RepeatedScalarFieldContainer[float]
    kind: Edge.Kind
    origin: Origin
    information_at: _containers.RepeatedScalarFieldContainer[int]
    def __init__(self, mission: _Optional[str] = ..., from_vertex: _Optional[_Union[VertexRef, _Mapping]] = ..., to_vertex: _Optional[_Union[VertexRef, _Mapping]] = ..., relative: _Optional[_Union[Pose3, _Mapping]] = ..., information: _Optional[_Iterable[float]] = ..., kind: _Optional[_Union[Edge.Kind, str]] = ..., origin: _Optional[_Union[Origin, _Mapping]] = ..., information_at: _Optional[_Iterable[int]] = ...) -> None: ...

class Landmark(_message.Message):
    __slots__ = ("mission", "index", "position", "covariance", "origin")
    MISSION_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    POSITION_FIELD_NUMBER: _ClassVar[int]
    COVARIANCE_FIELD_NUMBER: _ClassVar[int]
    ORIGIN_FIELD_NUMBER: _ClassVar[int]
    mission: str
    index: int
    position: Point3
    covariance: _containers.RepeatedScalarFieldContainer[float]
    origin: Origin
    def __init__(self, mission: _Optional[str] = ..., index: _Optional[int] = ..., position: _Optional[_Union[Point3, _Mapping]] = ..., covariance: _Optional[_Iterable[float]] = ..., origin: _Optional[_Union[Origin, _Mapping]] = ...) -> None: ...

class PointCloudBlock(_message.Message):
    __slots__ = ("mission", "points", "count", "bbox", "compressed", "vertex")
    MISSION_FIELD_NUMBER: _ClassVar[int]
    POINTS_FIELD_NUMBER: _ClassVar[int]
    COUNT_FIELD_NUMBER: _ClassVar[int]
    BBOX_FIELD_NUMBER: _ClassVar[int]
    COMPRESSED_FIELD_NUMBER: _ClassVar[int]
    VERTEX_FIELD_NUMBER: _ClassVar[int]
    mission: str
    points: bytes
    count: int
    bbox: Box3
    compressed: bool
    vertex: int
    def __init__(self, mission: _Optional[str] = ..., points: _Optional[bytes] = ..., count: _Optional[int] = ..., bbox: _Optional[_Union[Box3, _Mapping]] = ..., compressed: _Optional[bool] = ..., vertex: _Optional[int] = ...) -> None: ...

class Frame(_message.Message):
    __slots__ = ("mission", "frame", "transform", "covariance", "anchor", "linked", "edges", "duplicate_of", "content", "bbox", "mission_chunk")
    MISSION_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TRANSFORM_FIELD_NUMBER: _ClassVar[int]
    COVARIANCE_FIELD_NUMBER: _ClassVar[int]
    ANCHOR_FIELD_NUMBER: _ClassVar[int]
    LINKED_FIELD_NUMBER: _ClassVar[int]
    EDGES_FIELD_NUMBER: _ClassVar[int]
    DUPLICATE_OF_FIELD_NUMBER: _ClassVar[int]
    CONTENT_FIELD_NUMBER: _ClassVar[int]
    BBOX_FIELD_NUMBER: _ClassVar[int]
    MISSION_CHUNK_FIELD_NUMBER: _ClassVar[int]
    mission: str
    frame: str
    transform: Pose3
    covariance: _containers.RepeatedScalarFieldContainer[float]
    anchor: str
    linked: _containers.RepeatedScalarFieldContainer[str]
    edges: int
    duplicate_of: str
    content: str
    bbox: Box3
    mission_chunk: str
    def __init__(self, mission: _Optional[str] = ..., frame: _Optional[str] = ..., transform: _Optional[_Union[Pose3, _Mapping]] = ..., covariance: _Optional[_Iterable[float]] = ..., anchor: _Optional[str] = ..., linked: _Optional[_Iterable[str]] = ..., edges: _Optional[int] = ..., duplicate_of: _Optional[str] = ..., content: _Optional[str] = ..., bbox: _Optional[_Union[Box3, _Mapping]] = ..., mission_chunk: _Optional[str] = ...) -> None: ...

class GridTile(_message.Message):
    __slots__ = ("mission", "resolution", "x", "y", "width", "height", "cells", "bbox", "stamp", "yaw")
    MISSION_FIELD_NUMBER: _ClassVar[int]
    RESOLUTION_FIELD_NUMBER: _ClassVar[int]
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    HEIGHT_FIELD_NUMBER: _ClassVar[int]
    CELLS_FIELD_NUMBER: _ClassVar[int]
    BBOX_FIELD_NUMBER: _ClassVar[int]
    STAMP_FIELD_NUMBER: _ClassVar[int]
    YAW_FIELD_NUMBER: _ClassVar[int]
    mission: str
    resolution: float
    x: float
    y: float
    width: int
    height: int
    cells: bytes
    bbox: Box3
    stamp: float
    yaw: float
    def __init__(self, mission: _Optional[str] = ..., resolution: _Optional[float] = ..., x: _Optional[float] = ..., y: _Optional[float] = ..., width: _Optional[int] = ..., height: _Optional[int] = ..., cells: _Optional[bytes] = ..., bbox: _Optional[_Union[Box3, _Mapping]] = ..., stamp: _Optional[float] = ..., yaw: _Optional[float] = ...) -> None: ...
