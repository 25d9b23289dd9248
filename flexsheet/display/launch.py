"""The display's launch extension (:mod:`flexsheet.runtime.extensions`): the top-level ``twin:``, ``scene:``
and ``display_calib:`` sections of a launch file, the twin's registration before a simulated launch, and the
``--check`` rules for them.

- ``display_calib: FILE`` — the display registration (``display.yaml``) the nodes take their geometry from;
  may use ``$(out)`` and ``$(launch_dir)``; handed to every node with a ``display_calib`` param.
- ``scene: FILE`` — the scene file (``launch/scenes/*.yaml``) every node with a ``scene`` param presents.
- the display's node types' topics and the values two of them share, for the graph builder
  (:mod:`flexsheet.display.graph_topics`);
- ``twin: {realism, truth_seed, registration}`` — the hidden truth every twin node draws; with
  ``registration: true`` (default) and no ``display_calib``, ``flexsheet launch`` first runs the registration
  in the twin (cached per seed) and hands its ``display.yaml`` to the estimators.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

from pydantic import ConfigDict

from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.dirs import cache_root as flexsheet_cache_root
from flexsheet.display.graph_topics import NODE_TOPICS, SHARED_VALUES
from flexsheet.model.scenes import load_scene
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.runtime.console import console_logger, show_lines
from flexsheet.runtime.extensions import LaunchExtension, LaunchSection
from flexsheet.runtime.launch import LaunchError, LaunchFile, substitute, substitutions
from flexsheet.twin.registration import sim_display_calib, sim_display_calib_cached
from flexsheet.vision.calib_yaml import load_yaml

#: the launcher's console (the display layer's lines among the launcher's own)
log = console_logger("launch")
#: the loggers of the twin's registration whose progress a launch shows
REGISTRATION_LOGGERS = ("flexsheet.twin.registration", "flexsheet.calibration")

__all__ = ["TwinSpec", "EXTENSION", "display_calib_path", "twin_registration", "twin_registration_path",
           "read_display_calib", "DISPLAY_NEEDS", "DISPLAY_COMMANDS"]

#: node type → the ``display.yaml`` entries its nodes take
#: their geometry from (``{arm}``: the node's arm param)
DISPLAY_NEEDS: dict[str, tuple[str, ...]] = {"camera": ("camera",), "renderer": ("projector", "eye"),
                                             "planner": ("arms.left", "arms.right"),
                                             "arm_bridge": ("arms.{arm}",)}
#: display.yaml entry → the command that measures it (docs/calibration.md)
DISPLAY_COMMANDS = {"camera": "flexsheet calibrate camera-pose", "projector": "flexsheet calibrate projector",
                    "arms": "flexsheet calibrate arms", "eye": "flexsheet calibrate eye"}


class TwinSpec(TruthChoice):
    """The top-level ``twin:`` section: which hidden truth every twin node draws (``realism``, ``truth_seed``:
    :class:`~flexsheet.model.truth_choice.TruthChoice`, the same config the twin nodes take) and
    ``registration``: before the nodes start, run the registration procedures in the twin
    (``flexsheet calibrate display --sim``, cached per seed) and give the estimators the ``display.yaml`` it
    writes (when the file names no ``display_calib`` of its own)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    registration: bool = True


def _path(value: str | None, lf: LaunchFile, out: str | None) -> str | None:
    return None if not value else os.path.expanduser(substitute(value, substitutions(lf, out)))


def display_calib_path(lf: LaunchFile, out: str | None = None) -> str | None:
    """The launch file's ``display_calib`` with substitutions and ``~`` expanded (None when it names none)."""
    return _path(lf.section("display_calib"), lf, out)


def _set_path(text: str) -> str | None:
    return os.path.abspath(os.path.expanduser(text)) if text else None


def twin_registration_path(twin: TwinSpec, cache_root: str | None = None) -> Path:
    """Where :func:`twin_registration` caches the ``display.yaml`` of ``twin``'s realism and seed (the cache
    of :func:`flexsheet.twin.registration.sim_display_calib`)."""
    root = Path(cache_root or flexsheet_cache_root()).expanduser()
    return root / "display" / f"{twin.realism}-{twin.truth_seed}" / "display.yaml"


def twin_registration(twin: TwinSpec, cache_root: str | None = None) -> str:
    """Run the display registration in the twin for ``twin`` (the procedures of ``flexsheet calibrate display
    --sim``: camera pose, projector, arm bases, against images rendered from the hidden truth), cached per
    realism, seed, options and procedure version; returns the ``display.yaml`` path. The estimators get only
    this file, never the truth. Its lines go to the launcher's console (``[launch] …``), the procedures'
    progress with them. Raises :class:`LaunchError` when the registration fails."""
    for name in REGISTRATION_LOGGERS:
        show_lines(name, prefix="[launch] ")
    log.info(f"[launch] twin registration ({twin.realism}, truth seed {twin.truth_seed}): the calibration "
             f"procedures in the twin (cached per seed; the first run of a seed takes ~20-60 s) ...")
    try:
        path = sim_display_calib(twin.truth_seed, twin.realism, cache_root=cache_root)
    except (ValueError, RuntimeError, OSError) as exc:
        raise LaunchError(f"twin registration (truth seed {twin.truth_seed}) failed: {exc}") from None
    log.info(f"[launch] twin registration: {path}")
    return str(path)


