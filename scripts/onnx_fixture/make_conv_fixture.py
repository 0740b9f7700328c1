"""Writes the ONNX test fixture used by perception/tests/onnx.rs: a tiny network shaped like a crop net.

crops [N,3,128,128] -> Conv(3->2, 3x3, stride 2, pad 1, bias) -> Relu -> "features" [N,2,64,64]
                                                              \-> GlobalAveragePool -> "pooled" [N,2,1,1]
Weights follow a closed formula (w[o,c,ky,kx] = 0.5*sin(1 + 27o + 9c + 3ky + kx), bias = [0.1, -0.2]) so
the Rust test recomputes the convolution by hand, independently of this file.
Usage: scripts/onnx_fixture/venv.sh prints a python with `onnx`; run this with it:
  $(scripts/onnx_fixture/venv.sh) scripts/onnx_fixture/make_conv_fixture.py perception/tests/data/onnx
It writes conv_fixture.onnx and prints its sha256 (copy it into conv_fixture.toml).
"""

import hashlib
import math
import pathlib
import sys

import onnx
from onnx import TensorProto, helper

OPSET = 17


def main(out_dir: str) -> None:
    weights = [
        0.5 * math.sin(1 + 27 * o + 9 * c + 3 * ky + kx)
        for o in range(2)
        for c in range(3)
        for ky in range(3)
        for kx in range(3)
    ]
    w = helper.make_tensor("w", TensorProto.FLOAT, [2, 3, 3, 3], weights)
    b = helper.make_tensor("b", TensorProto.FLOAT, [2], [0.1, -0.2])
    nodes = [
        helper.make_node("Conv", ["crops", "w", "b"], ["conv"], kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1]),
        helper.make_node("Relu", ["conv"], ["features"]),
        helper.make_node("GlobalAveragePool", ["features"], ["pooled"]),
    ]
    graph = helper.make_graph(
        nodes,
        "conv_fixture",
        [helper.make_tensor_value_info("crops", TensorProto.FLOAT, ["batch", 3, 128, 128])],
        [
            helper.make_tensor_value_info("features", TensorProto.FLOAT, ["batch", 2, 64, 64]),
            helper.make_tensor_value_info("pooled", TensorProto.FLOAT, ["batch", 2, 1, 1]),
        ],
        initializer=[w, b],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="cell-onnx-fixture")
    model.ir_version = 8
    onnx.checker.check_model(model, full_check=True)
    path = pathlib.Path(out_dir) / "conv_fixture.onnx"
    data = model.SerializeToString()
    tmp = path.with_suffix(".onnx.tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
    print(f"{path} sha256 {hashlib.sha256(data).hexdigest()} ({len(data)} bytes, opset {OPSET})")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
