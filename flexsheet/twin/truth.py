"""The twin's hidden truth: one consistent set of "as built" display parameters drawn from a seed around the
nominal values, each by a realistic, documented spread (pure: numpy + OpenCV + Pinocchio).

The nominal values are :func:`flexsheet.calibration.display_calib.nominal_display_calib` — the constants in
:mod:`flexsheet.model.geometry`, :mod:`flexsheet.model.projector`, :mod:`flexsheet.arm.kinematics` and
:mod:`flexsheet.twin.camera`. Every twin node (world, camera twin, controller twins, measurement camera)
builds its physics from one :class:`TwinTruth`; estimators (triangulator, planner, bridges, renderer, FEM, the
calibration procedures) never read it — they read ``display.yaml``.

Spreads (:class:`Spreads`; 1-σ Gaussian unless stated; "assumption" marks a number not taken from a document):

=========================  ======================  =================================================================
quantity                   σ                       why
=========================  ======================  =================================================================
stereo intrinsics,         bootstrap covariance    the uncertainty the real XIMEA calibration leaves: 40 bootstrap
distortion, R, T           (× ``camera_scale``)    resamples of its 17 pairs (``ximea_calib_bootstrap.json``,
                                                   :func:`bootstrap_stereo_calibration`): σ_f ≈ 1.5–2 px, σ_c
                                                   ≈ 1–1.8 px, σ_T ≈ 0.25/0.3/1.3 mm, σ_R ≈ 0.15°; drawn
                                                   jointly (correlations kept: k1/k2/k3 compensate each other)
camera mount               10 mm, 1° per axis      bracket placed by hand near the design pose (assumption)
projector focal length     1 %                     zoom/focus ring set by hand; throw-ratio tolerance (assumption)
projector principal point  5 px per axis           lens-shift tolerance (assumption)
projector distortion k1    0.01                    short-throw lenses: ≲ 0.5 % at the image edge (assumption)
projector mount            10 mm, 0.5° per axis    on a shelf, aimed by hand (assumption)
arm base x, y, z           3 mm                    floor plates placed from the drawing (assumption)
arm base yaw / tilt        0.3° / 0.05°            idem; levelled with a spirit level (0.05° ≈ 1 mm/m)
RV-1A link lengths         0.1 mm per offset       ISO 2768-f (±0.15–0.2 mm over 30–400 mm) ≈ 2σ (assumption)
RV-1A joint zero offsets   0.02°                   encoder origin set with the maker's jig (assumption); the
                                                   datasheet repeatability is ±0.02 mm
clamp marker offset        2 mm per axis           marker glued by hand on the clamp (assumption)
fingertip marker diameter  3 %                     a 4 mm retro-reflective dot cut by hand (assumption)
sheet Young's modulus      15 %                    Shore A 50 ± 5 through Gent's relation (tension.py)
sheet pre-strain           |N(0, 0.5 %)|           slack or pull left by clamping (assumption)
sheet thickness            5 %                     cast urethane sheet, ±0.1 mm on 1 mm ≈ 2σ (assumption)
grip slip                  |N(0, 5 %)| of stretch  rubber sliding in the clamp jaws (assumption)
=========================  ======================  =================================================================

``realism="ideal"`` gives the nominal values exactly (every deviation zero), the twin as it was before.
"""  # noqa: E501 - a table, template or command line kept whole

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field

import cv2
import numpy as np
import pinocchio as pin

from flexsheet.arm.kinematics import URDF_PATH
from flexsheet.calibration.display_calib import (
    BOOTSTRAP_FILE,
    NOMINAL_CLAMP_MARKER,
    STEREO_NAMES,
    nominal_display_calib,
    pose_from_rt,
    stereo_from_vector,
    stereo_vector,
)
from flexsheet.model.geometry import SHEET_THICKNESS
from flexsheet.model.tension import URETHANE_E
from flexsheet.vision.stereo_calibration import detect_board, parse_board

__all__ = ["Spreads", "TwinTruth", "TruthArm", "bootstrap_stereo_calibration", "random_rotation"]

