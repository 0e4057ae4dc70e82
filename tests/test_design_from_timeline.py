"""station design --from with an effect in the time (bias_drift, bias_step) or the temperature
(temperature_bias) (issue 28, twentieth session):
the extension's segments are recorded after the capture's end, so the search informs the drift
of each at the time it will have there (the capture's last sample, the resumed warm-up, its
place in the extension), and the capture's own segments at theirs -- before, every candidate
was informed at its time in the candidates' own simulated capture, and the estimator then did
not confirm what the search proposed (exit 2).

The reference shares no code with the placement: the extension is recorded into the capture by
`station run --sim --append` (the dry run's bench clock, its resumed warm-up), and the
estimator's least-squares information of that recorded capture, weighted with the noise the
design used, gives each drift's 1σ."""
import json
import shutil

import numpy as np
import pytest

from station.bench.config import load_config
from station.cli import main
from station.cli.run import table_geometry
from station.estimate import lsq
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.io.scheme import load_scheme, scheme_from_text
from station.model import LIBRARY
from station.simulate import dryrun

SCHEME = """\
name: long statics
defaults: {dwell_s: 60.0, rate_dps: 100.0, rotation_s: 3.6}
segments:
  - {static: zup, up_body: [0, 0, 1]}
  - {static: zdown, up_body: [0, 0, -1]}
  - {static: xup, up_body: [1, 0, 0]}
  - {static: xdown, up_body: [-1, 0, 0]}
  - {static: yup, up_body: [0, 1, 0]}
  - {static: ydown, up_body: [0, -1, 0]}
  - {static: xy, up_body: [1, 1, 0]}
  - {static: yz, up_body: [0, 1, 1]}
  - {static: xz, up_body: [1, 0, 1]}
  - {rotation: rx, axis_body: [1, 0, 0]}
  - {rotation: ry, axis_body: [0, 1, 0]}
  - {rotation: rz, axis_body: [0, 0, 1]}
"""
# a warm-up with a slope rule: the append waits it again (one window on the warm IMU) before the
# extension, which the placement must count
CONFIG = """\
version: 1
imu:
  rate_hz: 10
table:
  axes: 3
  limits: [{max_rate_dps: 300, max_accel_dps2: 300, move_rate_dps: 60, move_accel_dps2: 60, rate_accel_dps2: 100}]
run:
  operator: false
  settle_s: 1
warmup:
  duration_s: 60
  temp_slope_c_per_h: 6
  window_s: 20
  max_s: 2000
"""


# the simulated IMU's accelerometer biases step by (300, -200, 250) µg between xy and yz (the
# bench's clock: the warm-up, then a static every 75 s from 285 s)
STEP_UG, STEP_TIME_S = [300.0, -200.0, 250.0], 802.0


@pytest.fixture(scope="module")
def dry_run(tmp_path_factory):
    """The capture (station run --sim's recording, without its estimate) and the configuration."""
    root = tmp_path_factory.mktemp("from-timeline")
    (root / "station.yaml").write_text(CONFIG)
    config = load_config(str(root / "station.yaml"))
    truth = dryrun.load_truth(None, 1)
    truth.accel.bias_step = np.array(STEP_UG)
    truth.accel.bias_step_time_s = STEP_TIME_S
    dryrun.record_scheme(scheme_from_text(SCHEME, "s.yaml"), truth, 1, root / "cap",
                         geometry=table_geometry(config.table), ramp_accel_dps2=dryrun.table_ramp_accel(config.table),
                         warmup=config.warmup)
    return root


def _design(dry_run, tmp_path, capsys, effect, reveal, fraction, dwells="60"):
    """A copy of the capture, station design --from's report and the extension recorded into the
    copy (station run --sim --append's recording, without its estimate)."""
    cap, out = tmp_path / "cap", tmp_path / "ext.yaml"
    shutil.copytree(dry_run / "cap", cap)
    config = str(dry_run / "station.yaml")
    capsys.readouterr()
    status = main(["design", "--from", str(cap), "--config", config, "--add", effect, "--reveal", reveal,
                   "--fraction", fraction, "--rates", "100", "--revolutions", "1", "--dwells", dwells, "-o", str(out),
                   "--json"])
    said = capsys.readouterr()
    assert status == 0, said.err
    table = load_config(config)
    dryrun.append_scheme(load_scheme(str(out)), out.read_text(), cap,
                         ramp_accel_dps2=dryrun.table_ramp_accel(table.table), warmup=table.warmup)
    return cap, json.loads(said.out)


