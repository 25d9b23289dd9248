"""The camera sensor's noise measured on real chessboard images (the XIMEA pairs of
``../shared/data/stereo_calib_xi``): each view is re-rendered ideal from its fitted board pose, and the
residual gives the read noise (DN), the shot-noise gain, the blur (PSF σ, px) and the black and white levels
that :data:`flexsheet.twin.registration_camera.XIMEA_NOISE` holds."""

from __future__ import annotations

import glob
import math
import os
from dataclasses import asdict

import cv2
import numpy as np

from flexsheet.twin.registration_camera import NoiseModel, TrueCamera, board_texture
from flexsheet.vision.stereo_calibration import parse_board

__all__ = ["measure_ximea_noise"]


# ----------------------------------------------------------------------------------------------- measurement
def _board_images(directory: str, side: str, crit) -> tuple[list, list, list]:
    """(images, refined corners, file names) of the ``side`` camera's images in ``directory`` that show the
    9×6 chessboard."""
    imgs, corners, names = [], [], []
    for f in sorted(glob.glob(os.path.join(directory, f"{side}*.jpg"))):
        im = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(im, (9, 6),
                                          flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            continue
        imgs.append(im)
        corners.append(cv2.cornerSubPix(im, c, (11, 11), (-1, -1), crit))
        names.append(os.path.basename(f))
    return imgs, corners, names


def _ideal_view(board, square, K, D, rv, tv, shape, texture):
    """The ideal board seen by the calibrated camera at pose (``rv``, ``tv``): (ideal image (h, w), mask of
    the inner squares (h, w))."""
    tex, ppm, (x0, y0) = texture
    R = cv2.Rodrigues(rv)[0]
    T_board_cam = np.eye(4)
    T_board_cam[:3, :3] = R.T
    T_board_cam[:3, 3] = (-R.T @ tv).ravel()
    cam = TrueCamera(K, D, shape, T_board_cam)
    plane = np.eye(4)[:, [2, 0, 1, 3]]        # normal = board z, in-plane axes = board x, y
    bx, by, ok, _ = cam.plane_hit(plane, 3)
    mx = ((bx - x0) * ppm - 0.5).astype(np.float32)
    my = ((by - y0) * ppm - 0.5).astype(np.float32)
    val = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    w, h = shape
    ideal = val.reshape(h, 3, w, 3).mean(axis=(1, 3))
    bxc = bx.reshape(h, 3, w, 3).mean(axis=(1, 3))
    byc = by.reshape(h, 3, w, 3).mean(axis=(1, 3))
    inner = (bxc > 0.05 * square) & (bxc < 7.95 * square) & (byc > 0.05 * square) & (byc < 4.95 * square)
    return ideal, inner


def _fit_blur(im, ideal, inner, blur_grid):
    """The blur σ (px) on ``blur_grid`` whose blurred ideal board, times an affine gain plus an affine offset,
    best fits the image on ``inner``: (σ, coefficients, residual, blurred ideal, design matrix)."""
    h, w = im.shape
    ys, xs = np.nonzero(inner)
    obs = im[inner].astype(float)
    xn, yn = (xs - w / 2) / w, (ys - h / 2) / h
    best = None
    for sg in blur_grid:
        B = cv2.GaussianBlur(ideal.astype(np.float32), (0, 0), float(sg))[inner]
        A = np.column_stack([np.ones_like(B), xn, yn, B, B * xn, B * yn])
        coef, *_ = np.linalg.lstsq(A, obs, rcond=None)
        res = obs - A @ coef
        rss = float(res @ res)
        if best is None or rss < best[0]:
            best = (rss, float(sg), coef, res, B, A)
    return best[1:]


def _image_noise(im, ideal, inner, blur_grid) -> dict:
    """Blur, black and white levels and pixel noise of one image against its ideal board."""
    h, w = im.shape
    sg, coef, res, B, A = _fit_blur(im, ideal, inner, blur_grid)
    edge = cv2.dilate(((cv2.Laplacian(ideal.astype(np.float32), cv2.CV_32F) != 0) * 255).astype(np.uint8),
                      np.ones((6, 6), np.uint8))[inner] > 0
    flat_b = (~edge) & (B < 0.1)
    flat_w = (~edge) & (B > 0.9)
    pred = A @ coef
    lb, lw = float(np.mean(pred[flat_b])), float(np.mean(pred[flat_w]))
    # pixel noise: differences of horizontally/vertically adjacent flat pixels (removes the smooth
    # shading and print non-uniformity the affine model leaves); robust σ = 1.4826·MAD/√2
    sig = {}
    for cls, fl in (("black", flat_b), ("white", flat_w)):
        r_img = np.full((h, w), np.nan)
        r_img[inner] = np.where(fl, res, np.nan)
        d = np.concatenate([(r_img[:, 1:] - r_img[:, :-1]).ravel(), (r_img[1:] - r_img[:-1]).ravel()])
        d = d[np.isfinite(d)]
        sig[cls] = float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))
        sig[cls + "_total"] = float(np.std(res[fl]))
    return {"blur_px": sg, "black_dn": lb, "white_dn": lw,
            "sigma_black_dn": sig["black"], "sigma_white_dn": sig["white"],
            "sigma_black_total_dn": sig["black_total"], "sigma_white_total_dn": sig["white_total"]}


