"""Review of grp28 (issue 28): a recorded elevation splits an axis group.  A way the split
misfired on a capture nobody here designed for (~0.5 s):

* a rotation whose elevation is not recorded beside one about the same body axis whose is (0):
  the estimator (summaries) gives them two groups, station design --from (capture_groups,
  capture_scheme: a missing elevation read as 0.0) one -- the design predicts for another
  model than the one the estimator fits, and numbers the axis groups differently.

(The review's other case -- the same elevation recorded to a few decimals, 90 and 89.99999: an
extra axis group, dof 145 -> 144 -- is not resolved: its test is on branch wip/grp28-review;
docs/design.md, "a level and a vertical turn about one body axis".)"""
import yaml

from sim_devices.truth import mems_truth
from station.design import sequential
from station.estimate.summaries import summarise
from station.io.capture import read_capture
from station.io.scheme import scheme_from_text
from station.simulate import dryrun

SCHEME = """\
name: twoturns
defaults: {dwell_s: 1.0, rate_dps: 100.0, rotation_s: 3.6}
segments:
""" + "".join(f"  - {{static: s{i}, up_body: {u}}}\n" for i, u in enumerate(
    [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]])) + """\
  - {rotation: rx, axis_body: [1, 0, 0], axis_elevation_deg: ELEV}
  - {rotation: ry, axis_body: [0, 1, 0], axis_elevation_deg: ELEV}
  - {rotation: rz, axis_body: [0, 0, 1], axis_elevation_deg: ELEV}
  - {rotation: wz, axis_body: [0, 0, 1], axis_elevation_deg: ELEV, rate_dps: 200}
"""


def _capture(path, elevation, wz_elevation):
    """A dry run's capture with two turns about z (rz, wz), wz's recorded elevation edited."""
    dryrun.record_scheme(scheme_from_text(SCHEME.replace("ELEV", str(elevation)), "twoturns.yaml"),
                         mems_truth(0), 5, path)
    manifest = path / "manifest.yaml"
    doc = yaml.safe_load(manifest.read_text())
    for seg in doc["segments"]:
        if seg["name"].startswith("wz"):
            if wz_elevation is None:
                seg.pop("axis_elevation_deg", None)
            else:
                seg["axis_elevation_deg"] = wz_elevation
    manifest.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_design_from_numbers_the_axis_groups_as_the_estimator_when_an_elevation_is_not_recorded(tmp_path):
    path = _capture(tmp_path / "cap", 0, None)
    estimator = summarise(read_capture(path)).groups
    capture = read_capture(path, load_data=False)
    design = sequential.capture_groups(sequential.capture_scheme(capture), sequential.capture_sessions(capture))
    assert len(design) == estimator, (len(design), estimator)
