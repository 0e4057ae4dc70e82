"""Review of issue 28's twentieth session (branch vib28): the separation of an offset per axis group
from a vibration once per revolution by recorded ramps rests on how the vibration behaves through the
ramp.  A table's once-per-revolution vibration is driven by its turning (an imbalance's force is
m e w^2 across and m e dw/dt along the platter; a bearing's runout is a displacement whose
acceleration is d2/dt2 of it): a platter at rest does not vibrate.  The simulated table
(sim_devices/world.py table_vibration_enu) accelerated its base by cos(theta + phase) D whatever
the rate, so during a recorded ramp's rest the resting IMU sensed a constant acceleration D cos(phase);
since the twenty-first session the base's displacement is a function of the platter's angle and its
acceleration theta_dot^2 x'' + theta_ddot x': nothing at rest.  (The review's failing test, kept.)"""

import numpy as np

from sim_devices.bench import SimulatedBench
from sim_devices.truth import mems_truth


def test_a_table_at_rest_does_not_vibrate():
    segs = []
    for mg in ([0.0, 0.0, 0.0], [0.0, 10.0, 0.0]):
        truth = mems_truth(0)
        truth.bench.vibration_mg = np.array(mg)
        truth.bench.vibration_phase_deg = 0.0
        segs.append(SimulatedBench(truth, seed=3).rotation([1, 0, 0], 100.0, 3.6, record_ramp="start",
                                                         ramp_accel_dps2=50.0, ramp_rest_s=0.5))
    quiet, shaken = segs
    assert np.array_equal(quiet.t, shaken.t)
    rest = quiet.t - quiet.t[0] < 0.4          # the table at rest (ramp_rest_s 0.5 s)
    assert rest.sum() > 10
    # the same noise draws: the difference is the vibration alone; at rest it must be nothing (here
    # 10 mg cos(0) = 98 mm/s^2 before the table moves)
    diff = np.abs(shaken.accel[rest] - quiet.accel[rest]).max()
    assert diff < 1e-9, diff
