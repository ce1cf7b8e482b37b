#!/usr/bin/env bash
# Generate the Python protobuf modules from proto/ into $1 (default mapapi/_pb).
# The generated imports name the proto package (`from mapapi.v1 import ...`);
# we rewrite them to the real Python package so cross-file imports resolve.
set -euo pipefail
out=${1:-mapapi/_pb}
py=${PY:-.venv/bin/python}
mkdir -p "$out"
"$py" -m grpc_tools.protoc -Iproto --python_out="$out" --pyi_out="$out" proto/mapapi/v1/*.proto
for f in "$out"/mapapi/v1/*_pb2.py "$out"/mapapi/v1/*_pb2.pyi; do
  sed -i 's/^from mapapi\.v1 import/from mapapi._pb.mapapi.v1 import/' "$f"
done
touch "$out/__init__.py" "$out/mapapi/__init__.py" "$out/mapapi/v1/__init__.py"
