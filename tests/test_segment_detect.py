"""Still intervals and turns found in continuous recordings: a real hand session (imucal's
Ferraris example, sections annotated by its authors) and a synthetic one with known truth."""
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from station.io.scheme import load_scheme
from station.io.segment_detect import detect, match, still_mask

DATA = Path(__file__).resolve().parent / "data" / "imucal"
RATE = 102.4
STATIC_UP = {"x_p": "xup", "x_a": "xdown", "y_p": "yup", "y_a": "ydown", "z_p": "zup", "z_a": "zdown"}
TURNS = {"x_rot": "turnx", "y_rot": "turny", "z_rot": "turnz"}


@pytest.mark.skipif(not DATA.exists(), reason="tests/data/imucal not present")
def test_the_imucal_session_is_split_where_its_authors_annotated_it():
    raw = np.genfromtxt(DATA / "example_ferraris_session.csv", delimiter=",", names=True)
    gyro = np.column_stack([raw["gyr_x"], raw["gyr_y"], raw["gyr_z"]])
    accel = np.column_stack([raw["acc_x"], raw["acc_y"], raw["acc_z"]])
    t = np.arange(len(raw)) / RATE
    sections = json.loads((DATA / "example_ferraris_session_list.json").read_text())
    det = detect(t, accel, gyro)
    assert len(det.statics()) >= 6 and len(det.motions()) == len(det.statics()) - 1
    found = match(det, load_scheme("manual6").segments)
    assert set(found) == set(STATIC_UP.values()) | set(TURNS.values())
    for label, name in STATIC_UP.items():          # every annotated static lies in a detected one
        sec, (iv, _) = sections[label], found[name]
        same_face = [s for s in det.statics() if float(s.up @ iv.up) > 0.99]
        assert any(s.start <= sec["start"] + 10 and sec["end"] - 10 <= s.stop for s in same_face), label
    for label, name in TURNS.items():               # and every annotated turn in the matched motion
        sec, (iv, sign) = sections[label], found[name]
        assert iv.start <= sec["start"] and sec["end"] <= iv.stop, label
        assert sign == -1.0                           # clockwise seen from above: imucal's -360 deg
        assert iv.angle == pytest.approx(360.0, rel=0.05)     # raw gyro: its scale errors are ~1 %
    np.testing.assert_allclose(det.gyro_bias, [-0.60, -0.37, 0.06], atol=0.02)   # imucal: -0.60/-0.37/0.06


def synthetic_session(seed=0, rate=100.0, bias=(0.3, -0.5, 0.2), noise=(0.02, 0.05)):
    """Six faces at random headings (10 s each), 90/180-degree moves between them, then three
    whole turns about the vertical, each as four quarter turns with short pauses.  Returns
    t, accel, gyro and the truth: (kind, name, first, last sample, up or axis)."""
    rng = np.random.default_rng(seed)
    g = 9.81
    dt = 1.0 / rate
    att = [Rotation.identity()]                       # body -> ENU of the samples so far
    truth = []

    def still(seconds, kind=None, name=None, vec=None):
        n = int(seconds * rate)
        first = len(att)
        att.extend([att[-1]] * n)
        if kind:
            truth.append((kind, name, first, len(att) - 1, vec))

    def rotate_to(target, seconds):
        n = int(seconds * rate)
        key = Slerp([0, 1], Rotation.concatenate([att[-1], target]))
        s = np.linspace(0, 1, n + 1)[1:]
        att.extend(list(key(0.5 - 0.5 * np.cos(np.pi * s))))

    def face(up):
        up = np.asarray(up, float)
        r, _ = Rotation.align_vectors([[0, 0, 1]], [up])
        return Rotation.from_euler("z", rng.uniform(0, 360), degrees=True) * r

    faces = {"xup": (1, 0, 0), "xdown": (-1, 0, 0), "yup": (0, 1, 0), "ydown": (0, -1, 0),
             "zup": (0, 0, 1), "zdown": (0, 0, -1)}
    still(3.0)
    for name, up in faces.items():
        rotate_to(face(up), 1.5)
        still(12.0, "static", name, up)
    for name, axis in (("turnx", (1, 0, 0)), ("turny", (0, 1, 0)), ("turnz", (0, 0, 1))):
        rotate_to(face(axis), 1.5)
        still(4.0)
        first = len(att)
        for quarter in range(4):
            if quarter:
                still(0.4)
            rotate_to(Rotation.from_euler("z", 90, degrees=True) * att[-1], 1.0 + 0.3 * quarter)
        truth.append(("rotation", name, first, len(att) - 1, axis))
        still(4.0)
    C = Rotation.concatenate(att)
    # body rates from consecutive attitudes (exact for the sampled motion), accel from gravity
    w = (C[:-1].inv() * C[1:]).as_rotvec(degrees=True) / dt
    gyro = np.vstack([w, w[-1:]]) + bias + rng.normal(0, noise[1], (len(C), 3))
    accel = C.inv().apply([0, 0, g]) + rng.normal(0, noise[0], (len(C), 3))
    return np.arange(len(C)) * dt, accel, gyro, truth


def test_a_synthetic_session_is_found_and_matched():
    t, accel, gyro, truth = synthetic_session()
    det = detect(t, accel, gyro)
    np.testing.assert_allclose(det.gyro_bias, [0.3, -0.5, 0.2], atol=0.01)
    found = match(det, load_scheme("manual6").segments)
    assert set(found) == {name for _, name, *_ in truth}
    for kind, name, first, last, vec in truth:
        iv, sign = found[name]
        if kind == "static":
            assert first <= iv.start and iv.stop - 1 <= last and iv.stop - iv.start > 10 * 100
            assert np.degrees(np.arccos(iv.up @ vec)) < 0.1
        else:
            # the whole turn, quarter pauses included, from rest to rest
            assert iv.start <= first and last <= iv.stop and iv.stop - iv.start < (last - first) + 200
            assert iv.angle == pytest.approx(360.0, abs=0.5)
            assert np.degrees(np.arccos(iv.axis @ vec)) < 0.5 and sign == 1.0


def test_a_slow_steady_turn_is_not_still():
    n, rate = 2000, 100.0
    rest = np.tile([0.0, 0.0, 9.81], (n, 1))
    turning = np.tile([0.0, 0.0, 5.0], (n, 1)) + [0.1, -0.2, 0.05]        # 5 deg/s about up, plus bias
    window = 51
    assert still_mask(rest, np.tile([0.1, -0.2, 0.05], (n, 1)), window, accel_threshold=0.05,
                      gyro_threshold=0.5, bias=np.array([0.1, -0.2, 0.05]), rate_threshold_dps=1.0).all()
    assert still_mask(rest, turning, window, accel_threshold=0.05, gyro_threshold=0.5).all()   # no spread...
    assert not still_mask(rest, turning, window, accel_threshold=0.05, gyro_threshold=0.5,
                          bias=np.array([0.1, -0.2, 0.05]), rate_threshold_dps=1.0).any()  # ...but it turns
    t = np.arange(3 * n) / rate
    det = detect(t, np.vstack([rest] * 3), np.vstack([np.tile([0.1, -0.2, 0.05], (n, 1)), turning,
                                                       np.tile([0.1, -0.2, 0.05], (n, 1))]))
    assert [i.kind for i in det.intervals] == ["static", "motion", "static"]
    assert det.motions()[0].angle == pytest.approx(5.0 * n / rate, rel=0.02)
