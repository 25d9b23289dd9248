"""Where the CLI finds node types, experiments, benchmarks and calibration commands.

Each entry is ``"module:attribute"`` and is imported lazily, so ``flexsheet --help`` stays fast and a
broken optional module only breaks its own subcommand. Node entries name a :class:`flexsheet.runtime.node.Node`
subclass; experiment, bench and calibrate entries name a ``main(argv: list[str]) -> int`` function that
parses its own arguments with argparse (its ``--help`` shows a working example).
"""

from __future__ import annotations

import importlib
from typing import Any

NODES: dict[str, str] = {
    "camera": "nodes.camera.node:CameraNode",
    "triangulator": "nodes.triangulator.node:TriangulatorNode",
    "planner": "nodes.planner.node:PlannerNode",
    "arm_bridge": "nodes.arm_bridge.node:ArmBridgeNode",
    "arm_controller_sim": "nodes.arm_controller_sim.node:ArmControllerSimNode",
    "fem": "nodes.fem.node:FemNode",
    "renderer": "nodes.renderer.node:RendererNode",
    "world": "nodes.world.node:WorldNode",
    "viz": "nodes.viz.node:VizNode",
    "recorder": "flexsheet.runtime.bag:RecorderNode",
    "player": "flexsheet.runtime.bag:PlayerNode",
    "talker": "flexsheet.runtime.demo:TalkerNode",
    "listener": "flexsheet.runtime.demo:ListenerNode",
}

EXPERIMENTS: dict[str, str] = {
    "triangulation": "flexsheet.experiments.triangulation:main",
    "stroke": "flexsheet.experiments.graph_stroke:main",
    "stroke_model": "flexsheet.experiments.stroke:main",
    "scenes": "flexsheet.experiments.scenes:main",
    "fem": "flexsheet.experiments.fem:main",
    "correction": "flexsheet.experiments.correction:main",
    "stability": "flexsheet.experiments.stability:main",
    "compliance": "flexsheet.experiments.compliance:main",
    "latency_load": "flexsheet.experiments.latency_load:main",
    "determinism": "flexsheet.experiments.determinism:main",
    "faults": "flexsheet.experiments.faults:main",
}

BENCHES: dict[str, str] = {
    "transport": "flexsheet.benches.transport:main",
    "vision": "flexsheet.benches.vision:main",
    "camera": "nodes.camera.bench:main",
    "planner": "flexsheet.benches.planner:main",
    "arm": "nodes.arm_bridge.bench:main",
    "fem": "flexsheet.benches.fem:main",
    "fem_startup": "nodes.fem.startup_bench:main",
    "render": "nodes.renderer.bench:main",
    "load": "flexsheet.benches.load:main",
    "viz": "nodes.viz.bench:main",
    "graph": "nodes.camera.graph_bench:main",
}

CALIBRATE: dict[str, str] = {
    "stereo": "flexsheet.vision.stereo_calibration:main",
    "camera-pose": "flexsheet.display.calibrate:camera_pose_main",
    "projector": "flexsheet.display.calibrate:projector_main",
    "arms": "flexsheet.display.calibrate:arms_main",
    "eye": "flexsheet.display.calibrate:eye_main",
    "display": "flexsheet.display.calibrate:display_main",
    "noise": "flexsheet.display.calibrate:noise_main",
}


def load(spec: str) -> Any:
    """Import ``"module:attribute"`` and return the attribute; raises ``ImportError``/``AttributeError``."""
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)
