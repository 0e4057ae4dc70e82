"""station.model.geometry.distinct_directions with every head compared at once (issue 27 item 4:
one pair at a time in Python was quadratic in the poses) gives the labels of the pairwise loop it
replaced, kept here as the reference."""
import numpy as np
import pytest

from station.model.geometry import ATTITUDE_TOLERANCE_DEG, distinct_directions


def _reference(vectors, tolerance_deg=ATTITUDE_TOLERANCE_DEG):
    v = np.asarray(vectors, float).reshape(-1, 3)
    n = np.linalg.norm(v, axis=1)
    u = v / np.where(n > 0, n, 1.0)[:, None]
    cos_tol = np.cos(np.radians(tolerance_deg))
    labels = np.full(len(u), -1, int)
    heads = []
    for i, d in enumerate(u):
        for k, h in enumerate(heads):
            if d @ h >= cos_tol:
                labels[i] = k
                break
        else:
            labels[i] = len(heads)
            heads.append(d)
    return labels


@pytest.mark.parametrize("seed", range(4))
def test_the_same_labels_as_the_pairwise_loop(seed):
    rng = np.random.default_rng(seed)
    random_dirs = rng.standard_normal((600, 3))                        # ~300 clusters at 5 degrees
    faces = np.repeat(np.vstack([np.eye(3), -np.eye(3)]), 20, axis=0)  # hand poses on faces,
    faces = faces * 9.8 + rng.normal(0, 0.1, faces.shape)              # a degree or so apart
    for v in (random_dirs, faces, np.vstack([faces, random_dirs])[rng.permutation(720)],
              np.zeros((3, 3)), np.empty((0, 3))):
        got = distinct_directions(v)
        np.testing.assert_array_equal(got, _reference(v))
    assert distinct_directions(faces).max() + 1 == 6
