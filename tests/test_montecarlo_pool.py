"""Monte Carlo on every core: the pool gives the same runs as one process (seeds, not
scheduling, decide every number), reports progress as runs finish, computes the Cramér-Rao
bound in the same pool; the command's progress bar draws on a terminal only.  Short captures
(3 s dwells, 4 s rotations) and the algebraic method keep this fast; throughput is measured by
benchmarks/perf_montecarlo.py, never here."""
from __future__ import annotations

import io
import os

import numpy as np
import pytest
from rich.console import Console

from station.io.scheme import load_scheme
from station.simulate import montecarlo

SHORT = {"dwell_s": 3.0, "rotation_s": 4.0}


def _where_the_bound_is_computed(scheme, settings, seed=0):
    """Stands in for cramer_rao (whose noise-free fit of a short capture is slow): says which
    process computed it and for which scheme."""
    return np.array([os.getpid(), len(scheme.segments)], float)


def test_the_pool_gives_the_runs_of_one_process_in_seed_order_with_progress_and_bound(monkeypatch):
    scheme = load_scheme("optimal9", SHORT)
    settings = montecarlo.Settings(method="zhang2010")
    alone = montecarlo.study(scheme, settings, 3, first_seed=41, workers=1)
    calls = []
    monkeypatch.setattr(montecarlo, "cramer_rao", _where_the_bound_is_computed)   # forked workers see it
    pooled = montecarlo.study(scheme, settings, 3, first_seed=41, workers=2, bound=True,
                              progress=lambda done, total: calls.append((done, total)))
    assert pooled.workers == 2 and alone.workers == 1
    assert pooled.names == alone.names and pooled.errors.shape == (3, montecarlo.BASE_PARAMETERS)
    # the same seeds give the same simulated noise and the same estimate; one BLAS thread in
    # both, so even the rounding agrees (1e-9 relative leaves room for the summation order only)
    np.testing.assert_allclose(pooled.errors, alone.errors, rtol=1e-9, atol=1e-12)
    # three different seeds are three different runs (not one result copied)
    assert np.all(np.ptp(pooled.errors, axis=0)[:3] > 0)
    assert calls == [(0, 3), (1, 3), (2, 3), (3, 3)]
    pid, segments = pooled.crlb            # the bound was computed by a worker, beside the runs
    assert pid != os.getpid() and segments == len(scheme.segments)
    assert alone.crlb is None


def test_workers_never_exceed_the_jobs():
    scheme = load_scheme("optimal9", SHORT)
    result = montecarlo.study(scheme, montecarlo.Settings(method="zhang2010"), 2, workers=8)
    assert result.workers == 2 and result.errors.shape[0] == 2


def test_the_progress_bar_draws_on_a_terminal_and_stays_silent_in_a_pipe(monkeypatch):
    from station.cli import montecarlo as cli

    for terminal in (True, False):
        sink = io.StringIO()
        monkeypatch.setattr(cli, "err", Console(file=sink, force_terminal=terminal, width=100))
        with cli._progress_bar(4) as progress:
            for done in range(5):
                progress(done, 4)
        text = sink.getvalue()
        assert ("4/4" in text) == terminal and ("dry runs" in text) == terminal


def _children(pid: int) -> list[int]:
    path = f"/proc/{pid}/task/{pid}/children"
    try:
        with open(path) as f:
            return [int(x) for x in f.read().split()]
    except OSError:
        return []


@pytest.mark.skipif(not os.path.exists(f"/proc/{os.getpid()}/task/{os.getpid()}/children"),
                    reason="needs Linux /proc children lists")
def test_ctrl_c_ends_the_workers_and_says_interrupted(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) while the pool runs:
    exit status 130, the one line "interrupted", no traceback, and no worker left behind."""
    import signal
    import subprocess
    import sys
    import time

    from server_guard import guard
    from station.io.scheme import scheme_text

    text, _ = scheme_text("optimal9")
    short = text.replace("dwell_s: 100.0", "dwell_s: 3.0").replace("rotation_s: 180.0", "rotation_s: 4.0")
    assert short != text
    (tmp_path / "short.yaml").write_text(short)
    p = subprocess.Popen([sys.executable, "-m", "station.cli", "montecarlo", "--scheme", str(tmp_path / "short.yaml"),
                          "--runs", "100000", "--method", "zhang2010", "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                         # Ctrl-C as a terminal delivers it, even when this test runs with SIGINT ignored
                         # (a background job): an ignored SIGINT is inherited and Python would keep it
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    guarded = guard(sessions=[p.pid], sig=signal.SIGKILL, grace_s=0.0)   # 100,000 runs: not past a killed pytest
    try:
        for _ in range(1200):                      # until the pool's two workers exist
            workers = _children(p.pid)
            if len(workers) >= 2 or p.poll() is not None:
                break
            time.sleep(0.05)
        assert len(workers) >= 2, "the pool did not start"
        time.sleep(0.5)                            # runs under way
        os.killpg(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:                       # its own session: the test's processes only
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        guarded.release()
    assert p.returncode == 130 and err.strip() == "interrupted" and out == ""
    assert not any(os.path.exists(f"/proc/{w}") and open(f"/proc/{w}/stat").read().split()[2] != "Z"
                   for w in workers)


def test_the_pool_forks_after_the_runs_modules_are_imported():
    """montecarlo.preload imports what a run imports, so the workers forked after it inherit the
    modules instead of each importing them (issue 27 item 5): a run after it imports nothing of
    station, sim_devices or scipy.  In a fresh process (this one has imported them already)."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from station.simulate import montecarlo as mc\n"
            "from station.io.scheme import load_scheme\n"
            "scheme, settings = load_scheme('optimal9'), mc.Settings()\n"
            "mc.preload()\n"
            "before = set(sys.modules)\n"
            "mc.one_run((scheme, settings, 3))\n"
            "print(sorted(m for m in set(sys.modules) - before if m.split('.')[0] in ('station', 'sim_devices', 'scipy')))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-1000:]
    assert run.stdout.strip() == "[]"
