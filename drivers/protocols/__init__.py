"""Protocol definitions as data, shared by the drivers (``drivers/``) and the device twins
(``sim_devices/twins/``), plus the frame encoders and decoders of the IMU protocols.

One module per protocol; ``docs/protocols.md`` is written from these tables.
"""
