"""station: a rate table and an IMU on a bench as a calibration lab.

The Python API is ``station.api`` (docs/api.md); ``import station`` itself imports nothing else:

    from station import api
    est = api.estimate("captures/run1")
"""
__version__ = "0.1.0"
