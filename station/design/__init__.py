"""Experiment design (``station design``): the scheme that calibrates a model best on a table
within a time budget (docs/design.md).  candidates.py (what the table can do, and its time),
information.py (each candidate's Fisher information, from the estimator's own Jacobian),
search.py (the criterion and the exchange algorithm), designer.py (the whole design: search,
scheme file, comparison with the built-in schemes)."""
