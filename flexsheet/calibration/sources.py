"""Where the procedures get their frames in the lab: captured images (:class:`ImageDirSource`; the twin's
source is :class:`flexsheet.twin.registration.TwinSource`). Both hand the same estimators the same things —
stereo pairs and the commanded inputs (sheet poses, projector patterns, joint vectors) — so the lab and the
twin run one code path.

Captured-images layout (``--images DIR``; :func:`save_frames` writes it, e.g. from the twin)::

    DIR/camera_pose/view00_left.png, view00_right.png, view01_...   # view00 = home pose
    DIR/projector/pose00/img00_left.png ... img41_right.png         # the patterns of gray_code_patterns(),
                                                                   # in order (42 for 1024x768), per pose
    DIR/arms/left/config00_left.png ..., DIR/arms/right/...
    DIR/head/fixture00.png ... fixture29.png, chin_rest00.png ...  # optional: the head camera (mono), the
                                                                   # fixture's steps in order, one per sitting
    DIR/manifest.json   {"arms": {"left": {"joints": [[q1..q6], ...]}, "right": {...}},   # commanded, rad
                         "projector": {"width": 1024, "height": 768},
                         "head": {"ipd": 0.0635}}                  # the pupillometer's reading, m

Images are 8-bit grayscale (PNG or any format ``cv2.imread`` reads), raw (not rectified), each ideally the
mean of several frames (the procedures' precision assumes averaging; see docs/calibration.md).
"""

from __future__ import annotations

import glob
import json
import os

import cv2
import numpy as np

from flexsheet.calibration.sheet import Press

__all__ = ["ImageDirSource", "PressFileSource", "save_frames"]

Pair = tuple[np.ndarray, np.ndarray]


def _read(path: str) -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError(f"cannot read image {path!r}")
    return img


def _pairs(pattern: str) -> list[Pair]:
    lefts = sorted(glob.glob(pattern.replace("{side}", "left")))
    out = []
    for lf in lefts:
        rf = lf[::-1].replace("tfel", "thgir", 1)[::-1]        # last "left" -> "right"
        if not os.path.isfile(rf):
            raise ValueError(f"{lf} has no right image {rf}")
        out.append((_read(lf), _read(rf)))
    return out


