"""OpenCV's ArUco detector (DICT_APRILTAG_36h11) + corner refinement + solvePnP on the boards
`cell board-study --save DIR` rendered, against their truth, beside our figures (DIR/ours.json).

Each board window is pasted at its sensor origin into a 5472 x 3648 frame of noisy grey table, as
the study does, so both detectors search the same 20 MP. OpenCV runs on 2 threads. The pose is
SQPnP then solvePnPRefineLM over every decoded corner, with the camera's distortion. Errors are in
the board frame at the board's centre (truth relative to the estimate), as the study reports them:
1 sigma over images is the root mean square over images. Usage: opencv.py DIR [--all].
"""

import glob
import json
import os
import sys
import time

import cv2
import numpy as np

TABLE_NOISE = 4
# Which of our corners (the reference detector's order) each ArUco corner is: a convention of the
# dictionary, found once on the first image as the cyclic order (either direction) nearest the
# truth, then used for every tag.
ORDERS = [[(k + r) % 4 for k in range(4)] for r in range(4)] + \
    [[(r - k) % 4 for k in range(4)] for r in range(4)]


def corner_order(corners, ids, tags):
    best, order = float("inf"), None
    for o in ORDERS:
        err = 0.0
        for c, i in zip(corners, ids.reshape(-1)):
            t = tags.get(int(i))
            if t is not None:
                c = c.reshape(4, 2)
                err += sum(float(((c[a] - np.array(t["pixels"][o[a]])) ** 2).sum()) for a in range(4))
        if err < best:
            best, order = err, o
    return order


def full_frame(window, origin, width, height, rng):
    edge = np.concatenate([window[0], window[-1], window[:, 0], window[:, -1]])
    fill = int(np.median(edge))
    full = (fill + rng.integers(-TABLE_NOISE, TABLE_NOISE + 1, size=(height, width))).clip(0, 255)
    full = full.astype(np.uint8)
    x0, y0 = origin
    full[y0:y0 + window.shape[0], x0:x0 + window.shape[1]] = window
    return full


def rotvec(r):
    v, _ = cv2.Rodrigues(r)
    return v.reshape(3)


def board_error(r_est, t_est, r_true, t_true):
    """[dt; dtheta] of the truth relative to the estimate, in the board frame."""
    dt = r_est.T @ (t_true - t_est)
    dr = rotvec(r_est.T @ r_true)
    return np.concatenate([dt, dr])


def detector(method):
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = method
    if method == cv2.aruco.CORNER_REFINE_SUBPIX:
        params.cornerRefinementWinSize = 5
        params.cornerRefinementMaxIterations = 100
        params.cornerRefinementMinAccuracy = 0.001
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    return cv2.aruco.ArucoDetector(dictionary, params)