def _sigma(cap, noise, effect) -> dict:
    """Each parameter's 1σ by the estimator's information of the recorded capture, weighted with
    the design's noise (densities to per-sample sigmas at the capture's rate); ``effect`` an
    instance (a bias step located as the capture located it)."""
    s = summarise(read_capture(cap, load_data=True), table_angle_arcsec=noise["table_angle_arcsec"])
    fs = s.sample_rate_hz
    s.accel_sigma = np.full(3, noise["accel_noise_ug"] * np.sqrt(fs) * 9.80665e-6)
    s.gyro_sigma = np.full(3, noise["gyro_noise_dph"] * np.sqrt(fs) / 3600.0)
    result = lsq.fit(s, [effect])
    names, index, factors, _ = lsq._reported_index(result, "m/s^2", "deg/s")
    cov = result.covariance_of(index) * np.outer(factors, factors)
    return dict(zip(names, np.sqrt(np.diag(cov))))


def test_design_from_informs_the_drift_after_the_captures_end(dry_run, tmp_path, capsys):
    """The accelerometers' drifts of a capture whose statics all come first are not revealed;
    the designer proposes segments after it, and the 1σ its search gives them is the one the
    estimator's information of the capture as recorded with them gives (measured: 0.1-0.3 %
    apart at 50 Hz, the recorded segments' times 5 ms from the placed ones; 1 % allowed) -- the
    capture's statics at the start, the extension after the capture's end and the resumed
    warm-up.  Before the change the estimator did not confirm the search's proposal (exit 2)."""
    cap, report = _design(dry_run, tmp_path, capsys, "bias_drift", "accel_bias_drift_*", "1")
    params = report["parameters"]
    assert len(params) == 3 and not any(p["revealed_before"] for p in params)
    assert all(p["revealed_after"] for p in params)
    recorded = _sigma(cap, report["noise"], LIBRARY["bias_drift"]())
    for p in params:
        ratio = p["sigma_searched"] / recorded[p["name"]]
        assert abs(ratio - 1.0) < 1e-2, (p["name"], ratio)
        assert abs(p["sigma_after"] / recorded[p["name"]] - 1.0) < 1e-2        # the estimator's check too


def test_design_from_a_capture_with_a_bias_step_adds_segments_after_it(dry_run, tmp_path, capsys):
    """A bias step located in the capture (inside a static or between two, as the estimator
    locates it) is not revealed where every attitude is visited once; segments added after the
    capture's end are all after the step, and the capture's own before or after it where it was
    located, so the search's 1σ is the estimator's information of the capture recorded with them
    with the step at that time (measured 0.1-0.4 %; 1 % allowed).  Before the change bias_step
    was refused by --from (exit 2)."""
    from station.estimate import profile

    cap, report = _design(dry_run, tmp_path, capsys, "bias_step", "accel_bias_step_*", "0.5")
    params = report["parameters"]
    # the design takes the step's time as known where the capture located it, while the estimate
    # counts that time's uncertainty (issue 28: its 1σ up to ~1.5x the time-known one for a
    # step of a few σ): the notes say the prediction holds the time (review of step28)
    assert any("bias_step" in n and "time as known" in n for n in report["notes"]), report["notes"]
    assert len(params) == 3 and not any(p["revealed_before"] for p in params)
    assert all(p["revealed_after"] for p in params)
    step = LIBRARY["bias_step"]()          # where the estimator locates it in the capture alone
    profile.locate(lsq.fit(lsq.summarise(read_capture(dry_run / "cap", load_data=True)), []), step)
    recorded = _sigma(cap, report["noise"], step)
    for p in params:
        ratio = p["sigma_searched"] / recorded[p["name"]]
        assert abs(ratio - 1.0) < 1e-2, (p["name"], ratio)
        assert abs(p["sigma_after"] / recorded[p["name"]] - 1.0) < 1e-2


def test_design_from_informs_temperature_after_the_captures_end(dry_run, tmp_path, capsys):
    """An accelerometer bias in the temperature: the capture's segments informed at their recorded
    temperatures, the extension's at the simulated IMU's warm-up after the capture's end (it goes
    on warming: 26.41-26.47 degC over the first six added turns), so the search's 1σ is the
    estimator's information of the capture recorded with them (measured: x 0.9996, z 1.0137 -- a
    turn pair informed at its two segments' mean temperature, each segment fitted at its own;
    2 % allowed).  Before the change the estimator did not confirm the proposal (exit 2)."""
    cap, report = _design(dry_run, tmp_path, capsys, "temperature_bias", "accel_bias_tempco_x,accel_bias_tempco_z",
                          "1", dwells="60,300")
    params = report["parameters"]
    assert len(params) == 2 and not any(p["revealed_before"] for p in params)
    assert all(p["revealed_after"] for p in params)
    recorded = _sigma(cap, report["noise"], LIBRARY["temperature_bias"]())
    for p in params:
        assert abs(p["sigma_searched"] / recorded[p["name"]] - 1.0) < 2e-2, p
        assert abs(p["sigma_after"] / recorded[p["name"]] - 1.0) < 1e-2, p