class ImageDirSource:
    """Frames captured in the lab, in the layout of the module doc. The commanded poses are not needed for the
    board and pattern scenes (the estimators do not use them); the arms' commanded joints come from
    ``manifest.json``. Raises ``ValueError`` naming the missing file or folder."""

    kind = "images"

    def __init__(self, root: str):
        if not os.path.isdir(root):
            raise ValueError(f"images folder not found: {root!r}")
        self.root = root
        man = os.path.join(root, "manifest.json")
        self.manifest = {}
        if os.path.isfile(man):
            try:
                with open(man) as fh:
                    self.manifest = json.load(fh)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{man}: not JSON ({exc})") from None

    @property
    def label(self) -> str:
        return f"lab images {self.root}"

    @property
    def has_head_camera(self) -> bool:
        """Whether the folder holds the head camera's registration images (``head/``)."""
        return os.path.isdir(os.path.join(self.root, "head"))

    def head_fixture_images(self, poses) -> list[np.ndarray]:
        """The head camera's images of the chin-rest fixture's steps (``head/fixtureNN.*``, one per pose)."""
        files = sorted(glob.glob(os.path.join(self.root, "head", "fixture*.*")))
        if len(files) != len(poses):
            raise ValueError(f"{self.root}/head: {len(files)} fixture images, expected {len(poses)} (one per "
                             "step)")
        return [_read(f) for f in files]

    def head_chin_rest_images(self) -> list[np.ndarray]:
        """The head camera's images of the viewer on the chin rest, one per sitting
        (``head/chin_restNN.*``)."""
        files = sorted(glob.glob(os.path.join(self.root, "head", "chin_rest*.*")))
        if not files:
            raise ValueError(f"no {self.root}/head/chin_rest00.png (the viewer on the chin rest, glasses on)")
        return [_read(f) for f in files]

    def pupillometer_ipd(self) -> float:
        """The viewer's IPD, m, from ``manifest.json`` ``head.ipd``."""
        try:
            ipd = float(self.manifest["head"]["ipd"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{self.root}/manifest.json lacks head.ipd (the pupillometer's reading, "
                             "m)") from None
        if not 0.0 < ipd <= 0.1:
            raise ValueError(f"{self.root}/manifest.json: head.ipd must be in (0, 0.1] m, got {ipd!r}")
        return ipd

    def board_views(self, board, sheet_poses=None, offset: float = 0.0) -> list[Pair]:
        views = _pairs(os.path.join(self.root, "camera_pose", "view*_{side}.*"))
        if not views:
            raise ValueError(f"no board views in {os.path.join(self.root, 'camera_pose')} (view00_left.png, "
                             "...)")
        return views

    def n_projector_poses(self) -> int:
        return len(glob.glob(os.path.join(self.root, "projector", "pose*")))

    def pattern_frames(self, patterns, sheet_pose, index: int) -> list[Pair]:
        d = os.path.join(self.root, "projector", f"pose{index:02d}")
        frames = _pairs(os.path.join(d, "img*_{side}.*"))
        if len(frames) != len(patterns):
            raise ValueError(f"{d}: {len(frames)} image pairs, expected {len(patterns)} (one per pattern, in "
                             "order)")
        return frames

    def marker_frames(self, side: str, joints=None) -> tuple[list[Pair], list[np.ndarray]]:
        d = os.path.join(self.root, "arms", side)
        frames = _pairs(os.path.join(d, "config*_{side}.*"))
        try:
            q = [np.asarray(v, float) for v in self.manifest["arms"][side]["joints"]]
        except (KeyError, TypeError):
            raise ValueError(f"{self.root}/manifest.json lacks arms.{side}.joints (commanded joints, "
                             "rad)") from None
        if len(q) != len(frames) or any(v.shape != (6,) for v in q):
            raise ValueError(f"arms.{side}: {len(frames)} image pairs but {len(q)} joint vectors (each 6 "
                             "numbers)")
        return frames, q


def save_frames(root: str, *, board_views: list[Pair] | None = None,
                projector: list[list[Pair]] | None = None,
                arms: dict[str, tuple[list[Pair], list[np.ndarray]]] | None = None,
                projector_size: tuple[int, int] | None = None,
                head: tuple[list[np.ndarray], list[np.ndarray], float] | None = None) -> None:
    """Write frames in the :class:`ImageDirSource` layout (PNG) plus ``manifest.json``; ``head``: (fixture
    images, chin-rest images (one per sitting), IPD m) of the head camera."""
    man: dict = {}
    if head:
        d = os.path.join(root, "head")
        os.makedirs(d, exist_ok=True)
        for k, img in enumerate(head[0]):
            cv2.imwrite(os.path.join(d, f"fixture{k:02d}.png"), img)
        for k, img in enumerate(head[1]):
            cv2.imwrite(os.path.join(d, f"chin_rest{k:02d}.png"), img)
        man["head"] = {"ipd": float(head[2])}
    if board_views:
        d = os.path.join(root, "camera_pose")
        os.makedirs(d, exist_ok=True)
        for k, (a, b) in enumerate(board_views):
            cv2.imwrite(os.path.join(d, f"view{k:02d}_left.png"), a)
            cv2.imwrite(os.path.join(d, f"view{k:02d}_right.png"), b)
    if projector:
        for p, frames in enumerate(projector):
            d = os.path.join(root, "projector", f"pose{p:02d}")
            os.makedirs(d, exist_ok=True)
            for k, (a, b) in enumerate(frames):
                cv2.imwrite(os.path.join(d, f"img{k:02d}_left.png"), a)
                cv2.imwrite(os.path.join(d, f"img{k:02d}_right.png"), b)
        if projector_size:
            man["projector"] = {"width": int(projector_size[0]), "height": int(projector_size[1])}
    if arms:
        man["arms"] = {}
        for side, (frames, q) in arms.items():
            d = os.path.join(root, "arms", side)
            os.makedirs(d, exist_ok=True)
            for k, (a, b) in enumerate(frames):
                cv2.imwrite(os.path.join(d, f"config{k:02d}_left.png"), a)
                cv2.imwrite(os.path.join(d, f"config{k:02d}_right.png"), b)
            man["arms"][side] = {"joints": [np.asarray(v, float).tolist() for v in q]}
    os.makedirs(root, exist_ok=True)
    path = os.path.join(root, "manifest.json")
    if os.path.isfile(path):
        with open(path) as fh:
            old = json.load(fh)
        old.update(man)
        man = old
    with open(path, "w") as fh:
        json.dump(man, fh, indent=1)


class PressFileSource:
    """A lab's probe readings for ``flexsheet calibrate sheet``: a CSV with a header row naming the columns
    ``stretch`` (clamp strain), ``u_m``, ``v_m`` (contact from the sheet centre, m), ``depth_m`` (probe depth
    from the flat sheet, m) and ``force_n`` (the load cell, N), one reading per row. Raises ``ValueError``
    naming the file, the row and the column of a missing or bad value."""

    COLUMNS = ("stretch", "u_m", "v_m", "depth_m", "force_n")

    def __init__(self, path: str) -> None:
        import csv

        if not os.path.isfile(path):
            raise ValueError(f"presses file not found: {path!r}")
        self.label = f"lab presses {os.path.basename(path)}"
        self.readings = []
        with open(path, newline="") as fh:
            rows = csv.DictReader(fh)
            missing = [c for c in self.COLUMNS if c not in (rows.fieldnames or [])]
            if missing:
                raise ValueError(f"{path}: missing columns {missing} (header: {rows.fieldnames})")
            for i, row in enumerate(rows, 2):
                vals = []
                for c in self.COLUMNS:
                    try:
                        vals.append(float(row[c]))
                    except (TypeError, ValueError):
                        raise ValueError(f"{path}: row {i}: {c} must be a number, got "
                                         f"{row[c]!r:.40}") from None
                self.readings.append(Press(*vals))
        if not self.readings:
            raise ValueError(f"{path}: no readings")

    def plan(self) -> list[tuple[float, float, float, tuple[float, ...]]]:
        """The presses the readings were taken at: (stretch, u, v, depths) per (stretch, u, v), in file
        order."""
        out: dict = {}
        for r in self.readings:
            out.setdefault((r.stretch, r.offset_u, r.offset_v), []).append(r.depth)
        return [(s, u, v, tuple(sorted(ds))) for (s, u, v), ds in out.items()]

    def sheet_presses(self, plan) -> list:
        """The file's readings (``plan`` is theirs)."""
        return list(self.readings)
