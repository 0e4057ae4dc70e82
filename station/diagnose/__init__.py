"""Compare the model with the measurements (docs/diagnose.md)."""

# what a diagnosis needs once the capture is summarised, imported while a forked child reads the
# capture (station.estimate.summarise_while_importing): here, so that naming them imports nothing
DIAGNOSIS_MODULES = ("station.estimate.lsq", "station.diagnose.auto", "station.diagnose.core")
