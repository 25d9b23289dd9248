"""The Foxglove / Lichtblick layout for the viz bridge and for bags with Foxglove channels (pure).

``layout()`` returns the layout as a dict in the classic layout-file format (``configById``,
``globalVariables``, ``userNodes``, ``layout`` mosaic tree) that both Foxglove ("Import from file…") and
Lichtblick import: a 3-D panel (``/viz/scene`` + ``/viz/tf``, following the ``display`` frame), the left and
right camera images with their calibrations, the projector's rendered pair, and plots of Δθ, the hop
latencies and the sheet tension from ``/viz/metrics``. ``docs/foxglove_layout.json`` is this dict;
regenerate it with ``python -m flexsheet.viz.layout docs/foxglove_layout.json`` (a test checks they agree).
"""

from __future__ import annotations

import argparse
import json
import sys

from flexsheet.viz.foxglove import (
    CAMERA_LEFT,
    CAMERA_LEFT_INFO,
    CAMERA_RIGHT,
    CAMERA_RIGHT_INFO,
    METRICS,
    RENDER_IMAGE,
    SCENE,
    TF,
)

__all__ = ["layout", "PLOTS", "main"]

#: plot panels: id -> (title, [(message path, label)])
PLOTS = {
    "Plot!dtheta": ("Δθ: object normal vs measured sheet normal (deg)",
                    [(f"{METRICS}.dtheta_deg", "Δθ (deg)")]),
    "Plot!latency": ("latency from camera exposure (ms)", [
        (f"{METRICS}.latency_ms.fingertip", "fingertip"), (f"{METRICS}.latency_ms.target", "sheet target"),
        (f"{METRICS}.latency_ms.arm_left", "left arm write"),
        (f"{METRICS}.latency_ms.arm_right", "right arm write"),
        (f"{METRICS}.latency_ms.render", "rendered frame")]),
    "Plot!tension": ("sheet tension (N/m)", [(f"{METRICS}.tension", "tension (N/m)")]),
}


def _plot(title: str, series: list[tuple[str, str]]) -> dict:
    return {"title": title,
            "paths": [{"value": v, "enabled": True, "timestampMethod": "receiveTime", "label": lab}
                      for v, lab in series],
            "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
            "showPlotValuesInLegend": True, "isSynced": True, "xAxisVal": "timestamp",
            "sidebarDimension": 240}


def _image(topic: str, calibration: str | None) -> dict:
    mode = {"imageTopic": topic}
    if calibration:
        mode["calibrationTopic"] = calibration
    return {"cameraState": {"distance": 1.0, "perspective": True, "phi": 60, "target": [0, 0, 0],
                            "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "thetaOffset": 45,
                            "fovy": 45, "near": 0.01, "far": 100},
            "followMode": "follow-pose", "scene": {}, "transforms": {}, "topics": {}, "layers": {},
            "publish": {"type": "point", "poseTopic": "/move_base_simple/goal",
                        "pointTopic": "/clicked_point",
                        "poseEstimateTopic": "/initialpose", "poseEstimateXDeviation": 0.5,
                        "poseEstimateYDeviation": 0.5, "poseEstimateThetaDeviation": 0.26179939},
            "imageMode": mode}


def layout() -> dict:
    """The layout dict (see module docstring). Topic names come from :mod:`flexsheet.viz.foxglove`."""
    three_d = {
        "cameraState": {"distance": 1.9, "perspective": True, "phi": 62, "thetaOffset": 35,
                        "target": [-0.1, 0, -0.1],
                        "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "fovy": 45,
                        "near": 0.01,
                        "far": 50},
        "followMode": "follow-pose", "followTf": "display",
        "scene": {"enableStats": False, "backgroundColor": "#1b1d22", "labelScaleFactor": 0.6,
                  "transforms": {"showLabel": False, "axisScale": 0.5}},
        "transforms": {"frame:display": {"visible": True}},
        "topics": {SCENE: {"visible": True}, TF: {"visible": True}},
        "layers": {"grid": {"layerId": "foxglove.Grid", "visible": True, "frameId": "display", "size": 2,
                            "divisions": 20, "lineWidth": 1, "color": "#ffffff30", "position": [0, 0, -0.4],
                            "rotation": [0, 0, 0], "order": 1, "label": "floor (z = -0.4 m)"}},
        "publish": {"type": "point", "poseTopic": "/move_base_simple/goal", "pointTopic": "/clicked_point",
                    "poseEstimateTopic": "/initialpose", "poseEstimateXDeviation": 0.5,
                    "poseEstimateYDeviation": 0.5, "poseEstimateThetaDeviation": 0.26179939},
        "imageMode": {},
    }
    config = {"3D!viz": three_d, "Image!left": _image(CAMERA_LEFT, CAMERA_LEFT_INFO),
              "Image!right": _image(CAMERA_RIGHT, CAMERA_RIGHT_INFO),
              "Image!render": _image(RENDER_IMAGE, None)}
    config.update({k: _plot(t, s) for k, (t, s) in PLOTS.items()})
    images = {"direction": "column", "splitPercentage": 33.3, "first": "Image!left",
              "second": {"direction": "column", "splitPercentage": 50, "first": "Image!right",
                         "second": "Image!render"}}
    plots = {"direction": "row", "splitPercentage": 33.3, "first": "Plot!dtheta",
             "second": {"direction": "row", "splitPercentage": 50, "first": "Plot!latency",
                        "second": "Plot!tension"}}
    tree = {"direction": "column", "splitPercentage": 70,
            "first": {"direction": "row", "splitPercentage": 68, "first": "3D!viz", "second": images},
            "second": plots}
    return {"configById": config, "globalVariables": {}, "userNodes": {},
            "playbackConfig": {"speed": 1.0}, "layout": tree}


def main(argv: list[str] | None = None) -> int:
    """Write the layout JSON to a file (or stdout with ``-``)."""
    ap = argparse.ArgumentParser(prog="python -m flexsheet.viz.layout", description=__doc__.splitlines()[0],
                                 epilog="example:\n  python -m flexsheet.viz.layout "
                                        "docs/foxglove_layout.json",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("output", nargs="?", default="-", help="output .json ('-': stdout)")
    args = ap.parse_args(argv)
    text = json.dumps(layout(), indent=2, ensure_ascii=False) + "\n"
    if args.output == "-":
        sys.stdout.write(text)
    else:
        with open(args.output, "w", encoding="utf-8") as fh:
            fh.write(text)
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
