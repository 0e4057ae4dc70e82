"""Device twins: a rate table and an IMU that speak the real protocols over pseudo-terminals,
driven by the simulated physics (``sim_devices.world``, ``sim_devices.truth``).

| module | role |
| --- | --- |
| ``clock`` | the shared simulated clock (device time, ``speed`` x wall time) |
| ``geometry`` | gimbal geometry: axis angles -> attitude, rate and angular acceleration of the platform |
| ``motion`` | one axis's motion: rate/acceleration-limited profiles, settling, braking |
| ``table`` | the table twin: axes, modes, limits, interlocks, faults, encoder readback |
| ``imu`` | the IMU twin: samples from the table twin's state through ``Truth.measure`` |
| ``table_acutrol``, ``table_aerosmith`` | table protocol front-ends (bytes in, bytes out) |
| ``imu_vectornav``, ``imu_csv`` | IMU protocol front-ends (commands, frames) |
| ``faults`` | the ``--faults`` file and the stream faults |
| ``pty`` | a pseudo-terminal end point |
| ``serve`` | both twins on pseudo-terminals, served by one loop |

See docs/twins.md.
"""
