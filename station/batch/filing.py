"""Calibrations a batch wrote, filed into the history store by the single commands' policy
(station.cli.history.file_quietly; docs/calibration-file.md, "History"): a real IMU's (a
serial) into the store, a simulated IMU's (serial SIM-...) into the simulations' own store,
one without a serial not at all; the same capture and model filed once.  Filing happens in the
process that started the batch, as each result arrives (one writer for the store), through the
store's public functions (station.io.history)."""
from __future__ import annotations

from collections import Counter


class Filer:
    def __init__(self, store=None):
        self.store = store
        self.counts: Counter = Counter()      # filed, already filed, no serial, not filed (error)
        self.warnings: list[str] = []

    def file(self, cal_path, serial: str | None = None) -> str:
        """File one calibration; returns what happened in a few words.  ``serial``: the IMU serial
        the file states, as the worker that wrote it reports it (Outcome.imu_serial); without it
        the file is read here for it.  (Reading it here too cost half of the filing's CPU, ~5 ms
        of the command's per capture: the store reads the file again as it files it.)"""
        from station.core.errors import UserError
        from station.io.history import SIMULATED_PREFIX, Store, real_serial, simulation_store

        try:
            if serial is None:
                from station.io.calfile import read_calfile

                doc = read_calfile(cal_path)
                serial = (doc.get("provenance") or {}).get("imu_serial") or ""
            else:
                doc = {"provenance": {"imu_serial": serial}}
            if isinstance(serial, str) and serial.startswith(SIMULATED_PREFIX):
                root = simulation_store(self.store)
            elif real_serial(doc) is None:
                self.counts["no serial"] += 1
                return "not filed: no IMU serial"
            else:
                root = self.store
            entry, new = Store(root).file(cal_path)
        except UserError as e:
            self.counts["not filed (error)"] += 1
            self.warnings.append(f"{cal_path}: not filed in the calibration history: {e}")
            return "not filed"
        self.counts["filed" if new else "already filed"] += 1
        return f"filed as #{entry.id}" if new else f"already filed as #{entry.id}"
