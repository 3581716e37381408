"""estimators/onnx_graph.py reads what the onnx package reads: every shipped model's weights
and nodes, byte for byte."""

import numpy as np
import onnx
import pytest
from onnx import numpy_helper

from sparse_body.core.resources import models_dir
from sparse_body.estimators.onnx_graph import read_graph


@pytest.mark.parametrize("path", sorted(models_dir().glob("*.onnx")), ids=lambda p: p.name)
def test_the_graph_and_weights_are_those_the_onnx_package_reads(path):
    ours, theirs = read_graph(path), onnx.load(str(path))
    assert ours.inputs == tuple(i.name for i in theirs.graph.input)
    assert [(n.op_type, n.inputs, n.outputs) for n in ours.nodes] == [
        (n.op_type, tuple(n.input), tuple(n.output)) for n in theirs.graph.node
    ]
    floats = [t for t in theirs.graph.initializer if t.data_type in (onnx.TensorProto.FLOAT, onnx.TensorProto.DOUBLE)]
    assert sorted(ours.weights) == sorted(t.name for t in floats)
    for t in floats:
        expected = numpy_helper.to_array(t)
        assert ours.weights[t.name].dtype == expected.dtype
        np.testing.assert_array_equal(ours.weights[t.name], expected)
    gemm = next((n for n in ours.nodes if n.op_type == "Gemm"), None)
    if gemm is not None:  # attributes come through as numbers
        expected = next(n for n in theirs.graph.node if n.op_type == "Gemm")
        assert gemm.attributes == {a.name: onnx.helper.get_attribute_value(a) for a in expected.attribute}


def test_a_file_that_is_not_onnx_is_a_value_error(tmp_path):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"\x3a\xff\xff\xff\xff\x0f")  # field 7 (the graph) claiming more bytes than there are
    with pytest.raises(ValueError, match="not an ONNX model"):
        read_graph(bad)
