"""An ONNX file's graph as data: its inputs, nodes (op, inputs, outputs, attributes) and weights.

Read with protobuf, which ONNX Runtime itself depends on, and the handful of onnx.proto's
fields this uses (numbers from onnx.proto; unknown fields are skipped). The onnx package does
the same and more, but costs the runtime 0.7 s of import and 31 MB for reading a few
tensors (DragPoser's compiled search reads its decoder's weights here). Parity with
onnx.numpy_helper: test_onnx_graph.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

F = {"message": 11, "string": 9, "float": 2, "int64": 3, "int32": 5, "bytes": 12, "double": 1}
# message -> (field, number, type, repeated); the message type is named where type is "message"
SCHEMA = {
    "Model": [("graph", 7, "Graph", False)],
    "Graph": [("node", 1, "Node", True), ("initializer", 5, "Tensor", True), ("input", 11, "ValueInfo", True)],
    "Node": [
        ("input", 1, "string", True),
        ("output", 2, "string", True),
        ("op_type", 4, "string", False),
        ("attribute", 5, "Attribute", True),
    ],
    "Attribute": [("name", 1, "string", False), ("f", 2, "float", False), ("i", 3, "int64", False)],
    "Tensor": [
        ("dims", 1, "int64", True),
        ("data_type", 2, "int32", False),
        ("float_data", 4, "float", True),
        ("name", 8, "string", False),
        ("raw_data", 9, "bytes", False),
        ("double_data", 10, "double", True),
    ],
    "ValueInfo": [("name", 1, "string", False)],
}
DTYPES = {1: np.float32, 11: np.float64}  # TensorProto.FLOAT, DOUBLE: what our models hold


@cache
def _model_class():
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    file = descriptor_pb2.FileDescriptorProto(name="sparse_body_onnx_subset.proto", package="sparse_body_onnx")
    for message, fields in SCHEMA.items():
        proto = file.message_type.add(name=message)
        for name, number, kind, repeated in fields:
            field = proto.field.add(name=name, number=number)
            field.label = field.LABEL_REPEATED if repeated else field.LABEL_OPTIONAL
            if kind in F:
                field.type = F[kind]
            else:
                field.type, field.type_name = F["message"], f".sparse_body_onnx.{kind}"
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("sparse_body_onnx.Model"))


@dataclass(frozen=True)
class Node:
    op_type: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    attributes: dict[str, float | int]  # the float and int attributes (whichever is set)


@dataclass(frozen=True)
class Graph:
    inputs: tuple[str, ...]
    nodes: tuple[Node, ...]
    weights: dict[str, np.ndarray]  # the initializers of a supported type (float32, float64)


def read_graph(path: str | Path) -> Graph:
    """The graph of an ONNX file; ValueError where it is not one."""
    from google.protobuf.message import DecodeError

    model = _model_class()()
    try:
        model.ParseFromString(Path(path).read_bytes())
    except DecodeError as e:
        raise ValueError(f"{path}: not an ONNX model ({e})") from None
    graph = model.graph
    weights = {}
    for t in graph.initializer:
        if t.data_type not in DTYPES:
            continue
        dtype = DTYPES[t.data_type]
        if t.raw_data:
            flat = np.frombuffer(t.raw_data, dtype=np.dtype(dtype).newbyteorder("<"))
        else:
            flat = np.asarray(t.float_data if t.data_type == 1 else t.double_data, dtype)
        if flat.size != int(np.prod(t.dims, dtype=np.int64)):
            raise ValueError(f"{path}: weight {t.name!r} holds {flat.size} numbers for the shape {tuple(t.dims)}")
        weights[t.name] = flat.astype(dtype).reshape(tuple(t.dims))
    nodes = tuple(
        Node(
            n.op_type,
            tuple(n.input),
            tuple(n.output),
            {a.name: (a.f if a.HasField("f") else a.i) for a in n.attribute},
        )
        for n in graph.node
    )
    return Graph(tuple(i.name for i in graph.input), nodes, weights)