def test_design_from_refuses_time_effects_on_a_capture_whose_clock_went_back(dry_run, tmp_path, capsys):
    """An IMU stamping its samples with its own clock (time since power-on), switched off and on
    between two sessions of the capture: the later session's segments are stamped earlier than
    the first's (here from yup on, 560 s earlier: yup at 25 s, xdown ended at 570 s).  The
    capture's clock then interleaves the sessions, and an extension recorded next goes on from the
    newest session's clock, not after the largest stamp: there is no timeline to place a drift or
    a step on, and a design on it says what the estimator will not.  station design --from says so
    in one line, exit 2 (the same check for bias_drift and the temperature's effects).  (Review of the twentieth session: the extension was placed after the
    largest stamp, 570 s, and the step "located between zup and xz", two segments of different
    sessions overlapping in time.)"""
    import yaml

    cap = tmp_path / "cap"
    shutil.copytree(dry_run / "cap", cap)
    manifest = yaml.safe_load((cap / "manifest.yaml").read_text())
    names = [s["name"] for s in manifest["segments"]]
    for s in manifest["segments"]:
        s.pop("sha256", None)
        if names.index(s["name"]) >= names.index("yup"):
            lines = (cap / s["file"]).read_text().splitlines()
            moved = [lines[0]] + [f"{float(x.split(',', 1)[0]) - 560.0:.3f}," + x.split(",", 1)[1] for x in lines[1:]]
            (cap / s["file"]).write_text("\n".join(moved) + "\n")
    (cap / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    capsys.readouterr()
    status = main(["design", "--from", str(cap), "--config", str(dry_run / "station.yaml"), "--add", "bias_step",
                   "--reveal", "accel_bias_step_*", "--fraction", "1", "--rates", "100", "--revolutions", "1", "--dwells", "60",
                   "-o", str(tmp_path / "ext.yaml")])
    said = capsys.readouterr()
    assert status == 2, said.out
    assert "clock went back" in said.err and "Traceback" not in said.err, said.err
    assert not (tmp_path / "ext.yaml").exists()


def test_design_from_places_the_extension_after_an_aborted_segment(dry_run, tmp_path, capsys):
    """A capture whose last segment was aborted (a static of which 250 s were recorded, kept
    incomplete: the estimator leaves it out): the bench's clock went on through it, so the
    extension recorded next comes after its samples, not after the last complete segment.  The
    search's 1σ of the drifts is then the estimator's information of the capture recorded with the
    extension (1 % allowed, as above).  (Review of the twentieth session: placed after the last
    complete segment, the search's 1σ was 1.25-1.43x the recorded capture's.)"""
    import yaml

    src = tmp_path / "src"
    shutil.copytree(dry_run / "cap", src)
    manifest = yaml.safe_load((src / "manifest.yaml").read_text())
    last = max(float((src / s["file"]).read_text().split()[-1].split(",")[0]) for s in manifest["segments"])
    rows = (src / "zup.csv").read_text().splitlines()
    rate = read_capture(src).imu.sample_rate_hz
    n = int(250 * rate)
    body = [f"{last + 16.0 + k / rate:.3f}," + rows[1 + k % (len(rows) - 1)].split(",", 1)[1] for k in range(n)]
    (src / "abort.csv").write_text("\n".join([rows[0]] + body) + "\n")
    manifest["segments"].append({"name": "abort", "kind": "static", "file": "abort.csv", "status": "incomplete",
                                 "up_body": [0.0, 0.0, 1.0]})
    (src / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(dry_run / "station.yaml", run / "station.yaml")
    shutil.copytree(src, run / "cap")
    cap, report = _design(run, tmp_path / "x", capsys, "bias_drift", "accel_bias_drift_*", "1")
    recorded = _sigma(cap, report["noise"], LIBRARY["bias_drift"]())
    for p in report["parameters"]:
        assert abs(p["sigma_searched"] / recorded[p["name"]] - 1.0) < 1e-2, (p["name"], p["sigma_searched"],
                                                                              recorded[p["name"]])
        assert abs(p["sigma_after"] / recorded[p["name"]] - 1.0) < 1e-2