def before_launch(lf: LaunchFile, check_only: bool) -> dict:
    """The twin's registration, when the file asks for it and names no ``display_calib``: returns
    ``{"display_calib": path}`` (nothing with ``check_only`` when the cache is cold: a note, logged at
    WARNING, instead)."""
    twin = lf.section("twin")
    if twin is None or not twin.registration or lf.section("display_calib") is not None:
        return {}
    if check_only:
        cached = sim_display_calib_cached(twin.truth_seed, twin.realism)
        if cached is None:
            log.warning(f"{lf.path}: the twin registration (truth seed {twin.truth_seed}) runs at start and "
                        f"writes {twin_registration_path(twin)}")
            return {}
        return {"display_calib": cached}
    return {"display_calib": twin_registration(twin)}


def read_display_calib(path: str) -> None:
    """Parse a display calibration (:func:`flexsheet.calibration.display_calib_file.load_display_calib`);
    raises ``ValueError``."""
    load_display_calib(path)


def read_stereo_calib(path: str) -> None:
    """Parse a stereo calibration YAML (:func:`flexsheet.vision.calib_yaml.load_yaml`); raises
    ``ValueError``."""
    load_yaml(path)


def _check_scene(c) -> None:
    """The top-level ``scene:`` file exists and validates (:func:`flexsheet.model.scenes.load_scene`)."""
    path = _path(c.lf.section("scene"), c.lf, c.out)
    if path is None:
        return
    problem = c.file_problem("scene", path)
    if problem:
        c.err("scene", path, problem)
        return

    try:
        load_scene(path)
    except ValueError as exc:
        c.err("scene", path, str(exc))


def _check_display_calib(c) -> None:
    """The ``display_calib`` file parses, holds every entry the checked host's nodes need (nominal ones are
    warned about) and its camera entry is newer than the camera's ``calib_file``."""
    path = display_calib_path(c.lf, c.out)
    if path is None:
        twin = c.lf.section("twin")
        users = [n for n, spec in c.lf.nodes.items() if spec.host in c.hosts and spec.type in DISPLAY_NEEDS]
        if users and (twin is None or not twin.registration):
            c.warn(f"no display_calib: node(s) {', '.join(users)} run on the nominal geometry (camera pose, "
                   "projector, eye, arm bases), not this display's; register it (flexsheet calibrate "
                   "display, docs/calibration.md) and name its display.yaml in the launch file: "
                   "display_calib: FILE")
        return
    problem = c.file_problem("display_calib", path)
    if problem:
        c.err("display_calib", path, problem + (" (the registration writes it: docs/calibration.md)"
                                                if problem == "no such file" else ""))
        return

    calib = load_display_calib(path)
    for name, spec in c.lf.nodes.items():
        if spec.host not in c.hosts:
            continue
        params = c.params(name)
        for entry in DISPLAY_NEEDS.get(spec.type, ()):
            entry = entry.format(arm=params.get("arm", "left"))
            command = DISPLAY_COMMANDS[entry.split(".")[0]]
            if calib.missing([entry]):
                c.err("display_calib", path, f"no '{entry}' entry, which node {name} needs (run: {command}; "
                                             "docs/calibration.md)")
            elif calib.stale(math.inf, [entry]):
                c.warn(f"display_calib: the '{entry}' entry node {name} uses is nominal, not measured (run: "
                       f"{command})")
        calib_file = params.get("calib_file")
        if spec.type == "camera" and calib.camera is not None and isinstance(calib_file, str) and calib_file \
                and os.path.isfile(os.path.expanduser(calib_file)):
            measured = time.time() - calib.camera.provenance.age_s()
            changed = os.path.getmtime(os.path.expanduser(calib_file))
            if calib.camera.provenance.source != "nominal" and measured < changed:
                c.err("display_calib", path, "stale 'camera' entry: measured "
                                             f"{calib.camera.provenance.measured_at},"
                                             f" before node {name}'s calib_file {calib_file} changed "
                                             f"({time.strftime('%Y-%m-%dT%H:%M:%S', time.localtime(changed))}"
                                             f"); run: {DISPLAY_COMMANDS['camera']}")


def _check(c) -> None:
    _check_display_calib(c)
    _check_scene(c)


def _twin_value(twin: TwinSpec | None, lf: LaunchFile, out: str | None) -> dict | None:
    return None if twin is None else {"realism": twin.realism, "truth_seed": twin.truth_seed}


#: the display's launch extension, named in pyproject.toml's ``flexsheet.launch_extensions`` entry points
EXTENSION = LaunchExtension(
    name="display",
    sections=(
        LaunchSection("display_calib", str | None, lambda v, lf, out: _path(v, lf, out), _set_path,
                      "display registration file (display.yaml) the nodes take their geometry from"),
        LaunchSection("scene", str | None, lambda v, lf, out: _path(v, lf, out), _set_path,
                      "scene file (launch/scenes/*.yaml) every node presents"),
        LaunchSection("twin", TwinSpec | None, _twin_value, None,
                      "the twin's hidden truth (simulated graphs only)"),
    ),
    before_launch=before_launch,
    check=_check,
    file_readers={"calib_file": read_stereo_calib, "display_calib": read_display_calib},
    input_params=frozenset({"scene"}),
    output_params={("fem", "cache_dir"): "dir"},
    listen_params={"arm_controller_sim": ("host", "port")},
    node_topics=NODE_TOPICS,
    shared_values=SHARED_VALUES,
)
