"""The lab PCs' clocks as the twin draws them: each arm PC's clock is off the main PC's by a drawn offset.

The lab synchronises its three PCs with chrony (docs/deploy.md, "2. Time sync"), which keeps each arm PC
within :data:`ARM_CLOCK_OFFSET_MAX` of main, so the two arm PCs within twice that (0.5 ms) of each other. Both
bridges evaluate the sheet's motion at their own clock's instant against the segment's start stamp from main,
so the offset puts one clamp ahead of the other on the path. A realistic truth draws each arm's offset
uniformly in ±:data:`ARM_CLOCK_OFFSET_MAX`, per truth seed and arm; an ideal one has none. Units s.
"""

from __future__ import annotations

from flexsheet.twin.head import seeded_stream

__all__ = ["ARM_CLOCK_OFFSET_MAX", "arm_clock_offset"]

#: the largest offset of an arm PC's clock from main's, s (chrony on the lab's LAN: docs/deploy.md)
ARM_CLOCK_OFFSET_MAX = 0.25e-3


def arm_clock_offset(truth_seed: int, realism: str, arm: str) -> float:
    """The ``arm`` ("left" or "right") PC's clock minus main's, s, for truth ``truth_seed`` (int ≥ 0) and
    ``realism`` ("realistic": drawn in ±:data:`ARM_CLOCK_OFFSET_MAX`; "ideal": 0). Raises ``ValueError``
    naming a bad argument."""
    if arm not in ("left", "right"):
        raise ValueError(f"arm must be 'left' or 'right', got {arm!r}")
    if realism not in ("realistic", "ideal"):
        raise ValueError(f"realism must be 'realistic' or 'ideal', got {realism!r}")
    if not isinstance(truth_seed, int) or truth_seed < 0:
        raise ValueError(f"truth_seed must be an integer >= 0, got {truth_seed!r}")
    if realism == "ideal":
        return 0.0
    return float(seeded_stream(truth_seed, f"{arm} arm PC clock").uniform(-ARM_CLOCK_OFFSET_MAX,
                                                                           ARM_CLOCK_OFFSET_MAX))
