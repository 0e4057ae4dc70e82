"""diagnose's words (station/diagnose/words.py): only a turn about a vertical axis *off every body
axis* separates the accelerometers' size effect from a table vibration (about a body axis the size
effect leaves nothing along the axis, and its constant across it is the vertical vibration's own:
this session's review found every position undetermined with no alias named)."""
import types

import numpy as np

from station.diagnose.words import _vertical_turns

G = 9.80665


def rotation(index, axis_body, up_body):
    """A steady rotation's harmonics: gravity (``up_body``, the specific force's direction in the
    case at the start) split along the axis (the mean) and across it (the first harmonic)."""
    l = np.asarray(axis_body, float) / np.linalg.norm(axis_body)
    f = G * np.asarray(up_body, float) / np.linalg.norm(up_body)
    along = (f @ l) * l
    across = f - along
    return types.SimpleNamespace(index=index, steady=True, axis_body=l, accel_dc=along,
                                 accel_cos=across, accel_sin=-np.cross(l, across))


def test_only_a_vertical_turn_off_the_body_axes_counts():
    level = rotation(0, [1, 0, 0], [0, 0, 1])
    about_z = rotation(1, [0, 0, 1], [0, 0, 1])
    diagonal = rotation(2, [1, 1, 1], [1, 1, 1])
    assert not _vertical_turns(types.SimpleNamespace(rotations=[level]))
    assert not _vertical_turns(types.SimpleNamespace(rotations=[level, about_z]))
    assert _vertical_turns(types.SimpleNamespace(rotations=[level, diagonal]))
