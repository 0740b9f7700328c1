"""Training smoke test: a couple of optimiser steps of each net on a tiny dataset, export to ONNX,
manifests written. Checks the plumbing, not the accuracy.

Usage: python smoke.py DATASET_ROOT OUT_DIR [CATALOG]
CATALOG is the part catalog the dataset was made from (default: the USB-C catalog).
DATASET_ROOT needs crops/PART/{train,test} and train_feeder/ + test_feeder/, e.g. from
`cell dataset --out DIR --train-crops 2 --test-crops 1 --train-overviews 0 --test-overviews 0
--train-feeder 2 --test-feeder 1` (two training frames, so that their table scales differ).
"""

import os
import sys
import tomllib

import torch

import catalog
import train_keypoints
import train_segmenter
from common import transfer
from nets import KeypointNet, Segmenter

PRETRAINED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenarios", "models", "usbc")
"""Another family's committed nets, the start `--pretrained` is checked from."""


def check_transfer(n_parts):
    """Both committed USB-C nets go into nets for `n_parts` parts: every weight copied exactly,
    but each new part's planes or rows, which are the mean of the source's parts'."""
    for net, name in ((KeypointNet, "keypoints"), (Segmenter, "segmenter")):
        path = os.path.join(PRETRAINED, f"{name}.pt")
        model = net(n_parts)
        transfer(model, path)
        saved = torch.load(path, map_location="cpu")
        source, n_source = saved["state_dict"], len(saved["parts"])
        for key, got in model.state_dict().items():
            src = source[key]
            if key in net.PART_SLOTS:
                axis, first = net.PART_SLOTS[key]
                mean = src.narrow(axis, first, n_source).mean(axis, keepdim=True)
                tail = src.shape[axis] - first - n_source
                ok = (torch.equal(got.narrow(axis, 0, first), src.narrow(axis, 0, first))
                      and torch.equal(got.narrow(axis, first + n_parts, tail), src.narrow(axis, first + n_source, tail))
                      and all(torch.allclose(got.narrow(axis, first + i, 1), mean) for i in range(n_parts)))
            else:
                ok = torch.equal(got, src)
            if not ok:
                sys.exit(f"smoke: --pretrained did not carry {name}'s {key} over")


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    data, out = sys.argv[1], sys.argv[2]
    common = ["--train", data, "--test", data, "--dataset-seed", "0", "--limit", "1"]
    if len(sys.argv) == 4:
        common += ["--catalog", sys.argv[3]]
    # Symmetric parts are scored against the nearer of two twins (a no-op for other parts).
    train_keypoints.main(common + ["--out", out, "--epochs", "2", "--batch", "2", "--twins", "2"])
    # Another family's nets as the start, whatever this catalog's parts.
    check_transfer(len(catalog.assembled_parts(sys.argv[3] if len(sys.argv) == 4 else "../scenarios/parts/usbc.toml")))
    train_keypoints.main(common + ["--out", os.path.join(out, "pretrained"), "--epochs", "1", "--batch", "2",
                                   "--pretrained", os.path.join(PRETRAINED, "keypoints.pt")])
    seg = common + ["--steps", "2", "--batch", "2", "--size", "64", "--eval-every", "1"]
    train_segmenter.main(seg + ["--out", out])
    train_segmenter.main(seg + ["--out", os.path.join(out, "pretrained"), "--pretrained",
                                os.path.join(PRETRAINED, "segmenter.pt")])
    # Frames resampled to one scale: the manifest records that scale as both ends of the range
    # (as rendered, two frames from two camera heights give two).
    fixed = os.path.join(out, "fixed_scale")
    train_segmenter.main(seg + ["--out", fixed, "--fixed-scale"])
    with open(os.path.join(fixed, "segmenter.toml"), "rb") as f:
        lo, hi = tomllib.load(f)["training"]["table_px_per_mm"]
    if lo != hi:
        sys.exit(f"smoke: --fixed-scale recorded the scales [{lo}, {hi}], want one")
    # Re-exported without the flag, those weights are still evaluated at the scale they learned.
    again = os.path.join(out, "fixed_scale_again")
    train_segmenter.main(seg + ["--out", again, "--eval-only", os.path.join(fixed, "segmenter.pt")])
    with open(os.path.join(again, "segmenter.toml"), "rb") as f:
        if (got := tomllib.load(f)["training"]["table_px_per_mm"]) != [lo, hi]:
            sys.exit(f"smoke: --eval-only of weights trained at {lo} px/mm recorded {got}")
    for f in ("keypoints.onnx", "keypoints.toml", "keypoints_curve.csv", "segmenter.onnx", "segmenter.toml", "segmenter_curve.csv"):
        if not os.path.isfile(os.path.join(out, f)):
            sys.exit(f"smoke: {f} was not written to {out}")
    print("smoke: ok")


if __name__ == "__main__":
    main()
