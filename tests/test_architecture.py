"""The layers of docs/architecture.md hold: import-linter's contracts in pyproject.toml (layers,
no simulated devices outside simulation, the simulated world independent of the model, no cycles)."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_are_kept():
    exe = shutil.which("lint-imports")
    if exe is None:
        pytest.fail("lint-imports is not installed: pip install -e '.[dev]'")
    done = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout


def test_runtime_layers_do_not_load_the_simulated_devices():
    """Importing the estimator, the bench and the CLI's parser loads no sim_devices module."""
    code = ("import sys, station.estimate.lsq, station.bench.sequencer, station.diagnose.core, "
            "station.cli.app; station.cli.app.build_parser(); "
            "print(sorted(m for m in sys.modules if m.startswith('sim_devices')))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
