"""station fleet: each parameter's spread across units, the units outside their lot's spread,
drift per unit, pass/fail counts; the JSON, the page (checked in headless chromium when one is
installed), the same view from a SQLite and a PostgreSQL store."""
import copy
import hashlib
import json
import random

import numpy as np
import pytest

from browser import needs_browser, screenshot
import yaml

from pg_server import pg  # noqa: F401  (the module's server)
from station.cli import main

DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)     # libyaml: the test files written fast
from station.diagnose.fleet import TAIL, UnitValue, _spread

HEADER_RGB = (0x1d, 0x2a, 0x44)
RED = (214, 39, 40)                 # matplotlib tab:red: a unit outside the lot's spread
UNITS = 12
LOT_SIGMAS = 10.0                   # units of the lot spread by 10 of their own 1σ per parameter
PLANTED = ("SN-A07", "accel_bias_y", 8.0)     # a unit 8 σ of the lot away in one parameter


def _cal(base, serial, lot, capture, date, shift, verdict="passes"):
    doc = copy.deepcopy(base)
    doc["provenance"].update(imu_serial=serial, imu_lot=lot, imu_model="VN-100", date_utc=date,
                             capture_sha256=hashlib.sha256(capture.encode()).hexdigest())
    for name, p in doc["parameters"].items():
        if name in shift and "_scale_" in name:     # the compensation moved with it: one calibration
            sensor, axis = name.split("_scale_")
            column = "xyz".index(axis)
            for row in doc["compensation"][f"{sensor}_matrix"]:
                row[column] *= p["value"] / (p["value"] + shift[name])
        p["value"] += shift.get(name, 0.0)
    doc["verdict"]["result"] = verdict
    return doc


@pytest.fixture(scope="module")
def lot(optimal9_run, tmp_path_factory):
    """UNITS units of lot A (each parameter spread by LOT_SIGMAS of the units' own 1σ, normal,
    seed 5), PLANTED, one unit recalibrated with gyro_scale_x moved by 10 own σ, one unit whose
    only calibration fails, and 4 units of lot B (filed with history --add --lot B)."""
    base = yaml.safe_load((optimal9_run / "calibration.yaml").read_text())
    rng = random.Random(5)
    out = tmp_path_factory.mktemp("lot")
    docs = []
    for u in range(UNITS):
        serial = f"SN-A{u:02d}"
        shift = {n: rng.gauss(0.0, LOT_SIGMAS * p["sigma"]) for n, p in base["parameters"].items()}
        if serial == PLANTED[0]:
            shift[PLANTED[1]] += PLANTED[2] * LOT_SIGMAS * base["parameters"][PLANTED[1]]["sigma"]
        docs.append(("A", _cal(base, serial, "A", f"{serial}/1", "2031-01-10T00:00:00Z", shift)))
        if u == 3:
            again = dict(shift, gyro_scale_x=shift["gyro_scale_x"] + 10.0 * base["parameters"]["gyro_scale_x"]["sigma"])
            docs.append(("A", _cal(base, serial, "A", f"{serial}/2", "2032-01-10T00:00:00Z", again)))
    docs.append(("A", _cal(base, "SN-A99", "A", "bad", "2031-02-01T00:00:00Z", {}, verdict="fails")))
    for u in range(4):
        doc = _cal(base, f"SN-B{u:02d}", None, f"B{u}", "2030-06-01T00:00:00Z", {})
        docs.append(("B", doc))
    paths = []
    for k, (lot_name, doc) in enumerate(docs):
        path = out / f"{k:02d}.yaml"
        path.write_text(yaml.dump(doc, Dumper=DUMPER, sort_keys=False))
        paths.append((lot_name, path))
    return paths


def _file(lot, store):
    assert main(["history", "--store", store, *sum((["--add", str(p)] for name, p in lot if name == "A"), [])]) == 0
    assert main(["history", "--store", store, "--lot", "B",
                 *sum((["--add", str(p)] for name, p in lot if name == "B"), [])]) == 0


