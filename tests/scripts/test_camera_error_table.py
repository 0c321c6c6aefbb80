"""scripts/camera_error_table.py: what a run's camera correction left of the error its views were given, from the
run's record; checked against the records' own conventions (rigid motions about the view's optical centre): a
correction built as the error's inverse, and a point moved by the error alone."""

import math

import numpy as np
from scipy.spatial.transform import Rotation

from tests.scriptfiles import load_script

CENTRE = np.array([0.5, -0.25, 1.29])
MIDDLE = np.array([0.5, 0.0, 0.16])


def _motion(rotvec_deg, translation_mm) -> dict:
    return {"rotation_deg": list(rotvec_deg), "translation_mm": list(translation_mm), "origin": CENTRE.tolist()}


def _inverse(motion: dict) -> dict:
    """The motion about CENTRE (the optical centre) that undoes ``motion``: R^-1 and -R^-1 t."""
    R = Rotation.from_rotvec(np.radians(motion["rotation_deg"]))
    t = np.asarray(motion["translation_mm"])
    return _motion(np.degrees(R.inv().as_rotvec()), -R.inv().apply(t))


def test_a_correction_that_undoes_the_error_leaves_nothing_and_none_leaves_the_error():
    table = load_script("camera_error_table")
    error = _motion([0.3, -0.6, 0.7], [4.0, -3.0, 2.5])
    record = {"camera_error": {"views": {"fixed": error}},
              "camera_corrections": {"enough": True, "captures": [_inverse(error)]}}
    (left, turn, level, vertical), = table.left_of(record, MIDDLE)
    assert left < 1e-9 and turn < 1e-9 and level < 1e-9 and vertical < 1e-9
    record["camera_corrections"]["captures"] = [_motion([0, 0, 0], [0, 0, 0])]
    (left, turn, level, vertical), = table.left_of(record, MIDDLE)
    R = Rotation.from_rotvec(np.radians(error["rotation_deg"]))
    moved = CENTRE + R.apply(MIDDLE - CENTRE) + np.asarray(error["translation_mm"]) / 1e3
    assert math.isclose(left, np.linalg.norm(moved - MIDDLE) * 1e3, rel_tol=1e-9)
    assert math.isclose(turn, np.linalg.norm([0.3, -0.6, 0.7]), rel_tol=1e-9)
    assert math.isclose(level, np.linalg.norm([0.3, -0.6]), rel_tol=1e-9) and math.isclose(vertical, 0.7, rel_tol=1e-9)


def test_a_calibrated_cameras_correction_is_what_is_left_and_no_correction_is_nothing():
    table = load_script("camera_error_table")
    fix = _motion([0.0, 0.0, -0.4], [1.0, 0.0, 0.0])
    (left, turn, _, vertical), = table.left_of({"camera_corrections": {"enough": True, "captures": [fix]}}, MIDDLE)
    R = Rotation.from_rotvec(np.radians([0.0, 0.0, -0.4]))
    moved = CENTRE + R.apply(MIDDLE - CENTRE) + [0.001, 0.0, 0.0]
    assert math.isclose(left, np.linalg.norm(moved - MIDDLE) * 1e3, rel_tol=1e-9)
    assert math.isclose(turn, 0.4, rel_tol=1e-9) and math.isclose(vertical, 0.4, rel_tol=1e-9)
    assert table.left_of({"camera_corrections": {"enough": False, "captures": [fix]}}, MIDDLE) == []
    assert table.left_of({}, MIDDLE) == []
