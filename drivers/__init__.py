"""Device drivers: rate tables and IMUs over any pyserial URL.

``drivers.registry.open_table(url, "acutrol")`` / ``open_imu(url, "vectornav")`` give a
connected :class:`drivers.table.RateTable` / :class:`drivers.imu.Imu`.  Protocols are written
down as data in ``drivers/protocols``; see docs/protocols.md.
"""
