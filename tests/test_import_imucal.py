"""``station import imucal``: real imucal sessions into capture bundles; bad input refused."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from station import cli
from station.io.capture import read_capture
from station.core.errors import UserError
from station.estimate import estimate_capture
from station.io.importers import imucal

DATA = Path(__file__).resolve().parent / "data" / "imucal"
SESSION = DATA / "example_ferraris_session.csv"
SECTIONS = DATA / "example_ferraris_session_list.json"
ANNOTATED = DATA / "annotated_session.csv"

pytestmark = pytest.mark.skipif(not SESSION.exists(), reason="tests/data/imucal not present")


def test_session_round_trip(tmp_path):
    path = imucal.import_imucal(SESSION, tmp_path / "cap", rate_hz=102.4, sections_path=SECTIONS)
    capture = read_capture(path)
    assert capture.warnings == []
    assert (capture.imu.sample_rate_hz, capture.imu.accel_unit, capture.imu.gyro_unit) == (102.4, "m/s^2", "deg/s")
    spans = json.loads(SECTIONS.read_text())
    assert [s.name for s in capture.segments] == list(spans)           # the JSON is in time order
    raw = np.genfromtxt(SESSION, delimiter=",", names=True)
    for seg in capture.segments:
        start, end = spans[seg.name]["start"], spans[seg.name]["end"]
        rows = raw[start:end]
        assert len(seg.data.t) == end - start
        np.testing.assert_allclose(seg.data.t, rows["n_samples"] / 102.4, rtol=0, atol=1e-9)
        np.testing.assert_allclose(seg.data.accel, np.column_stack([rows[c] for c in imucal.ACC_COLS]), rtol=1e-11)
        np.testing.assert_allclose(seg.data.gyro, np.column_stack([rows[c] for c in imucal.GYR_COLS]), rtol=1e-11)
        if seg.kind == "static":
            up = np.array(imucal.STATIC_UP[seg.name], float)
            np.testing.assert_array_equal(seg.up_body, up)
            assert seg.data.accel.mean(axis=0) @ up > 9.0                 # that axis does see +1 g
        else:
            assert seg.kind == "rotation" and seg.angle_deg is None
            np.testing.assert_array_equal(seg.axis_body, imucal.ROTATION_AXIS[seg.name])
            assert seg.rate_dps < 0                                        # clockwise: negative
            assert "-360 deg in imucal's convention" in seg.note and "indeed clockwise" in seg.note
            assert seg.rate_dps == pytest.approx(-360.0 / ((end - start) / 102.4))
    assert capture.extra["import"]["gyro_kinematic_correlation"] > imucal.KINEMATIC_CONCLUSIVE


def test_gyro_integral_agrees_with_the_direction(tmp_path):
    """The bias-corrected gyro turns about -360 deg about each axis: right-handed negative."""
    capture = read_capture(imucal.import_imucal(SESSION, tmp_path / "c", rate_hz=102.4, sections_path=SECTIONS))
    bias = np.mean(np.vstack([s.data.gyro for s in capture.complete("static")]), axis=0)
    for seg in capture.complete("rotation"):
        turned = ((seg.data.gyro - bias) @ seg.axis_body).sum() / 102.4
        assert -380 < turned < -340, (seg.name, turned)


def test_annotated_session_detected_raw_and_inverted_gyro(tmp_path):
    path = imucal.import_imucal(ANNOTATED, tmp_path / "a", rate_hz=204.8)
    capture = read_capture(path)
    assert (capture.imu.accel_unit, capture.imu.gyro_unit) == ("raw", "raw")
    assert [s.name for s in capture.segments] == ["x_p", "x_a", "y_p", "y_a", "z_p", "z_a", "x_rot", "y_rot", "z_rot"]
    assert capture.extra["import"]["format"] == "annotated"
    # the raw gyro reads positive during the clockwise turns: it is inverted against the
    # accelerometers (imucal's own result for this file has R_g ~ -I); the direction stays negative
    assert capture.extra["import"]["gyro_kinematic_correlation"] < -imucal.KINEMATIC_CONCLUSIVE
    for seg in capture.complete("rotation"):
        assert seg.rate_dps < 0 and "reads inverted" in seg.note
        assert seg.data.gyro.mean(axis=0) @ seg.axis_body > 0
    assert capture.segment("x_p").data.accel.mean(axis=0)[0] > 2000            # ~2048 counts per g


def test_a_raw_gyro_without_a_scale_is_diagnosed_and_reported(tmp_path, capsys):
    """The annotated session (raw counts, hand turns without encoder angles): the diagnosis and the
    page are made (both refused the capture, naming an internal effect 'discovered_terms'), and
    say what the fit at its minimum says: untested, as the calibration file (no redundancy of the
    data's own).

    Its base fit (36 parameters, 54 rows; the gyro block of a raw gyro that nothing turned by a
    known angle, held by NO_ROTATION_PRIORS and the statics' Earth-rate magnitudes only) crept:
    scipy's MINPACK stopped at its limit of 1,000 evaluations at chi2 60.46 (reduced 10.1, which
    diagnose then printed as a model that fails, with the gyro terms 'searched in the
    accelerometers only').  Its minimum is chi2 1.0687 (reduced 0.178): where the fit ends, LM and
    trf with tolerances of 1e-15 gain less than 1e-9 (docs/method-lsq.md, fourteenth session)."""
    import re

    from scipy.optimize import least_squares

    from station.estimate import lsq
    from station.estimate.summaries import summarise

    path = imucal.import_imucal(ANNOTATED, tmp_path / "a", rate_hz=204.8)
    capsys.readouterr()
    assert cli.main(["diagnose", str(path)]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "discovered_terms" not in printed and "not converged" not in printed
    # the file's verdict: untested (a redundancy of 0.2 of its own; the 6 degrees of freedom counted
    # are the priors'), said by diagnose too since this session (it said "explains" on the 6)
    assert "untested: the data have no redundancy of their own" in printed
    # the fit diagnose shows is at its minimum: from where it ends a solver with far tighter
    # tolerances gains less than 0.01 of chi2, i.e. every parameter is within 0.1 sigma of the
    # minimum (chi2 - chi2_min = |delta / sigma|^2 near it); stopped early it was 59 (MINPACK's
    # limit) or 0.08 (LM resumed with the scales of its start, far off) above it
    fit = lsq.fit(summarise(read_capture(path)))
    assert fit.model.converged
    tight = least_squares(fit.model.residuals, fit.x, jac=fit.model.jacobian, method="trf", x_scale="jac",
                          xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    assert fit.chi2 - 2 * tight.cost < 0.01, (fit.chi2, 2 * tight.cost)
    # and that is the fit printed: its reduced chi2 to the 3 digits shown
    reduced = float(re.search(r"degrees of freedom \(reduced ([0-9.]+)", printed).group(1))
    assert abs(reduced - fit.chi2 / fit.dof) <= 0.0005 + 1e-9, (reduced, fit.chi2, fit.dof)
    assert cli.main(["report", str(path), "-o", str(tmp_path / "page.html")]) == 0
    page = (tmp_path / "page.html").read_text(encoding="utf-8")
    assert "discovered_terms" not in page and "untested: the data have no redundancy of their own" in page


def test_cli_import_and_what_station_can_estimate(tmp_path, capsys):
    out = tmp_path / "cli"
    assert cli.main(["import", "imucal", str(SESSION), "--sections", str(SECTIONS), "--rate-hz", "102.4",
                     "-o", str(out)]) == 0
    assert "x_rot" in capsys.readouterr().out
    # hand turns annotated apart from the statics: the hand-rotation terms need a static just
    # before and after each turn, so the gyros are not determined: an accelerometer-only
    # calibration that says why; the 2010 method needs nine attitudes and +/- pairs
    cal, _, _ = estimate_capture(out)
    notes = " ".join(cal.fit["notes"])
    assert "x_rot: hand rotation without a static segment just before and after" in notes
    assert "accelerometer-only calibration" in notes and cal.fit["gyro_calibrated"] is False
    # (tests/test_noise_groups.py's check, on this estimate of the same import) six poses, the
    # turns not usable: the fit counted 6 degrees of freedom and called the noise overestimated
    # (reduced chi2 0.03); the leverages say the data have none of their own (the 6 are the
    # priors'): untested
    assert cal.fit["data_redundancy"] < 0.5 and cal.fit["dof"] == 6
    assert cal.fit["verdict"]["result"] == "untested"
    assert "the data have no redundancy of their own" in cal.fit["verdict"]["reason"]
    assert any("the chi-square verdict is taken on the data's" in n for n in cal.fit["notes"])
    with pytest.raises(UserError, match="at least 9 static attitudes; the capture has 6"):
        estimate_capture(out, "zhang2010")
    assert cli.main(["estimate", str(out)]) == 0
    # station diagnose says the same: untested, not "the model explains the data" on the counted
    # degrees of freedom (the review's case: "explains, reduced chi2 0.030" before)
    capsys.readouterr()
    assert cli.main(["diagnose", str(out)]) == 0
    said = capsys.readouterr().out
    assert "untested: the data have no redundancy of their own" in said and "explains" not in said, said


def test_protocol_turn_lets_lsq_agree_with_imucal(tmp_path):
    """With imucal's assumptions made explicit (--turn-deg 360, 1 deg placement), the
    least-squares model reproduces imucal's published result within its printed digits."""
    path = imucal.import_imucal(SESSION, tmp_path / "c", rate_hz=102.4, sections_path=SECTIONS,
                                turn_deg=360.0)
    assert read_capture(path).segment("x_rot").angle_deg == -360.0
    cal, _, prov = estimate_capture(path)
    assert prov["method"] == "lsq"
    p = {n: v for n, v, _ in cal.parameters()}
    published = {"accel_scale": ([0.997, 1.002, 1.023], 1.0, 0.0005),
                 "accel_bias": ([0.54, -0.62, 0.40], 9.80665e-6, 0.005),
                 "gyro_bias": ([-0.60, -0.37, 0.06], 1 / 3600, 0.005)}
    for block, (values, unit, half_digit) in published.items():
        for a, v in zip("xyz", values):
            assert abs(p[f"{block}_{a}"] * unit - v) <= half_digit, (block, a, p[f"{block}_{a}"] * unit, v)
    # six poses cannot reveal the misalignments: their 1-sigma is the placement prior's size
    assert all(cal.sigma[f"accel_misalignment_{n}"] > 1000 for n in ("yz", "zy", "zx"))


# --- bad input -------------------------------------------------------------------------------------

def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def session_text(rows=20, **change):
    lines = ["n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z"]
    for i in range(rows):
        lines.append(f"{i},0.1,0.2,0.3,9.8,0.0,0.1")
    for lineno, text in change.items():
        lines[int(lineno[1:]) - 1] = text
    return "\n".join(lines) + "\n"


SECTIONS_OK = '{"x_p": {"start": 0, "end": 10}, "x_rot": {"start": 10, "end": 20}}'


@pytest.mark.parametrize("csv_text, sections, message", [
    ("n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y\n0,1,2,3,4,5\n", SECTIONS_OK,
     r"bad\.csv: line 1: column 'acc_z': required, missing"),
    (session_text(l5="4,0.1,abc,0.3,9.8,0.0,0.1"), SECTIONS_OK, r"bad\.csv: line 5: column 'gyr_y': not a number: 'abc'"),
    (session_text(l7="6,0.1,0.2,0.3,nan,0.0,0.1"), SECTIONS_OK, r"bad\.csv: line 7: column 'acc_x': not finite"),
    (session_text(l3="2,0.1,0.2,0.3,9.8,0.0"), SECTIONS_OK, r"bad\.csv: line 3: 6 fields, the header has 7"),
    (session_text(l4="1,0.1,0.2,0.3,9.8,0.0,0.1"), SECTIONS_OK, r"bad\.csv: line 4: column 'n_samples': sample number does not increase"),
    (session_text(), '{"x_p": {"start": 0, "end": 10},', r"sec\.json: line 1: not valid JSON"),
    (session_text(), '{"x_p": {"start": 0, "end": 25}}', r"sec\.json: field 'x_p': rows \[0, 25\) out of range: the CSV has 20"),
    (session_text(), '{"x_p": {"start": 5, "end": 5}}', r"sec\.json: field 'x_p': rows \[5, 5\) out of range"),
    (session_text(), '{"x_p": {"start": "0", "end": 5}}', r"sec\.json: field 'x_p.start': must be a whole row number"),
    (session_text(), '{"x_up": {"start": 0, "end": 5}}', r"sec\.json: field 'x_up': unknown section label"),
    (session_text(), '{"x_p": [0, 5]}', r"sec\.json: field 'x_p': must be an object"),
    (session_text(), '{"x_p": {"start": 0, "end": 12}, "x_a": {"start": 10, "end": 20}}', r"field 'x_a': overlaps section 'x_p'"),
    (session_text(), '[]', r"sec\.json: must be a JSON object"),
    ("", SECTIONS_OK, r"bad\.csv: empty file"),
])
def test_bad_session_input_refused_with_line_and_field(tmp_path, csv_text, sections, message):
    csv_path = write(tmp_path, "bad.csv", csv_text)
    json_path = write(tmp_path, "sec.json", sections)
    with pytest.raises(UserError, match=message):
        imucal.import_imucal(csv_path, tmp_path / "out", rate_hz=100.0, sections_path=json_path)
    assert not (tmp_path / "out" / "manifest.yaml").exists()


@pytest.mark.parametrize("csv_text, message", [
    ("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx_p,0,1,2,3,4,5,6\nwobble,1,1,2,3,4,5,6\n",
     r"line 3: column 'part': unknown section label 'wobble'"),
    ("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx_p,0,1,2,3,4,5,6\nx_a,1,1,2,3,4,5,6\nx_p,2,1,2,3,4,5,6\n",
     r"line 4: column 'part': section 'x_p' starts again \(it already ran from line 2\)"),
    ("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx_p,0,1,2,3,4,5,6\nx_p,1,1,2,3,x,5,6\n",
     r"line 3: column 'gyr_x': not a number"),
    ("part,samples,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\nx_p,5,1,2,3,4,5,6\nx_a,3,1,2,3,4,5,6\nx_a,6,1,2,3,4,5,6\n",
     r"line 2: column 'samples': section 'x_p' overlaps section 'x_a' in time"),
])
def test_bad_annotated_input_refused(tmp_path, csv_text, message):
    with pytest.raises(UserError, match=message):
        imucal.import_imucal(write(tmp_path, "ann.csv", csv_text), tmp_path / "out", rate_hz=204.8)


def test_option_errors(tmp_path):
    with pytest.raises(UserError, match="needs its section list"):
        imucal.import_imucal(SESSION, tmp_path / "o1", rate_hz=102.4)
    with pytest.raises(UserError, match="--sections is not used"):
        imucal.import_imucal(ANNOTATED, tmp_path / "o2", rate_hz=204.8, sections_path=SECTIONS)
    with pytest.raises(UserError, match="rate-hz"):
        imucal.import_imucal(SESSION, tmp_path / "o3", rate_hz=float("nan"), sections_path=SECTIONS)
    with pytest.raises(UserError, match="cannot read"):
        imucal.import_imucal(tmp_path / "missing.csv", tmp_path / "o4", rate_hz=1.0, sections_path=SECTIONS)
    target = tmp_path / "twice"
    imucal.import_imucal(SESSION, target, rate_hz=102.4, sections_path=SECTIONS)
    with pytest.raises(UserError):
        imucal.import_imucal(SESSION, target, rate_hz=102.4, sections_path=SECTIONS)
    bad = write(tmp_path, "latin.csv", "n_samples,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z\n")
    bad.write_bytes(bad.read_bytes() + b"0,\xff,1,1,1,1,1\n")
    with pytest.raises(UserError, match="line 2: not UTF-8"):
        imucal.import_imucal(bad, tmp_path / "o5", rate_hz=1.0, sections_path=SECTIONS)


def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys):
    broken = tmp_path / "broken.csv"
    shutil.copy(SESSION, broken)
    lines = broken.read_text().splitlines()
    lines[100] = lines[100].replace(",", ",x", 1)
    broken.write_text("\n".join(lines) + "\n")
    code = cli.main(["import", "imucal", str(broken), "--sections", str(SECTIONS), "--rate-hz", "102.4",
                     "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "broken.csv: line 101: column 'gyr_x': not a number" in err
