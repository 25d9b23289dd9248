"""How a GenICam stereo pair is synchronised (pure, no Aravis): :func:`probe_features` reads what a camera
offers (trigger lines, PTP, timestamp latch; SFNC 2.x and GigE Vision legacy names) and :func:`plan_sync`
chooses hardware trigger, master/slave trigger line, software trigger or free run, and PTP when offered
(:class:`SyncPlan`). Setup guide: ``docs/camera.md``."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["SyncPlan", "plan_sync", "probe_features", "PTP_FEATURES", "LATCH_FEATURES", "PTP_LOCKED"]


PTP_FEATURES = (("PtpEnable", "PtpStatus"), ("GevIEEE1588", "GevIEEE1588Status"))  # SFNC 2.x, GigE legacy


LATCH_FEATURES = (("TimestampLatch", "TimestampLatchValue"),  # SFNC 2.x
                  ("GevTimestampControlLatch", "GevTimestampValue"))  # GigE Vision legacy


PTP_LOCKED = ("Master", "Slave")


@dataclass
class SyncPlan:
    """How the pair is synchronised.

    ``trigger``: ``hardware`` (both cameras triggered on ``trigger_line`` by an external pulse),
    ``master`` (the left camera free-runs and drives ``master_output_line`` with ExposureActive, wired to
    the right camera's ``trigger_line``), ``software`` (the host fires TriggerSoftware on both, back to
    back, every period), or ``free`` (both free-run at the frame rate). ``ptp``: enable IEEE 1588 on both.
    ``notes``: one log line per degradation or caveat.
    """

    trigger: str
    ptp: bool
    trigger_line: str = "Line1"
    master_output_line: str = "Line2"
    notes: list[str] = field(default_factory=list)


def plan_sync(left: dict, right: dict, trigger: str, ptp: str, trigger_line: str = "Line1",
              master_output_line: str = "Line2") -> SyncPlan:
    """Choose the synchronisation from the two cameras' probed features (:func:`probe_features` dicts:
    ``ptp`` feature name or None, ``trigger_sources`` list, ``software_trigger`` bool, ``line_selector``
    and ``line_source`` lists). ``trigger`` is requested: hardware | master | software | free; ``ptp``:
    auto | on | off. What a camera lacks degrades the plan (hardware/master → software → free), with one
    note per step saying what was missing. Raises ``ValueError`` for an unknown ``trigger``/``ptp``."""
    if trigger not in ("hardware", "master", "software", "free"):
        raise ValueError(f"trigger must be hardware|master|software|free, got {trigger!r}")
    if ptp not in ("auto", "on", "off"):
        raise ValueError(f"ptp must be auto|on|off, got {ptp!r}")
    cams = {"left": left, "right": right}
    notes: list[str] = []
    chosen = trigger
    if chosen == "hardware":
        lacking = [n for n, f in cams.items() if trigger_line not in f.get("trigger_sources", [])]
        if lacking:
            notes.append(f"hardware trigger: {', '.join(lacking)} camera offers no TriggerSource "
                         f"{trigger_line!r} (left has {left.get('trigger_sources', [])}, right has "
                         f"{right.get('trigger_sources', [])}); falling back to software trigger")
            chosen = "software"
    elif chosen == "master":
        why = []
        if master_output_line not in left.get("line_selector", []):
            why.append(f"left camera has no output line {master_output_line!r} "
                       f"(lines {left.get('line_selector', [])})")
        elif "ExposureActive" not in left.get("line_source", []):
            why.append("left camera cannot drive ExposureActive on a line "
                       f"(sources {left.get('line_source', [])})")
        if trigger_line not in right.get("trigger_sources", []):
            why.append(f"right camera offers no TriggerSource {trigger_line!r} "
                       f"({right.get('trigger_sources', [])})")
        if why:
            notes.append("master/slave trigger: " + "; ".join(why) + "; falling back to software trigger")
            chosen = "software"
    if chosen == "software":
        lacking = [n for n, f in cams.items() if not f.get("software_trigger")]
        if lacking:
            notes.append(f"software trigger: {', '.join(lacking)} camera has no TriggerSoftware; "
                         "free-running")
            chosen = "free"
    use_ptp = False
    if ptp != "off":
        lacking = [n for n, f in cams.items() if not f.get("ptp")]
        if not lacking:
            use_ptp = True
        elif ptp == "on" or chosen == "free":
            notes.append(f"PTP: {', '.join(lacking)} camera has neither PtpEnable nor GevIEEE1588; device "
                         "clocks stay independent (each mapped to host time; skew measured through that "
                         "mapping)")
    if chosen == "free" and not use_ptp:
        notes.append("free-running without PTP: exposures are not synchronised (phase random, skew up to "
                     "half a frame period); pairs beyond pair_tolerance_s are dropped as unpaired")
    return SyncPlan(chosen, use_ptp, trigger_line, master_output_line, notes)


def _enum_entries(cam, name: str) -> list[str]:
    try:
        if not cam.is_feature_available(name):
            return []
        return list(cam.dup_available_enumerations_as_strings(name))
    except Exception:  # noqa: BLE001 - a feature that cannot be read is a feature the camera lacks
        return []


def _available(cam, name: str) -> bool:
    try:
        return bool(cam.is_feature_available(name))
    except Exception:  # noqa: BLE001
        return False


def probe_features(cam) -> dict:
    """Probe one ``Aravis.Camera``: ``ptp``/``ptp_status`` feature names (or None), ``trigger_sources``,
    ``software_trigger``, ``line_selector``, ``line_source``, ``latch`` (command, value) names or None,
    ``pixel_formats``, ``tick_hz`` (GigE timestamp tick frequency, 0 if unknown; 1e9 for USB3: ns by
    spec), ``gv`` (GigE device)."""
    f: dict = {"ptp": None, "ptp_status": None, "latch": None}
    for en, st in PTP_FEATURES:
        if _available(cam, en):
            f["ptp"], f["ptp_status"] = en, st if _available(cam, st) else None
            break
    for cmd, val in LATCH_FEATURES:
        if _available(cam, cmd) and _available(cam, val):
            f["latch"] = (cmd, val)
            break
    f["trigger_sources"] = _enum_entries(cam, "TriggerSource") if _available(cam, "TriggerMode") else []
    f["software_trigger"] = bool(cam.is_software_trigger_supported()) and "Software" in f["trigger_sources"]
    f["line_selector"] = _enum_entries(cam, "LineSelector")
    f["line_source"] = _enum_entries(cam, "LineSource")
    f["pixel_formats"] = list(cam.dup_available_pixel_formats_as_strings())
    f["gv"] = bool(cam.is_gv_device())
    f["tick_hz"] = 1e9
    if f["gv"]:
        try:
            f["tick_hz"] = float(cam.get_device().get_timestamp_tick_frequency())
        except Exception:  # noqa: BLE001
            f["tick_hz"] = 0.0
    return f
