"""The lab's timings, declared with their sources: what a live simulated graph (``clock: sim``) charges to
simulated time for each device and each handler of the display (``Node.subscribe(..., sim_cost=)``).

The display's own compute is declared per handler as the CPU time it takes on this project's reference host
(its mean per output in a full simulated run) times :attr:`LabTiming.compute_scale` for the lab's PC.
Declared, not measured during the run: a run's result must not depend on how busy the host is. The run reports
beside it what each node's handlers really took on the host (``sim_clock.json``: ``host_handler_cpu_s``).

Sources (A = an assumption, to be replaced by the lab's measurement):

* camera: the twin renders the XIMEA model (640 × 512 mono8 pairs) at the camera node's ``rate_hz`` with its
  ``exposure_s``; frames are stamped at mid-exposure. Sensor readout 2.4 ms (the Vicon pipeline's figure,
  docs/realtime.md; A for the XIMEA sensor); transfer of the pair over USB3 Vision at 350 MB/s sustained (A:
  USB 3.0's 5 Gb/s less protocol overhead); host driver hand-over 0.3 ms (A).
* network: one hop between the lab's PCs over switched gigabit Ethernet, 0.2 ms for a message of a few
  hundred bytes (A: a switch and two kernel stacks).
* controller: the MELFA real-time external control cycle of 7.11 ms (MELFA CR1/CR2 manual, "Real-time
  external command"; :mod:`flexsheet.arm.bridge_config`); the servo's response is the controller twin's
  (:class:`flexsheet.twin.servo.ServoParams`).
* projector: the DepthQ's 120 Hz frame-sequential stereo (the paper's projector; InFocus DepthQ HDs3D-1
  data: 120 Hz input); a frame is shown from the first vsync after it is rendered, plus one frame of input
  buffering (A: 8.33 ms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["LabTiming", "LAB"]


@dataclass(frozen=True)
class LabTiming:
    """The lab's timings (SI: s, Hz, B/s). See the module docstring for each source."""

    camera_readout_s: float = 0.0024
    camera_transfer_bytes_per_s: float = 350e6
    camera_handover_s: float = 0.0003
    network_s: float = 0.0002
    controller_cycle_s: float = 0.00711
    projector_refresh_hz: float = 120.0
    projector_input_latency_s: float = 1.0 / 120.0
    #: the lab PC's speed relative to the reference host on which ``compute_s`` was measured (1.0: alike)
    compute_scale: float = 1.0
    #: CPU time per call on the reference host, s: the mean handler CPU per output of each node in a full
    #: ``launch/sim.yaml`` run on this project's 2-core machine (``sim_clock.json``
    #: ``host_handler_cpu_s`` over the output count, all the node's handlers included; docs/realtime.md)
    compute_s: dict[str, float] = field(default_factory=lambda: {
        "triangulator": 0.00176,  # detect + undistort + triangulate + Kalman, one 640x512 pair
        "planner": 0.00061,  # contact point, tangent plane, sheet target, two arm targets (+ FEM stiffness)
        "fem": 0.00144,           # one realtime FEM update (nonlinear snapshots)
        "renderer": 0.0040,  # one corrected stereo pair on a desktop GPU (A: llvmpipe here takes ~13.6 ms)
        "arm_bridge": 0.00005,    # IK of one clamp target
        # ArUco detection, edge-line corners + PnP of the glasses board, one 640x512 frame
        "head_camera": 0.0031,
    })

    def camera_latency(self, exposure_s: float, width: int = 640, height: int = 512) -> float:
        """Mid-exposure → frame handed to the graph, s: half the exposure, readout, transfer of the pair
        (``2·width·height`` bytes), hand-over. Raises ``ValueError`` for a negative exposure."""
        if not exposure_s >= 0.0:
            raise ValueError(f"exposure_s must be >= 0 s, got {exposure_s!r}")
        return (0.5 * exposure_s + self.camera_readout_s + 2.0 * width * height
                / self.camera_transfer_bytes_per_s
                + self.camera_handover_s)

    def compute(self, what: str) -> float:
        """Declared compute of one call of handler ``what`` (a key of :attr:`compute_s`) on the lab's PC, s.
        Raises ``KeyError`` naming the known keys."""
        try:
            return self.compute_s[what] * self.compute_scale
        except KeyError:
            raise KeyError(f"no declared compute for {what!r}; known: "
                           f"{', '.join(sorted(self.compute_s))}") from None

    def projected_at(self, rendered: float) -> float:
        """When a frame rendered (handed to the display) at ``rendered`` s is on the sheet: the next vsync of
        the projector's refresh plus its input latency, s."""
        period = 1.0 / self.projector_refresh_hz
        return math.ceil(rendered / period) * period + self.projector_input_latency_s


#: the lab's timings used by the simulated graph
LAB = LabTiming()
