"""Batches: one command (estimate, diagnose, report, export) over many captures on a Dask
cluster -- every local core by default (a LocalCluster the batch starts and stops), or an
existing cluster (``--scheduler tcp://HOST:8786``).  docs/fleet.md, "Batches".

- ``cluster.py``: the Dask client: a local cluster started and stopped around the batch, or a
  connection to a running scheduler (dask is imported here only, when a batch starts);
- ``inputs.py``: the captures a batch runs on (paths, globs, a history query) and the output
  file of each;
- ``tasks.py``: what a worker does for one capture: the same library functions the single-capture
  commands call, every error caught and returned as one line (the other captures go on);
- ``state.py``: the batch state file (what is done, with the capture's fingerprint and the
  output's sha256) that a restarted batch skips;
- ``runner.py``: submit, collect as they finish, skip what is done, record the state;
- ``filing.py``: calibrations filed into the history store, by the single commands' policy.

``import station.batch`` imports none of them (nor dask)."""