def _fleet_json(capsys, *argv):
    capsys.readouterr()
    assert main(["fleet", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def sqlite_store(lot, tmp_path_factory):
    store = str(tmp_path_factory.mktemp("fleet-store"))
    _file(lot, store)
    return store


def test_the_planted_unit_is_outside_and_the_lot_is_judged_by_its_own_spread(sqlite_store, capsys):
    view = _fleet_json(capsys, "--store", sqlite_store, "--lot", "A", "--model", "VN-100")
    assert view["format"] == "station-fleet/1"
    assert view["units"] == UNITS + 1 and view["calibrations"] == UNITS + 2
    assert view["verdicts"] == {"passes": UNITS + 1, "fails": 1} and view["units_without_usable_calibration"] == ["SN-A99"]
    outside = [(p["name"], v["serial"]) for p in view["parameters"] for v in p["values"] if v["outside"]]
    assert (PLANTED[1], PLANTED[0]) in outside
    # the others are chance: 12 x 21 judgements at the 0.27 % tail expect 0.68; 4 or more has
    # probability 0.5 % (binomial)
    assert view["judgements"] == UNITS * 21 and len(outside) - 1 <= 3, outside
    p = next(p for p in view["parameters"] if p["name"] == PLANTED[1])
    v = next(v for v in p["values"] if v["serial"] == PLANTED[0])
    # 8 σ of the lot planted on a draw from the lot (within ±3.3 at 99.9 %), in σ of the rest of
    # the lot (their std 0.38-1.67 of the truth, below): between 2.8 and 30
    assert 2.8 < v["z_lot"] < 30.0
    others = np.array([w["value"] for w in p["values"] if w["serial"] != PLANTED[0]])
    d = v["value"] - others.mean()
    assert v["z_lot"] == pytest.approx(d / others.std(ddof=1), rel=1e-9)
    assert v["z_own"] == pytest.approx(d / v["sigma"], rel=1e-9)
    # each parameter spread by LOT_SIGMAS of the own 1σ: the std across the 11 others within the
    # chi distribution's 99.9 % range for 10 degrees of freedom (0.38-1.67 of the truth)
    q = next(p for p in view["parameters"] if p["name"] == "gyro_bias_z")
    assert 0.38 < q["std"] / (LOT_SIGMAS * q["median_sigma"]) < 1.67
    (drift,) = view["drift"]
    assert drift["serial"] == "SN-A03" and drift["calibrations"] == 2
    flagged = [c for c in drift["changes"] if c["flagged"]]
    # 10 own σ on one side, the same σ on the other: 10/sqrt(2) combined σ
    assert [c["parameter"] for c in flagged] == ["gyro_scale_x"] and flagged[0]["z"] == pytest.approx(10 / 2**0.5, rel=1e-6)
    assert flagged[0]["per_year"] == pytest.approx(flagged[0]["change"] * 365.25 / 365.0, rel=1e-9)


def test_selection_by_lot_and_date_and_the_text_output(sqlite_store, capsys):
    view = _fleet_json(capsys, "--store", sqlite_store, "--lot", "B")
    assert view["units"] == 4 and not view["drift"]
    # every lot at once: each unit judged within its own lot (lot B's four identical units have
    # no spread to be judged against: not judged), the distribution over all 16 usable units
    every = _fleet_json(capsys, "--store", sqlite_store)
    only_a = _fleet_json(capsys, "--store", sqlite_store, "--lot", "A")
    assert every["units"] == UNITS + 5 and every["judgements"] == only_a["judgements"] == UNITS * 21
    assert [(p["name"], v["serial"], v["z_lot"]) for p in every["parameters"] for v in p["values"] if v["outside"]] \
        == [(p["name"], v["serial"], v["z_lot"]) for p in only_a["parameters"] for v in p["values"] if v["outside"]]
    assert all(v["t"] is None for p in every["parameters"] for v in p["values"] if v["lot"] == "B")
    assert all(p["units"] == UNITS + 4 and p["t_limit"] is None for p in every["parameters"])
    assert _fleet_json(capsys, "--store", sqlite_store, "--since", "2031-01-01")["units"] == UNITS + 1
    assert main(["fleet", "--store", sqlite_store, "--lot", "A"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert f"│ {PLANTED[1]} │ {PLANTED[0]} │" in text and f"outside: 1 of {UNITS * 21} unit × parameter" in text
    assert "drift SN-A03 (2 calibrations, 2031-01-10 → 2032-01-10): gyro_scale_x +7.1σ (> 3σ)" in text
    for argv, words in ((["--since", "last week"], "--since 'last week': not a date"),
                        (["--lot", "Z"], "no calibration in")):
        assert main(["fleet", "--store", sqlite_store, *argv]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1


def test_the_leave_one_out_judgement_flags_a_normal_lot_at_its_stated_rate():
    """2,000 lots of 6 normal units: the fraction flagged is the stated tail (0.27 %); 12,000
    judgements expect 32.4 flags, standard deviation 5.7: within 4 of them."""
    rng = np.random.default_rng(11)
    flags = 0
    for _ in range(2000):
        values = [UnitValue("s", 0, "", float(x), 1.0) for x in rng.normal(0.0, 3.0, 6)]
        flags += len(_spread("p", "1", values).outside)
    expected = 12000 * TAIL
    assert abs(flags - expected) < 4 * (expected * (1 - TAIL)) ** 0.5, flags


def test_each_unit_against_the_rest_exactly_also_for_scale_factors():
    """The O(n) judgement gives what each unit's rest computed on its own gives, to 1e-9, also for
    scale factors (1 +- 1e-5: centred before summing, no digits lost)."""
    rng = np.random.default_rng(3)
    x = 1.0 + 1e-5 * rng.standard_normal(40)
    values = [UnitValue(f"u{i}", i, "", float(v), 1e-6) for i, v in enumerate(x)]
    _spread("accel_scale_x", "1", values)
    for i, v in enumerate(values):
        rest = np.delete(x, i)
        d = x[i] - rest.mean()
        assert v.z_lot == pytest.approx(d / rest.std(ddof=1), rel=1e-9, abs=1e-12)
        assert v.t == pytest.approx(v.z_lot / (1 + 1 / 39) ** 0.5, rel=1e-12)
        assert v.z_own == pytest.approx(d / 1e-6, rel=1e-9, abs=1e-12)


def test_the_same_view_from_postgresql(pg, lot, sqlite_store, tmp_path, capsys):
    url = pg.create_database("fleet")
    _file(lot, url)
    a = _fleet_json(capsys, "--store", sqlite_store, "--lot", "A")
    b = _fleet_json(capsys, "--store", url, "--lot", "A")
    for view in (a, b):
        view.pop("selection")
        for p in view["parameters"]:
            for v in p["values"]:
                v.pop("calibration")
        for d in view["drift"]:
            d.pop("first"), d.pop("last")
    assert a == b


@needs_browser
def test_chromium_renders_the_fleet_page_with_its_figure(sqlite_store, tmp_path, capsys):
    page = tmp_path / "fleet.html"
    assert main(["fleet", "--store", sqlite_store, "--lot", "A", "-o", str(page)]) == 0
    text = page.read_text(encoding="utf-8")
    assert "<script" not in text and "data:image/svg+xml;base64," in text and PLANTED[0] in text
    img = screenshot(page, tmp_path, 4000)
    assert np.abs(img[20, 20] - HEADER_RGB).max() <= 3          # the stylesheet applied
    red = np.all(np.abs(img - RED) <= 6, axis=2).sum()            # the outside unit's dot drawn
    assert red > 20, red


def test_a_lot_stated_when_filing_or_later(lot, tmp_path, capsys):
    """history --add --lot files the lot where the file states none, and sets it on a calibration
    filed before ("already filed"); --lot without --add is refused."""
    store = str(tmp_path / "s")
    (_, path), = [(n, p) for n, p in lot if n == "B"][:1]
    assert main(["history", "--store", store, "--add", str(path)]) == 0
    assert _fleet_json(capsys, "--store", store)["units"] == 1
    assert main(["fleet", "--store", store, "--lot", "Q"]) == 2
    capsys.readouterr()
    assert main(["history", "--store", store, "--add", str(path), "--lot", "Q", "--imu-model", "VN-200"]) == 0
    assert "already filed: #1" in capsys.readouterr().out
    view = _fleet_json(capsys, "--store", store, "--lot", "Q", "--model", "VN-200")
    assert view["units"] == 1 and view["calibrations"] == 1
    assert main(["history", "--store", store, "--lot", "Q"]) == 2
    assert "--lot and --imu-model go with --add" in capsys.readouterr().err
