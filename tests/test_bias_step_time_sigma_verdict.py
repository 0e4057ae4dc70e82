"""Review of issue 28: a failing fit's verdict multiplies every 1-sigma by sqrt(reduced chi2); the
bias step's time's 1-sigma (step_time_s_sigma, written in the effect's state from the fit's
covariance at the nominal noise, station.estimate.lsq._held_values_freed) is one of them."""
import numpy as np

from station.estimate.verdict import _verdict
from station.model.calibration import Calibration


def calibration(chi2, dof=100):
    eye = np.eye(3)
    cal = Calibration("m/s^2", "deg/s", np.ones(3), eye, np.zeros(3), np.ones(3), eye, np.zeros(3), eye)
    cal.fit = {"method": "lsq", "chi2": float(chi2), "dof": dof}
    cal.sigma = {"accel_bias_x": 10.0, "gyro_bias_step_z": 2.0}
    cal.effect_compensation = [{"id": "bias_step", "source": "library", "parameters": {"gyro_bias_step_z": 8.0},
                                "state": {"step_time_s": 300.0, "segment": "pos09", "step_time_s_sigma": 1.5}}]
    return cal


def test_a_failing_fit_widens_the_step_times_1_sigma_as_every_other():
    cal = calibration(400.0)                       # reduced chi2 4: fails, every 1-sigma x2
    _verdict(cal)
    assert cal.fit["verdict"]["result"] == "fails"
    scale = cal.fit["sigma_scale"]
    assert scale == np.sqrt(4.0) and cal.sigma["gyro_bias_step_z"] == 2.0 * scale
    assert cal.effect_compensation[0]["state"]["step_time_s_sigma"] == 1.5 * scale


def test_a_passing_fit_keeps_the_step_times_1_sigma():
    cal = calibration(100.0)
    _verdict(cal)
    assert cal.fit["verdict"]["result"] == "passes"
    assert cal.effect_compensation[0]["state"]["step_time_s_sigma"] == 1.5
