"""The names the parser offers (``--method``, ``--to``, ``--preset``, ...), written out here so
that building the parser -- ``station --help``, ``station COMMAND --help``, every light command
-- imports none of the modules that own them (the estimators pull in scipy.optimize and
scipy.spatial, the importers scipy.ndimage, the exporters the calibration model).

Each list is a copy: tests/test_cli_startup.py compares every one with the registry it copies,
so a method, format or preset added there and not here fails a test instead of going missing
from the command line.  Import nothing here but the standard library.
"""
from __future__ import annotations

# station.estimate.METHODS
ESTIMATE_METHODS = ("auto", "lsq", "zhang2010", "fourier", "fourier-high")

# station.io.exporters.FORMATS: name -> the module's TITLE, in FORMATS' order
EXPORT_FORMATS = {
    "imucal": "imucal calibration JSON v2 (Turntable/Ferraris calibration info)",
    "imu_tk": "imu_tk text, T K B per triad (PREFIX_acc.calib, PREFIX_gyro.calib)",
    "kalibr": "Kalibr imu.yaml (noise densities, random walks, rate)",
    "ros": "ROS imu_calib YAML (SM, bias; gyro_SM, gyro_bias)",
    "c": "C header (double, float and Q31 fixed point matrices and biases, inline functions)",
    "json": "plain JSON (station's compensation, parameters, noise)",
}

# station.io.importers.imucal.FORMATS and DEFAULT_GRAVITY_MPS2 (m/s², imucal's default)
IMUCAL_FORMATS = ("auto", "session", "annotated")
IMUCAL_DEFAULT_GRAVITY_MPS2 = 9.81

# sorted(station.io.importers.delimited.PRESETS)
CSV_PRESETS = ("imu_tk", "imucal", "station", "t-a-g")

# station.io.importers.recording.MIN_POSES (the default of --min-poses)
RECORDING_MIN_POSES = 9

# station.io.importers.rosbag.STAMPS
ROSBAG_STAMPS = ("header", "bag")

# station.design.search.CRITERIA (station design --criterion; "worst" takes :PARAM,...)
DESIGN_CRITERIA = ("D", "A", "worst")
