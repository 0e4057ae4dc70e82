"""Issue 28 review item 3: a recorded ramp's window checks that the table holds its state outside
the ramp's compiled time, as a steady turn's poll does (a read off the rate by more than 1 % stops
the run), and that a brake ends inside the window.  The twins have no fault that makes a rate sag
or a brake slow, so a small wrapper around the real table driver (over the twins' pseudo-terminal)
makes them: every other read of the turning axis 5 % low, or the brake at a tenth of the
configured acceleration.  In process, as tests/test_sequencer_safety.py."""
import numpy as np
import pytest

from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer
from station.bench.compile import compile_scheme
from station.bench.config import AxisConfig, Config, RunConfig, TableConfig
from station.bench.sequencer import SequencerError
from station.io.scheme import scheme_from_text
from test_sequencer_safety import Hands, new_writer, sequencer

SPEED = 8.0
ACCEL = 300.0


class Faulty:
    """The table driver with a fault: ``sag``: every other read of an axis turning faster than 50
    deg/s reports 95 % of its rate; ``slow_brake``: a rate-mode stop commanded at a tenth of the
    configured acceleration (the table brakes slower than station.yaml says)."""

    def __init__(self, inner, sag=False, slow_brake=False):
        self.inner, self.sag, self.slow_brake, self.reads = inner, sag, slow_brake, 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def read_rates_dps(self):
        rates = np.array(self.inner.read_rates_dps(), float)
        if self.sag:
            fast = np.abs(rates) > 50.0
            if fast.any():
                self.reads += 1
                if self.reads % 2 == 0:
                    rates[fast] *= 0.95
        return rates

    def set_rate(self, axis, rate_dps, **kw):
        if self.slow_brake and rate_dps == 0.0 and not kw.get("wait", True):      # the recorded brake
            self.inner.set_rate_limits(axis, "rate", self.inner.limits[axis - 1].max_rate_dps, ACCEL / 10.0)
        return self.inner.set_rate(axis, rate_dps, **kw)


def run_ramp(tmp_path, kind, wrap, rate_dps=100.0, rotation_s=3.6):
    """One recorded ramp of ``kind`` ("start"/"end") at ``rate_dps`` on the twins (speed SPEED,
    ACCEL deg/s^2), through the table driver ``wrap(table, bench)`` returns (a fault, a delay).
    Returns the sequencer (its ``console``: what it said)."""
    config = Config(table=TableConfig(axes=3, limits=tuple(
                        AxisConfig(max_rate_dps=300, max_accel_dps2=300, rate_accel_dps2=ACCEL) for _ in range(3))),
                    run=RunConfig(operator=False, settle_s=0.5, max_missing_fraction=0.02, max_gap_s=2.0))
    scheme = scheme_from_text(f"""name: r
defaults: {{dwell_s: 1, rate_dps: {rate_dps:g}, rotation_s: {rotation_s:g}}}
segments:
  - {{rotation: r, axis_body: [0, 0, 1], record_ramp: {kind}, pair: false}}
""", "r.yaml")
    plan = compile_scheme(scheme, config)
    with BenchServer(default_truth(11), BenchOptions(speed=SPEED, seed=11, axes=3, lossless=True)) as bench:
        seq, table, imu = sequencer(bench, config, new_writer(tmp_path / "cap"), Hands(bench, speed=SPEED))
        seq.table = wrap(table, bench)
        try:
            seq.run(plan.steps)
        finally:
            table.stop()
            table.close()
            imu.close()
    return seq


def _run(tmp_path, kind, **fault):
    run_ramp(tmp_path, kind, lambda table, bench: Faulty(table, **fault))


@pytest.mark.parametrize("kind", ["start", "end"])
def test_a_ramp_window_stops_when_the_rate_sags_outside_the_ramp(tmp_path, kind):
    """"start": the reads at the rate after the ramp; "end": those before the brake's command."""
    with pytest.raises(SequencerError, match="did not hold 100 deg/s while recording r outside its ramp"):
        _run(tmp_path, kind, sag=True)


def test_a_brake_slower_than_configured_stops_the_run(tmp_path):
    """The brake at 30 deg/s^2 instead of 300: 3.3 s instead of 0.33 s, past the window (0.33 s
    and 0.5 s at rest): a read after the compiled brake, still turning, stops the run."""
    with pytest.raises(SequencerError, match="did not hold at rest while recording r outside its ramp"):
        _run(tmp_path, "end", slow_brake=True)
