"""Display registration: pure estimators that put the stereo camera, the projector, the arms and the
eye into the ``display`` frame, the twin that renders what the real camera would see from a hidden truth, and
the ``flexsheet calibrate camera-pose | projector | arms | eye | display`` commands.

Modules: :mod:`.camera_pose`, :mod:`.projector`, :mod:`.arms`, :mod:`.eye` (estimators, fed frames by either
source), :mod:`.twin` (frames from the truth), :mod:`.sources` (the twin source and the lab's captured-images
source), :mod:`.procedures` (the lab-order procedures on any source), :mod:`.cli` (commands). See
docs/calibration.md.
"""
