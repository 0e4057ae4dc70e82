"""The command line: argument parsing and output only; the work is done by the layers below
(docs/architecture.md)."""
from station.cli.app import main

__all__ = ["main"]