_FLIP_X = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Spreads:
    """1-σ spreads of the truth around nominal (module doc for the reasons). Units: mm, deg, px, relative."""

    camera_scale: float = 1.0
    camera_mount_mm: float = 10.0
    camera_mount_deg: float = 1.0
    projector_focal_rel: float = 0.01
    projector_pp_px: float = 5.0
    projector_k1: float = 0.01
    projector_mount_mm: float = 10.0
    projector_mount_deg: float = 0.5
    base_mm: float = 3.0
    base_yaw_deg: float = 0.3
    base_tilt_deg: float = 0.05
    link_mm: float = 0.1
    joint_zero_deg: float = 0.02
    clamp_marker_mm: float = 2.0
    marker_diameter_rel: float = 0.03
    young_rel: float = 0.15
    prestrain: float = 0.005
    thickness_rel: float = 0.05
    grip_slip: float = 0.05

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first negative or non-finite spread."""
        for k, v in asdict(self).items():
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"spread {k} must be finite and >= 0, got {v!r}")


def random_rotation(rng: np.random.Generator, sigma_rad: float) -> np.ndarray:
    """(3, 3) rotation exp([w]×) with w ~ N(0, σ² I) (rad)."""
    return cv2.Rodrigues(rng.normal(0.0, sigma_rad, 3))[0]


def bootstrap_stereo_calibration(left: list[np.ndarray], right: list[np.ndarray], board, n: int = 40,
                                 seed: int = 1) -> dict:
    """Bootstrap the stereo calibration of image pairs: ``n`` resamples (with replacement) of the pairs, each
    calibrated like :func:`flexsheet.vision.stereo_calibration.calibrate_stereo` (intrinsics per camera, then
    the extrinsics with them fixed). Returns ``{"names": [...24], "deviations": (n, 24) list}`` — each
    resample's :func:`stereo_vector` minus the all-pairs one. ``board``: a
    :class:`flexsheet.vision.stereo_calibration.BoardSpec`. Raises ``ValueError`` when the board is not found
    in at least 6 pairs. Source: Efron & Tibshirani, *An Introduction to the Bootstrap* (1993), ch. 6.
    """
    obj_all = board.object_points()
    data = []
    for a, b in zip(left, right, strict=True):
        da, db = detect_board(a, board), detect_board(b, board)
        if da is None or db is None:
            continue
        common, ia, ib = np.intersect1d(da[0], db[0], return_indices=True)
        data.append((obj_all[common], da[1][ia].reshape(-1, 1, 2), db[1][ib].reshape(-1, 1, 2)))
    if len(data) < 6:
        raise ValueError(f"board found in only {len(data)} pairs, need >= 6 to bootstrap")
    size = left[0].shape[::-1]

    def calib(idx):
        objs = [data[i][0] for i in idx]
        pl = [data[i][1] for i in idx]
        pr = [data[i][2] for i in idx]
        _, K1, D1, _, _ = cv2.calibrateCamera(objs, pl, size, None, None)
        _, K2, D2, _, _ = cv2.calibrateCamera(objs, pr, size, None, None)
        out = cv2.stereoCalibrate(objs, pl, pr, K1, D1, K2, D2, size, flags=cv2.CALIB_FIX_INTRINSIC)
        return stereo_vector({"K1": K1, "D1": D1, "K2": K2, "D2": D2, "R": out[5], "T": out[6]})

    full = calib(range(len(data)))
    rng = np.random.default_rng(seed)
    devs = []
    while len(devs) < n:
        idx = rng.integers(0, len(data), len(data))
        if len(set(idx.tolist())) >= 6:
            devs.append(calib(idx) - full)
    return {"names": list(STEREO_NAMES), "deviations": np.round(np.array(devs), 10).tolist(),
            "n_pairs": len(data)}


def _bootstrap_deviations() -> np.ndarray:
    with open(BOOTSTRAP_FILE) as fh:
        doc = json.load(fh)
    D = np.asarray(doc["deviations"], float)
    if D.ndim != 2 or D.shape[1] != 24:
        raise ValueError(f"{BOOTSTRAP_FILE}: deviations must be (n, 24), got {D.shape}")
    return D


# ------------------------------------------------------------------------------------------------ truth arm
class TruthArm:
    """Forward kinematics of one "as built" RV-1A: the URDF with every joint origin offset by ``link_deltas``
    (6, 3) m, joint zeros offset by ``joint_offsets`` (6,) rad (actual angle = commanded + offset), the base
    at ``T_display_base`` (4, 4). Tool frame as :class:`flexsheet.arm.kinematics.ArmKinematics` (flip about x
    for the right clamp)."""

    def __init__(self, side: str, T_display_base: np.ndarray, link_deltas: np.ndarray,
                 joint_offsets: np.ndarray):
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        self.side = side
        self.T_display_base = np.asarray(T_display_base, float)
        self.link_deltas = np.asarray(link_deltas, float).reshape(6, 3)
        self.joint_offsets = np.asarray(joint_offsets, float).reshape(6)
        self.model = pin.buildModelFromUrdf(str(URDF_PATH))
        for j in range(1, 7):
            M = self.model.jointPlacements[j]
            self.model.jointPlacements[j] = pin.SE3(M.rotation, M.translation + self.link_deltas[j - 1])
        self.data = self.model.createData()
        self.fid = self.model.getFrameId("clamp")
        self.T_link_tool = _FLIP_X if side == "right" else np.eye(4)

    def fk(self, q) -> np.ndarray:
        """True T_display_clamp (4, 4) m for commanded joints ``q`` (6,) rad. Raises ``ValueError`` on bad
        q."""
        q = np.asarray(q, float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ValueError(f"q must be a finite (6,) joint vector, got {q!r}")
        pin.framesForwardKinematics(self.model, self.data, q + self.joint_offsets)
        return self.T_display_base @ self.data.oMf[self.fid].homogeneous @ self.T_link_tool


# ------------------------------------------------------------------------------------------------ the truth
@dataclass
class TwinTruth:
    """One drawn "as built" display (module doc). Arrays in SI units, display frame.

    ``camera_calib``: stereo dict (``image_size``, K1, D1, K2, D2, R, T) of the true cameras;
    ``T_display_camera`` (4, 4) the true left camera pose; ``projector_K`` (3, 3), ``projector_D`` (5,),
    ``T_display_projector`` (4, 4), ``projector_size`` (w, h); ``bases`` side → (4, 4); ``link_deltas`` side →
    (6, 3) m; ``joint_offsets`` side → (6,) rad; ``clamp_marker`` side → (3,) m in the clamp frame;
    ``clamp_marker_diameter`` m; ``marker_diameter`` m (fingertip); ``sheet_young`` Pa; ``sheet_prestrain``;
    ``sheet_thickness`` m; ``grip_slip``: the fraction of the clamps' stretch lost to the rubber sliding in
    the jaws; ``tension_ratio``: None, the sheet's pre-stress is the gripped plane-stress field
    (:mod:`flexsheet.model.sheet_prestress`), or a uniform T_v/T_u (never drawn: a stability sweep's what-if).
    """

    seed: int
    realism: str
    spreads: Spreads
    camera_calib: dict
    T_display_camera: np.ndarray
    projector_K: np.ndarray
    projector_D: np.ndarray
    T_display_projector: np.ndarray
    projector_size: tuple[int, int]
    bases: dict[str, np.ndarray]
    link_deltas: dict[str, np.ndarray]
    joint_offsets: dict[str, np.ndarray]
    clamp_marker: dict[str, np.ndarray]
    clamp_marker_diameter: float = 0.010
    marker_diameter: float = 0.004
    sheet_young: float = 0.0
    sheet_prestrain: float = 0.0
    sheet_thickness: float = 0.001
    grip_slip: float = 0.0
    tension_ratio: float | None = None
    _arms: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def draw(cls, seed: int, realism: str = "realistic", spreads: Spreads | None = None) -> TwinTruth:
        """Draw the truth of ``seed`` (int ≥ 0). ``realism``: ``realistic`` (spreads applied) or ``ideal``
        (nominal exactly). Deterministic in (seed, realism, spreads). Raises ``ValueError`` on a bad realism,
        seed or spread."""
        if realism not in ("realistic", "ideal"):
            raise ValueError(f"realism must be 'realistic' or 'ideal', got {realism!r}")
        if not (isinstance(seed, (int, np.integer)) and seed >= 0):
            raise ValueError(f"seed must be an int >= 0, got {seed!r}")
        sp = spreads or Spreads()
        sp.validate()
        k = 1.0 if realism == "realistic" else 0.0
        nom = nominal_display_calib()
        rng = np.random.default_rng([int(seed), 20250101])
        mm, deg = 1e-3, math.radians(1.0)

        # camera: stereo parameters from the bootstrap covariance, mount around the design pose
        D = _bootstrap_deviations()
        w = rng.normal(size=len(D))
        dev = (w @ (D - D.mean(axis=0))) / math.sqrt(len(D) - 1)
        st = nom.camera.stereo
        cam = stereo_from_vector(stereo_vector(st) + k * sp.camera_scale * dev, st["image_size"])
        T_dc = nom.camera.T_display_camera.copy()
        dR = random_rotation(rng, k * sp.camera_mount_deg * deg)
        dt = rng.normal(0.0, k * sp.camera_mount_mm * mm, 3)
        T_dc = pose_from_rt(dR @ T_dc[:3, :3], T_dc[:3, 3] + dt)

        # projector
        p = nom.projector
        K = p.K.copy()
        f_scale = 1.0 + k * sp.projector_focal_rel * rng.normal()
        K[0, 0] *= f_scale
        K[1, 1] *= f_scale
        K[0, 2] += k * sp.projector_pp_px * rng.normal()
        K[1, 2] += k * sp.projector_pp_px * rng.normal()
        Dp = np.zeros(5)
        Dp[0] = k * sp.projector_k1 * rng.normal()
        dR = random_rotation(rng, k * sp.projector_mount_deg * deg)
        dt = rng.normal(0.0, k * sp.projector_mount_mm * mm, 3)
        T_dp = pose_from_rt(dR @ p.T_display_projector[:3, :3], p.T_display_projector[:3, 3] + dt)

        # arms
        bases, links, zeros, markers = {}, {}, {}, {}
        for side in ("left", "right"):
            Tb = nom.arms[side].T_display_base
            tilt = np.array([rng.normal(0.0, k * sp.base_tilt_deg * deg),
                             rng.normal(0.0, k * sp.base_tilt_deg * deg),
                             rng.normal(0.0, k * sp.base_yaw_deg * deg)])
            bases[side] = pose_from_rt(cv2.Rodrigues(tilt)[0] @ Tb[:3, :3],
                                       Tb[:3, 3] + rng.normal(0.0, k * sp.base_mm * mm, 3))
            links[side] = _link_deltas(rng, k * sp.link_mm * mm)
            zeros[side] = rng.normal(0.0, k * sp.joint_zero_deg * deg, 6)
            markers[side] = np.array(NOMINAL_CLAMP_MARKER) + rng.normal(0.0, k * sp.clamp_marker_mm * mm, 3)

        marker_d = 0.004 * (1.0 + k * sp.marker_diameter_rel * rng.normal())
        young = URETHANE_E * max(0.3, 1.0 + k * sp.young_rel * rng.normal())
        prestrain = abs(k * sp.prestrain * rng.normal())
        thickness = SHEET_THICKNESS * max(0.5, 1.0 + k * sp.thickness_rel * rng.normal())
        slip = min(0.5, abs(k * sp.grip_slip * rng.normal()))
        return cls(int(seed), realism, sp, cam, T_dc, K, Dp, T_dp, (p.width, p.height), bases, links, zeros,
                   markers, 0.010, marker_d, young, prestrain, thickness, slip)

    def arm(self, side: str) -> TruthArm:
        """The true forward kinematics of arm ``side`` (cached)."""
        if side not in self._arms:
            self._arms[side] = TruthArm(side, self.bases[side], self.link_deltas[side],
                                        self.joint_offsets[side])
        return self._arms[side]

    def clamp_pose(self, side: str, q) -> np.ndarray:
        """True T_display_clamp (4, 4) of arm ``side`` at commanded joints ``q`` (6,) rad."""
        return self.arm(side).fk(q)

    def clamp_marker_position(self, side: str, q) -> np.ndarray:
        """True clamp-marker centre (3,) m, display frame, at commanded joints ``q``."""
        T = self.clamp_pose(side, q)
        return T[:3, :3] @ self.clamp_marker[side] + T[:3, 3]

    def projector_pose_error(self, T_display_projector: np.ndarray) -> tuple[float, float]:
        """(translation error m, rotation error rad) of an estimated projector pose against the truth."""
        return _pose_error(T_display_projector, self.T_display_projector)

    def camera_pose_error(self, T_display_camera: np.ndarray) -> tuple[float, float]:
        """(translation error m, rotation error rad) of an estimated left-camera pose against the truth."""
        return _pose_error(T_display_camera, self.T_display_camera)

    def base_error(self, side: str, T_display_base: np.ndarray) -> tuple[float, float]:
        """(translation error m, rotation error rad) of an estimated base pose of ``side`` against the
        truth."""
        return _pose_error(T_display_base, self.bases[side])

    def summary(self) -> dict:
        """JSON-able dict of the truth (for the twin's logs and the honest-twin report; never for
        estimators)."""
        def a(x):
            return np.asarray(x, float).round(9).tolist()
        return {"seed": self.seed, "realism": self.realism, "spreads": asdict(self.spreads),
                "camera": {k: (a(v) if k != "image_size" else list(v)) for k, v in self.camera_calib.items()},
                "T_display_camera": a(self.T_display_camera), "projector_K": a(self.projector_K),
                "projector_D": a(self.projector_D), "T_display_projector": a(self.T_display_projector),
                "bases": {s: a(v) for s, v in self.bases.items()},
                "link_deltas": {s: a(v) for s, v in self.link_deltas.items()},
                "joint_offsets": {s: a(v) for s, v in self.joint_offsets.items()},
                "clamp_marker": {s: a(v) for s, v in self.clamp_marker.items()},
                "marker_diameter": self.marker_diameter, "sheet_young": self.sheet_young,
                "sheet_prestrain": self.sheet_prestrain, "sheet_thickness": self.sheet_thickness,
                "grip_slip": self.grip_slip}


def _link_deltas(rng: np.random.Generator, sigma: float) -> np.ndarray:
    """(6, 3) joint-origin offsets: σ on each non-zero component of the URDF's joint origins (the machined
    lengths), and σ/4 across them (assembly)."""
    model = pin.buildModelFromUrdf(str(URDF_PATH))
    out = np.zeros((6, 3))
    for j in range(1, 7):
        t = np.asarray(model.jointPlacements[j].translation, float)
        scale = np.where(np.abs(t) > 1e-9, 1.0, 0.25)
        out[j - 1] = rng.normal(0.0, 1.0, 3) * sigma * scale
    return out


def _pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    T_est = np.asarray(T_est, float)
    dt = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    c = (float(np.trace(T_est[:3, :3].T @ T_true[:3, :3])) - 1.0) * 0.5
    return dt, math.acos(max(-1.0, min(1.0, c)))


def main(argv: list[str] | None = None) -> int:
    """``python -m flexsheet.twin.truth --bootstrap DIR``: regenerate ``ximea_calib_bootstrap.json`` from the
    real XIMEA pairs in DIR (``left*.jpg``/``right*.jpg``, chessboard 9×6, 24 mm); ``--seed N``: print a
    truth."""
    import argparse
    import glob

    ap = argparse.ArgumentParser(prog="python -m flexsheet.twin.truth",
                                 epilog="example: python -m flexsheet.twin.truth --seed 3")
    ap.add_argument("--bootstrap", metavar="DIR", help="regenerate the bootstrap file from real pairs in DIR")
    ap.add_argument("--n", type=int, default=40, help="bootstrap resamples")
    ap.add_argument("--seed", type=int, help="print the truth of this seed as JSON")
    a = ap.parse_args(argv)
    if a.bootstrap:
        ls = sorted(glob.glob(os.path.join(a.bootstrap, "left*.jpg")))
        rs = sorted(glob.glob(os.path.join(a.bootstrap, "right*.jpg")))
        imgs = [[cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in fs] for fs in (ls, rs)]
        doc = bootstrap_stereo_calibration(imgs[0], imgs[1], parse_board("chessboard:9x6", 0.024), a.n)
        doc["source"] = f"bootstrap of {doc['n_pairs']} XIMEA pairs ({a.bootstrap}), {a.n} resamples"
        with open(BOOTSTRAP_FILE, "w") as fh:
            json.dump(doc, fh)
        print(f"wrote {BOOTSTRAP_FILE}: std {np.round(np.std(doc['deviations'], axis=0), 5).tolist()}")
    if a.seed is not None:
        print(json.dumps(TwinTruth.draw(a.seed).summary(), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
