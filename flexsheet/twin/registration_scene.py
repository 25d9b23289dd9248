"""The registration scenes as the camera twin streams them while a lab drives the live graph (``flexsheet
calibrate display --live``): the images of :class:`flexsheet.twin.registration_camera.CalibrationTwin`, one
frame at a time, for the state the graph is in now — the arms' joints (read back from the controller twins),
the image the projector shows (``/projector/image``) and what the operator set up (a board on the sheet, the
room dark for the clamp markers).

Scenes (:data:`SCENES`): ``finger`` (the display running; the camera twin's own fingertip renderer, not here),
``board`` (the calibration board on the sheet), ``patterns`` (the bare sheet lit by the projector) and
``markers`` (the room dark, both clamp markers lit). The sheet with both arms at the joints that hold it at
the home pose (:func:`commanded_sheet_joints` of the identity) is rendered *at* the display frame: the board
there defines that frame, as in the offline twin.

Each state's noise-free image is drawn once and kept (:meth:`RegistrationScene.render` re-draws only when the
joints move by more than :data:`JOINT_KEY_RAD` or the projector image changes); every frame gets its own
sensor noise.
"""

from __future__ import annotations

import numpy as np

from flexsheet.twin.registration_camera import CalibrationTwin, commanded_sheet_joints
from flexsheet.twin.truth import TwinTruth
from flexsheet.vision.stereo_calibration import BoardSpec, parse_board

__all__ = ["SCENES", "RegistrationScene", "JOINT_KEY_RAD"]

SCENES = ("finger", "board", "patterns", "markers")
#: joints closer than this (rad) draw the same noise-free image (6 µm at the clamp's 0.3 m reach)
JOINT_KEY_RAD = 2e-5
#: the home pose's joints within this (rad, every joint) put the board at the display frame
HOME_TOL_RAD = 1e-4


class RegistrationScene:
    """Streams the registration scenes of ``truth`` (module doc). ``seed``: the image-noise seed."""

    def __init__(self, truth: TwinTruth, seed: int = 0):
        self.twin = CalibrationTwin(truth, seed=seed, frames=1)
        self.scene = "finger"
        self.board: BoardSpec = parse_board("chessboard:9x8", 0.022)
        self.board_offset = 0.0
        self._home = commanded_sheet_joints(np.eye(4), 0.0, self.twin._ik)
        self._key = None
        self._clean: list[np.ndarray] | None = None
        self._maps = None

    def set_scene(self, scene: str, board: str = "chessboard:9x8", square: float = 0.022,
                  offset: float = 0.0) -> str:
        """Switch to ``scene`` (one of :data:`SCENES`); for ``board``, the board spec (``board``, ``square``
        m) and its printed surface ``offset`` m in front of the sheet. Raises ``ValueError`` naming the
        field."""
        if scene not in SCENES:
            raise ValueError(f"scene must be one of {', '.join(SCENES)}, got {scene!r}")
        if not 0.0 <= float(offset) <= 0.02:
            raise ValueError(f"offset must be within [0, 0.02] m, got {offset!r}")
        self.board = parse_board(board, float(square))
        self.board_offset = float(offset)
        self.scene = scene
        self._key, self._clean, self._maps = None, None, None
        return scene

    def at_home(self, q_left: np.ndarray, q_right: np.ndarray) -> bool:
        """Whether both arms hold the sheet at the home pose (every joint within :data:`HOME_TOL_RAD`)."""
        return bool(np.all(np.abs(q_left - self._home["left"]) <= HOME_TOL_RAD)
                    and np.all(np.abs(q_right - self._home["right"]) <= HOME_TOL_RAD))

    def render(self, q_left, q_right, projector: tuple[int, np.ndarray] | None) -> tuple[np.ndarray,
                                                                                         np.ndarray]:
        """One raw stereo pair (uint8 (H, W) each) of the current scene with the arms at ``q_left``,
        ``q_right`` (6,) rad and the projector showing ``projector`` ((id, uint8 (h, w) image) or ``None``:
        dark). Raises ``ValueError`` in the ``finger`` scene (the fingertip renderer draws that one)."""
        if self.scene == "finger":
            raise ValueError("the finger scene is drawn by the camera twin's fingertip renderer")
        ql, qr = np.asarray(q_left, float), np.asarray(q_right, float)
        jkey = tuple(np.round(np.concatenate([ql, qr]) / JOINT_KEY_RAD).astype(np.int64))
        pkey = None if projector is None or self.scene != "patterns" else projector[0]
        key = (self.scene, jkey, pkey)
        if key != self._key:
            self._clean = self._draw(ql, qr, jkey, projector)
            self._key = key
        tw = self.twin
        ss_out = [tw.expose(img) for img in self._clean]
        return ss_out[0], ss_out[1]

    def _draw(self, ql, qr, jkey, projector) -> list[np.ndarray]:
        tw = self.twin
        if self.scene == "markers":
            dn = tw.marker_dn([tw.truth.clamp_marker_position("left", ql),
                               tw.truth.clamp_marker_position("right", qr)])
            return [tw.clean(a, tw.ss) for a in dn]
        T = np.eye(4) if self.at_home(ql, qr) and self.scene == "board" else tw.true_sheet_pose(ql, qr)
        if self.scene == "board":
            return [tw.clean(a, tw.ss) for a in tw.board_dn(self.board, T, self.board_offset)]
        if self._maps is None or self._maps[0] != jkey:          # the sheet moved: where the projector lands
            self._maps = (jkey, tw.pattern_maps(T))
        maps = self._maps[1]
        return [tw.clean(a, maps.ss)
                for a in tw.pattern_dn(maps, None if projector is None else projector[1])]
