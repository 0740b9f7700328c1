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

import train_keypoints
import train_segmenter


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    data, out = sys.argv[1], sys.argv[2]
    common = ["--train", data, "--test", data, "--dataset-seed", "0", "--limit", "1"]
    if len(sys.argv) == 4:
        common += ["--catalog", sys.argv[3]]
    # Symmetric parts are scored against the nearer of two twins (a no-op for other parts).
    train_keypoints.main(common + ["--out", out, "--epochs", "2", "--batch", "2", "--twins", "2"])
    seg = common + ["--steps", "2", "--batch", "2", "--size", "64", "--eval-every", "1"]
    train_segmenter.main(seg + ["--out", out])
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
