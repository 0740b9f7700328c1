"""Writes the contract-shaped ONNX test fixtures used by perception/tests/learned_models.rs: not
trained networks, but graphs with the exact inputs and outputs of the learned pipeline's models
(see the MODEL CONTRACT: perception/src/learned/models.rs), so that loading, the contract checks
and a full pipeline run are tested without the trained models.

segmenter.onnx: image [N,3,H,W] -> Conv(3->4, 4x4, stride 4) -> "logits" [N,4,H/4,W/4]
                                \-> Conv(3->2, 4x4, stride 4) -> "offsets" [N,2,H/4,W/4]
  logits: background 0.5 - brightness, main_shell brightness - 0.5 (bright cells are main_shell);
  offsets: zero (every cell votes for its own centre).
keypoints.onnx: crop [N,6,128,128] -> Conv(6->1, 2x2, stride 2) -> "mask" [N,1,64,64]
                                   \-> Conv(6->18, 2x2, stride 2) -> "vectors" [N,18,64,64]
  mask: brightness - 0.5; vectors: fixed per-channel biases.
Usage (any python with `onnx`, e.g. $(scripts/onnx_fixture/venv.sh)):
  python scripts/onnx_fixture/make_learned_fixtures.py perception/tests/data/onnx/learned
It writes both models and their manifests (sha256 filled in).
"""

import hashlib
import math
import pathlib
import sys

import onnx
from onnx import TensorProto, helper

OPSET = 17
PARTS = ["main_shell", "insert_mold", "top_shell"]


def conv(name, inp, out, cin, cout, k, weight, bias):
    w = helper.make_tensor(f"{name}_w", TensorProto.FLOAT, [cout, cin, k, k],
                           [weight(o, c) for o in range(cout) for c in range(cin) for _ in range(k * k)])
    b = helper.make_tensor(f"{name}_b", TensorProto.FLOAT, [cout], [bias(o) for o in range(cout)])
    node = helper.make_node("Conv", [inp, w.name, b.name], [out], kernel_shape=[k, k], strides=[k, k])
    return node, [w, b]


def save(model, out_dir, stem, inputs, outputs):
    model.ir_version = 8
    onnx.checker.check_model(model, full_check=True)
    data = model.SerializeToString()
    (out_dir / f"{stem}.onnx").write_bytes(data)
    sha = hashlib.sha256(data).hexdigest()
    lines = [
        "# Test fixture, not a trained model: written by scripts/onnx_fixture/make_learned_fixtures.py.",
        f'name = "{stem}-fixture"',
        "parts = [" + ", ".join(f'"{p}"' for p in PARTS) + "]",
        f'file = "{stem}.onnx"',
        f'sha256 = "{sha}"',
        f"opset = {OPSET}",
    ]
    for kind, specs in (("inputs", inputs), ("outputs", outputs)):
        for name, shape in specs:
            lines += ["", f"[[{kind}]]", f'name = "{name}"', f"shape = {shape}", 'dtype = "f32"']
    (out_dir / f"{stem}.toml").write_text("\n".join(lines) + "\n")
    print(f"{stem}.onnx sha256 {sha} ({len(data)} bytes)")


def main(out_dir):
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mean = 1.0 / (3 * 16)  # mean over 3 channels and a 4x4 cell
    n1, w1 = conv("logits", "image", "logits", 3, 4, 4,
                  lambda o, c: {0: -mean, 1: mean}.get(o, 0.0), lambda o: {0: 0.5, 1: -0.5}.get(o, -1.0))
    n2, w2 = conv("offsets", "image", "offsets", 3, 2, 4, lambda o, c: 0.0, lambda o: 0.0)
    graph = helper.make_graph(
        [n1, n2], "segmenter_fixture",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])],
        [helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["n", 4, "h4", "w4"]),
         helper.make_tensor_value_info("offsets", TensorProto.FLOAT, ["n", 2, "h4", "w4"])],
        initializer=w1 + w2)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="cell-onnx-fixture")
    save(model, out_dir, "segmenter", [("image", [-1, 3, -1, -1])],
         [("logits", [-1, 4, -1, -1]), ("offsets", [-1, 2, -1, -1])])

    kmean = 1.0 / (3 * 4)
    n1, w1 = conv("mask", "crop", "mask", 6, 1, 2, lambda o, c: kmean if c < 3 else 0.0, lambda o: -0.5)
    n2, w2 = conv("vectors", "crop", "vectors", 6, 18, 2, lambda o, c: 0.0, lambda o: math.sin(1 + o))
    graph = helper.make_graph(
        [n1, n2], "keypoints_fixture",
        [helper.make_tensor_value_info("crop", TensorProto.FLOAT, ["n", 6, 128, 128])],
        [helper.make_tensor_value_info("mask", TensorProto.FLOAT, ["n", 1, 64, 64]),
         helper.make_tensor_value_info("vectors", TensorProto.FLOAT, ["n", 18, 64, 64])],
        initializer=w1 + w2)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="cell-onnx-fixture")
    save(model, out_dir, "keypoints", [("crop", [-1, 6, 128, 128])],
         [("mask", [-1, 1, 64, 64]), ("vectors", [-1, 18, 64, 64])])


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