def measure_ximea_noise(directory: str, square: float = 0.024, blur_grid=None) -> dict:
    """Measure the real XIMEA images' noise and blur: for each image of the 9×6 chessboard pairs in
    ``directory``, render the ideal board through that image's calibrated pose (``cv2.calibrateCamera`` on all
    images of the camera), fit ``I = a(x, y) + c(x, y)·blur_σ(board)`` (a, c affine in the image, σ on a
    grid) over the inner squares, and measure the residual's σ in flat areas (≥ 2.5 px from an edge) on
    the black and on the white squares. σ² = read² + gain·I over (black, white) gives read noise and gain.

    Returns a dict with per-image numbers and medians: ``read_dn``, ``shot_gain``, ``blur_px``,
    ``black_dn``, ``white_dn``, ``corner_rms_px`` (per-view reprojection RMS of the calibration: corner jitter
    plus model error). Raises ``ValueError`` if no image shows the board.
    """
    board = parse_board("chessboard:9x6", square)
    blur_grid = np.arange(0.3, 1.55, 0.06) if blur_grid is None else np.asarray(blur_grid)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
    per_image = []
    for side in ("left", "right"):
        imgs, corners, names = _board_images(directory, side, crit)
        if not imgs:
            continue
        obj = [board.object_points()] * len(imgs)
        out = cv2.calibrateCameraExtended(obj, corners, imgs[0].shape[::-1], None, None)
        K, D, rvecs, tvecs, per_view = out[1], out[2], out[3], out[4], out[7]
        texture = board_texture(board, px_per_m=6000.0)
        for im, rv, tv, name, rms in zip(imgs, rvecs, tvecs, names, per_view.ravel(), strict=True):
            ideal, inner = _ideal_view(board, square, K, D, rv, tv, im.shape[::-1], texture)
            per_image.append({"image": f"{side}/{name}", **_image_noise(im, ideal, inner, blur_grid),
                              "corner_rms_px": float(rms)})
    if not per_image:
        raise ValueError(f"no chessboard image found in {directory!r}")
    med = {k: float(np.median([p[k] for p in per_image])) for k in per_image[0] if k != "image"}
    # σ² = read² + gain·I through the two levels
    gain = max(0.0,
               (med["sigma_white_dn"] ** 2 - med["sigma_black_dn"] ** 2)
               / max(med["white_dn"] - med["black_dn"], 1e-6))
    read = math.sqrt(max(0.0, med["sigma_black_dn"] ** 2 - gain * med["black_dn"]))
    model = NoiseModel(read_dn=round(read, 3), shot_gain=round(gain, 5), blur_px=round(med["blur_px"], 3),
                       black_dn=round(med["black_dn"], 1), white_dn=round(med["white_dn"], 1),
                       corner_rms_px=round(med["corner_rms_px"], 3))
    return {"source": directory, "method": measure_ximea_noise.__doc__.split("\n\n")[0].strip(),
            "model": asdict(model), "median": med, "per_image": per_image}
