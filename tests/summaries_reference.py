"""The rotation summary as computed before it was computed in chunks (whole arrays, one numpy
operation over all samples at a time): the reference tests/test_summaries_chunked.py compares
station.estimate.summaries.rotation_summary with."""
import numpy as np

from station.core.errors import UserError
from station.estimate.summaries import EDGE_SAMPLES, MAX_GRAM_CONDITION, STEADY_SPREAD, RotationSummary, _window


def _turned_fraction(t, gyro, start, duration) -> np.ndarray:
    """Fraction of the segment's turn reached at each sample, from the gyro's own integral about
    its mean rate direction (scale errors cancel in the ratio; a rate that ripples or drifts is
    followed, where a uniform rate would smear the harmonics)."""
    direction = gyro.mean(axis=0)
    norm = np.linalg.norm(direction)
    if norm == 0:
        return (t - start) / duration
    rate = gyro @ (direction / norm)
    dt = np.diff(t)
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)])
    turned += 0.5 * rate[0] * (t[1] - t[0])                    # from the window's start
    total = turned[-1] + 0.5 * rate[-1] * (t[-1] - t[-2])
    return turned / total if total != 0 else (t - start) / duration


def _phase_fraction(t, gyro, start, duration, gyro_sigma_dps):
    """Fraction of the turn at each sample: from the gyro when the rate really varies, else
    uniform in time.  Integrating the gyro adds its noise as a random walk of the phase (pinned
    at both ends: RMS sigma sqrt(dt T / 6)); over a few revolutions that wander projects onto the
    harmonics.  So the gyro-tracked phase is used only where its departure from a uniform phase is
    more than three times that noise, i.e. where the rate ripples or drifts."""
    tracked = _turned_fraction(t, gyro, start, duration)
    uniform = (t - start) / duration
    if gyro_sigma_dps is None:
        return tracked
    rate = np.linalg.norm(gyro.mean(axis=0))
    if rate == 0:
        return tracked
    dt = duration / len(t)
    noise_deg = float(np.max(gyro_sigma_dps)) * np.sqrt(dt * duration / 6.0)
    departure_deg = float(np.sqrt(np.mean(((tracked - uniform) * rate * duration) ** 2)))
    return tracked if departure_deg > 3.0 * noise_deg else uniform


def _rate(t, gyro, gyro_bias, angle_deg, duration):
    """The table rate (rad/s, signed like the angle) at each sample: the gyro along its mean
    direction (bias removed), rescaled to the encoder's mean rate."""
    g = gyro - (0.0 if gyro_bias is None else gyro_bias)
    direction = g.mean(axis=0)
    norm = np.linalg.norm(direction)
    mean_rate = np.radians(angle_deg) / duration
    if norm == 0 or len(t) < 3:
        return np.full(len(t), mean_rate)
    along = g @ (direction / norm)
    return along * (mean_rate / along.mean())


def _least_squares(basis, columns):
    """Least-squares coefficients (k, m) of ``columns`` (N, m) on the basis functions, given as
    the rows of ``basis`` (k, N).

    Through the normal equations (matrix products over the N samples, then a k x k solve): the
    harmonic basis of a turn is nearly orthogonal over whole revolutions, so its Gram matrix is
    well conditioned and this matches an SVD solution to about cond * 1e-16 while costing a
    fraction of it; a basis whose Gram matrix is worse conditioned than MAX_GRAM_CONDITION (a
    short sweep) goes to the SVD solver (numpy.linalg.lstsq)."""
    gram = basis @ basis.T
    if np.linalg.cond(gram) < MAX_GRAM_CONDITION:
        return np.linalg.solve(gram, np.column_stack([basis @ c for c in columns]))
    return np.linalg.lstsq(basis.T, np.column_stack(columns), rcond=None)[0]


def _contiguous_columns(matrix):
    return [np.ascontiguousarray(matrix[:, k]) for k in range(matrix.shape[1])]


def rotation_summary(name, axis_body, group, angle_deg, t, accel, gyro, temp,
                     gyro_sigma_dps=None, gyro_bias=None) -> RotationSummary:
    """``gyro_sigma_dps``: per-sample white gyro noise (deg/s); with it the phase is tracked by
    the gyro only where the rate varies beyond what that noise would make it seem to.
    ``gyro_bias``: a rough gyro bias (the statics' mean), removed before the rate's shape is taken."""
    if len(t) < 8:
        raise UserError(f"segment '{name}': a rotation segment needs at least 8 samples")
    start, end = _window(t)
    duration = end - start
    # trapezoid over the samples plus half a sample at each end: the integral over the window
    gyro_integral = (np.trapezoid(gyro, t, axis=0)
                     + 0.5 * (gyro[0] * (t[1] - t[0]) + gyro[-1] * (t[-1] - t[-2])))
    phase = np.radians(angle_deg) * _phase_fraction(t, gyro, start, duration, gyro_sigma_dps)
    basis = np.empty((5, len(t)))          # rows: 1, cos phi, sin phi, cos 2phi, sin 2phi
    basis[0] = 1.0
    np.cos(phase, out=basis[1])
    np.sin(phase, out=basis[2])
    np.multiply(basis[1], basis[1], out=basis[3])
    basis[3] -= basis[2] * basis[2]
    np.multiply(basis[1], basis[2], out=basis[4])
    basis[4] *= 2.0
    del phase
    # The table rate w(t) about the axis, its square and its time derivative are projected on the
    # same basis as the accelerometer (one solve for all of them)
    w = _rate(t, gyro, gyro_bias, angle_deg, duration)
    coefs = _least_squares(basis, _contiguous_columns(accel) + [w, w * w, np.gradient(w, t)])
    gram = basis @ basis.T / len(t)
    del basis, w
    coef, rate_coefs = coefs[:, :3], (coefs[:, 3], coefs[:, 4], coefs[:, 5])
    edge = min(EDGE_SAMPLES, len(t) // 4)
    magnitude = np.linalg.norm(gyro, axis=1)
    steady = bool(np.std(magnitude) < STEADY_SPREAD * np.mean(magnitude))
    rate_sq_factor = float(np.mean(magnitude**2) / np.mean(magnitude) ** 2)
    return RotationSummary(name=name, axis_body=axis_body, group=group, angle_deg=float(angle_deg),
                           duration_s=float(duration), samples=len(t), accel_dc=coef[0],
                           accel_cos=coef[1], accel_sin=coef[2], accel_cos2=coef[3],
                           accel_sin2=coef[4], gyro_integral=gyro_integral,
                           temp_c=None if temp is None else float(np.mean(temp)),
                           gyro_start=gyro[:edge].mean(axis=0), gyro_end=gyro[-edge:].mean(axis=0),
                           steady=steady, rate_sq_factor=rate_sq_factor,
                           rate_coef=rate_coefs[0], rate_sq_coef=rate_coefs[1], rate_dot_coef=rate_coefs[2],
                           gram=gram)


