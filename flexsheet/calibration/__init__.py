"""Display registration: pure estimators that put the stereo camera, the projector, the arms, the head camera
and the eye into the ``display`` frame, identify the sheet's force law, and write ``display.yaml``.

Modules: :mod:`.camera_pose`, :mod:`.projector` (+ :mod:`.projector_joint`, the joint refinement),
:mod:`.arms`, :mod:`.eye`, :mod:`.head_camera`, :mod:`.sheet` (estimators, fed frames by either source),
:mod:`.sources` (the lab's captured-images source; the twin's is
:class:`flexsheet.twin.registration.TwinSource`), :mod:`.procedures` (the lab-order procedures on any source),
:mod:`.display_calib` and :mod:`.display_calib_file` (the result and its file). The ``flexsheet calibrate …``
commands are :mod:`flexsheet.display.calibrate`; the registration run in the twin and its studies are in
:mod:`flexsheet.twin`. See docs/calibration.md.
"""