def run(directory, name, method, skip):
    det = detector(method)
    rng = np.random.default_rng(7)
    visible = decoded = false_ids = 0
    corner_sq, corners_n = 0.0, 0
    errors, detect_ms, pose_ms = [], [], []
    order = None
    for png in sorted(glob.glob(os.path.join(directory, "board_*.png"))):
        truth = json.load(open(png[:-4] + ".json"))
        cam = truth["camera"]
        k = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]])
        dist = np.array(cam["distortion"], dtype=np.float64)
        window = cv2.imread(png, cv2.IMREAD_GRAYSCALE)
        frame = full_frame(window, truth["origin"], cam["width"], cam["height"], rng)
        tags = {t["id"]: t for t in truth["tags"]}
        visible += sum(1 for t in truth["tags"] if t["visible"])
        start = time.perf_counter()
        corners, ids, _ = det.detectMarkers(frame)
        detect_ms.append((time.perf_counter() - start) * 1e3)
        obj, img = [], []
        if order is None and ids is not None:
            order = corner_order(corners, ids, tags)
        for c, i in zip(corners if ids is not None else [], ids.reshape(-1) if ids is not None else []):
            t = tags.get(int(i))
            if t is None:
                false_ids += 1
                continue
            decoded += int(t["visible"])
            c = c.reshape(4, 2)
            for a, o in enumerate(order):
                e = c[a] - np.array(t["pixels"][o])
                corner_sq += float(e @ e)
                corners_n += 1
                obj.append(t["board"][o])
                img.append(c[a])
        if len(obj) < 16 or os.path.basename(png) in skip:
            continue
        obj = np.array(obj, dtype=np.float64)
        img = np.array(img, dtype=np.float64)
        start = time.perf_counter()
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_SQPNP)
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, dist, rvec, tvec)
        pose_ms.append((time.perf_counter() - start) * 1e3)
        m = np.array(truth["camera_T_board"])
        r_est, _ = cv2.Rodrigues(rvec)
        errors.append(board_error(r_est, tvec.reshape(3), m[:3, :3], m[:3, 3]))
    errors = np.array(errors)
    rms = np.sqrt((errors ** 2).mean(axis=0))
    result = {
        "name": name,
        "images": len(detect_ms),
        "decode_rate": decoded / max(visible, 1),
        "decoded": decoded,
        "visible": visible,
        "false_ids": false_ids,
        "corner_rms_px": (corner_sq / max(corners_n, 1)) ** 0.5,
        "rms_error_um": (rms[:3] * 1e6).tolist(),
        "rms_error_urad": (rms[3:] * 1e6).tolist(),
        "detect_ms": float(np.mean(detect_ms)),
        "pose_ms": float(np.mean(pose_ms)) if pose_ms else float("nan"),
        "corner_order": order,
    }
    return result


def show(r, ours):
    print(f"{r['name']}: {r['images']} images (ArUco corner k is our corner {r['corner_order']}[k])")
    print(f"  tags decoded {r['decoded']} of {r['visible']} visible "
          f"({100 * r['decode_rate']:.3f} %), false ids {r['false_ids']}")
    line = f"  corner error (rms) {r['corner_rms_px']:.4f} px"
    if ours:
        line += f"  (ours {ours['corner_rms_refined_px']:.4f} px)"
    print(line)
    names = ["x", "y", "z (height)", "about x", "about y", "about z"]
    theirs = r["rms_error_um"] + r["rms_error_urad"]
    mine = (ours["rms_error_um"] + ours["rms_error_urad"]) if ours else None
    for j, n in enumerate(names):
        unit = "um" if j < 3 else "urad"
        line = f"  {n:<11} {theirs[j]:9.2f} {unit}"
        if mine:
            line += f"   ours {mine[j]:9.2f} {unit}   OpenCV / ours {theirs[j] / mine[j]:.2f}"
        print(line)
    line = f"  time per 20 MP image: detect {r['detect_ms']:.1f} ms, pose {r['pose_ms']:.2f} ms"
    if ours:
        total = ours["total_ms"]["mean"]
        line += (f"   ours {total:.1f} ms in all; OpenCV / ours "
                 f"{(r['detect_ms'] + r['pose_ms']) / total:.2f}")
    print(line)


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    directory = args[0] if args else "target/board_compare"
    cv2.setNumThreads(2)
    ours_path = os.path.join(directory, "ours.json")
    report = json.load(open(ours_path)) if os.path.exists(ours_path) else None
    ours = report["summary"] if report else None
    # Pose errors over the images ours posed (it refuses over-exposed ones), so both are paired.
    skip = {f"board_{r['index']:04d}.png" for r in report["images"] if r["refused"]} if report else set()
    if skip:
        print(f"pose errors over the images ours posed (without {sorted(skip)})")
    print(f"OpenCV {cv2.__version__}, 2 threads")
    # CORNER_REFINE_APRILTAG takes about 9 s per 20 MP image: only with --all.
    methods = [("CORNER_REFINE_SUBPIX", cv2.aruco.CORNER_REFINE_SUBPIX)]
    if "--all" in sys.argv:
        methods.append(("CORNER_REFINE_APRILTAG", cv2.aruco.CORNER_REFINE_APRILTAG))
    results = [run(directory, f"ArUco DICT_APRILTAG_36h11 + {n}", m, skip) for n, m in methods]
    for r in results:
        show(r, ours)
    json.dump(results, open(os.path.join(directory, "opencv.json"), "w"), indent=2)


if __name__ == "__main__":
    main()
