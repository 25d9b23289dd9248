"""The experiment's fixed settings: the accuracy target, the clamp stretch, the true sheet's FEM table, the
paper's numbers, the assumptions written into every summary and the models' column labels."""

from __future__ import annotations

from flexsheet.model import geometry

#: one projector pixel on the imaginary screen, m: the target
PIXEL = geometry.PIXEL_ON_SCREEN
#: clamp strain of both experiments: the planner's stretch for the default 30 N/m object
#: (``stretch_for_stiffness`` → 0.0388), rounded to the world's FEM table node (``FemSettings.stretch_step``)
STRETCH = 0.04
#: depths (m) of the true sheet's FEM table (centre contact; solved directly at Fig. 13's depths)
FEM_DEPTHS = (0.005, 0.010, 0.020, 0.030, 0.040, 0.050, 0.060)
#: contact positions of the true sheet's table: the centre only (the true contact is within a few mm of
#: it; the table's remapping moves the solution there, :class:`flexsheet.model.sheet_table.IndentTable`)
FEM_POSITIONS = (0.0,)

PAPER = {
    "inclined": {"50": {"uncorrected_mm": 27.5, "corrected_mm": 2.1},
                 "max_corrected_mm": {"h": 4.9, "u": 2.1, "d": 2.1},
                 "mean_corrected_mm": {"h": 2.5, "u": 1.1, "d": 1.1}},
    "pushed": {"50": {"uncorrected_mm": 15.8, "four_triangle_mm": 2.1},
               "max_corrected_mm": {"h": 4.2, "w": 2.8}, "mean_corrected_mm": {"h": 2.8, "w": 1.7}},
    "pixel_mm": 0.7,
}

ASSUMPTIONS = [
    "Inclined sheet = tangent plane of the cylinder at angle θ, tilted down (contact (−R+R cosθ, 0, −R "
    "sinθ), normal (cosθ, 0, −sinθ)); the planner commands it, the bridges solve the joints with the "
    "calibrated bases, the true arms put the sheet where the true kinematics of those joints say.",
    "Pushed sheet: the home pose; the finger is commanded to S behind the commanded sheet centre along its "
    "normal; the true depth and contact point follow from the true sheet plane; tracking is perfect.",
    f"Clamp stretch {STRETCH} in both (the planner's for the default 30 N/m object).",
    "Sizes on the imaginary screen seen from the eye: h at the centre column, u/d 10 % of h inside the "
    "top/bottom edges, w at the middle row; 0.5-crossings of the anti-aliased photograph. corrected_mm = "
    "mean absolute size error of the model the renderer picks; position_mm = shift of the image's centre.",
    "The measurement camera sits at the paper's fixed viewpoint V (geometry.EYE); the renderer draws for the "
    "eye of display.yaml.",
    "The drawn object is the rigid cylinder (the paper draws the FEM-deformed one; its outline barely "
    "moves).",
]

MODEL_LABELS = {"none": "uncorrected", "flat": "flat", "four_triangle": "four_triangle", "fine": "fine",
                "fem_nominal": "fem_nominal"}
