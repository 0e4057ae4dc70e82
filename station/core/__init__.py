"""What every layer may use, and nothing else: the user-error types (exit status 2) and the
units and their conversions.  Imports nothing from station; drivers and sim_devices use it too."""
