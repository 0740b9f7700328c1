"""Training smoke test: a couple of optimiser steps of each net on a tiny dataset, export to ONNX,
manifests written. Checks the plumbing, not the accuracy.

Usage: python smoke.py DATASET_ROOT OUT_DIR
DATASET_ROOT needs crops/PART/{train,test} and train_feeder/ + test_feeder/, e.g. from
`cell dataset --out DIR --train-crops 2 --test-crops 1 --train-overviews 0 --test-overviews 0
--train-feeder 1 --test-feeder 1`.
"""

import os
import sys

import train_keypoints
import train_segmenter


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    data, out = sys.argv[1], sys.argv[2]
    train_keypoints.main(
        ["--train", data, "--test", data, "--out", out, "--dataset-seed", "0", "--epochs", "2", "--batch", "2", "--limit", "1"]
    )
    train_segmenter.main(
        ["--train", data, "--test", data, "--out", out, "--dataset-seed", "0", "--steps", "2", "--batch", "2", "--size", "64", "--limit", "1", "--eval-every", "1"]
    )
    for f in ("keypoints.onnx", "keypoints.toml", "keypoints_curve.csv", "segmenter.onnx", "segmenter.toml", "segmenter_curve.csv"):
        if not os.path.isfile(os.path.join(out, f)):
            sys.exit(f"smoke: {f} was not written to {out}")
    print("smoke: ok")


if __name__ == "__main__":
    main()
