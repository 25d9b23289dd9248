"""The arm bridge's services (:class:`BridgeServices`, a part of
:class:`nodes.arm_bridge.node.ArmBridgeNode`): ``hold``, ``home`` and ``move_to`` hold the arm on joints
(targets are ignored until ``release``); each acts on the joints the controller reported last and refuses
while it is not connected."""

from __future__ import annotations

import numpy as np

from flexsheet.model.sheet import clamp_poses

__all__ = ["BridgeServices"]


class BridgeServices:
    """The service half of the arm bridge; it uses the node's ``params``, ``kin``, ``stream``, ``tracker``,
    ``_q_measured``, ``ignored_while_held``, ``arm_now`` and ``log``."""

    def _require_state(self) -> np.ndarray:
        """The joints the controller reported last; raises ``ValueError`` while it is not connected (a stale
        reading would move the arm back to an old pose once it is)."""
        if self._q_measured is None or not self.stream.connected:
            raise ValueError(f"the {self.params.arm} arm's controller is not connected: no current joints to "
                             "act on")
        return self._q_measured

    def _ik(self, T, what: str) -> np.ndarray:
        res = self.kin.ik(np.asarray(T, float), self._require_state(), max_jump=10.0)
        if not res.ok:
            raise ValueError(f"{what} is unreachable for the {self.params.arm} arm: {res.status}")
        return res.q

    def _held(self, q) -> list[float]:
        """Hold on joints ``q`` for a service; the first hold says that targets are ignored until
        ``release``."""
        q = self.tracker.move_to(q)
        if self.ignored_while_held is None:
            self.ignored_while_held = 0
            self.log.info("%s arm: held by a service (hold/home/move_to): targets ignored until release",
                          self.params.arm)
        return q.tolist()

    def srv_hold(self, args: dict) -> list[float]:
        return self._held(self._require_state())

    def srv_home(self, args: dict) -> list[float]:
        left, right = clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.05)
        return self._held(self._ik(left if self.params.arm == "left" else right, "the home pose"))

    def srv_move_to(self, args: dict) -> list[float]:
        if ("joints" in args) == ("pose" in args):
            raise ValueError("move_to takes one of joints ([6] rad) or pose (4x4, m, display frame)")
        if "joints" in args:
            return self._held(args["joints"])
        T = np.asarray(args["pose"], float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"pose must be a finite 4x4 matrix, got shape {T.shape}")
        return self._held(self._ik(T, "the pose"))

    def srv_release(self, args: dict) -> str:
        self.tracker.release(self.arm_now())
        if self.ignored_while_held is not None:
            self.log.info("%s arm: released: following targets again (%d ignored while held)",
                          self.params.arm,
                          self.ignored_while_held)
        self.ignored_while_held = None
        return "following targets"
