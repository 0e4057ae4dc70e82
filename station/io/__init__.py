"""Files in and out: capture bundles (station-capture/1), calibration files (station-calibration/1),
scheme files, segment detection in continuous recordings, importers of other tools' recordings.
Uses station.model for the calibration's contents; never the estimators, the bench or the CLI."""
