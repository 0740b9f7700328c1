"""OpenCV's ArUco detector (DICT_APRILTAG_36h11) + corner refinement + solvePnP on the boards
`cell board-study --save DIR` rendered, against their truth, beside our figures (DIR/ours.json).

Each board window is pasted at its sensor origin into a 5472 x 3648 frame of noisy grey table, as
the study does, so both detectors search the same 20 MP. OpenCV runs on 2 threads. The pose is
SQPnP then solvePnPRefineLM over every decoded corner, with the camera's distortion. Errors are in
the board frame at the board's centre (truth relative to the estimate), as the study reports them:
1 sigma over images is the root mean square over images.
"""

import glob
import json
import os
import sys
import time

import cv2
import numpy as np

# ArUco reports a marker's corners top-left, top-right, bottom-right, bottom-left; the reference
# AprilTag detector (and the board file) bottom-left, bottom-right, top-right, top-left.
ARUCO_TO_OURS = [3, 2, 1, 0]
TABLE_NOISE = 4


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


def run(directory, name, method):
    det = detector(method)
    rng = np.random.default_rng(7)
    visible = decoded = false_ids = 0
    corner_sq, corners_n = 0.0, 0
    errors, detect_ms, pose_ms = [], [], []
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
        for c, i in zip(corners if ids is not None else [], ids.reshape(-1) if ids is not None else []):
            t = tags.get(int(i))
            if t is None:
                false_ids += 1
                continue
            decoded += int(t["visible"])
            c = c.reshape(4, 2)
            for a, o in enumerate(ARUCO_TO_OURS):
                e = c[a] - np.array(t["pixels"][o])
                corner_sq += float(e @ e)
                corners_n += 1
                obj.append(t["board"][o])
                img.append(c[a])
        if len(obj) < 16:
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
    }
    return result


def show(r, ours):
    print(f"{r['name']}: {r['images']} images")
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
    directory = sys.argv[1] if len(sys.argv) > 1 else "target/board_compare"
    cv2.setNumThreads(2)
    ours_path = os.path.join(directory, "ours.json")
    ours = json.load(open(ours_path))["summary"] if os.path.exists(ours_path) else None
    print(f"OpenCV {cv2.__version__}, 2 threads")
    results = [
        run(directory, "ArUco DICT_APRILTAG_36h11 + CORNER_REFINE_SUBPIX", cv2.aruco.CORNER_REFINE_SUBPIX),
        run(directory, "ArUco DICT_APRILTAG_36h11 + CORNER_REFINE_APRILTAG", cv2.aruco.CORNER_REFINE_APRILTAG),
    ]
    for r in results:
        show(r, ours)
    json.dump(results, open(os.path.join(directory, "opencv.json"), "w"), indent=2)


if __name__ == "__main__":
    main()
