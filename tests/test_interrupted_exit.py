"""An interrupted command (Ctrl-C: status 130) ends without the interpreter's own shutdown
(station.cli._end_interrupted): the threads that are not daemons joined and the atexit handlers
run as that shutdown would, the output flushed, then os._exit.  A Ctrl-C while the CSV engine
parsed a long segment on its own threads ended some interrupted estimates of a 1 kHz capture
with SIGABRT (exit status -6; docs/performance.md, eighteenth session)."""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = textwrap.dedent("""
    import atexit, sys, threading, time
    from pathlib import Path
    out = Path(sys.argv[1]); status = int(sys.argv[2])

    atexit.register(lambda: (out / "atexit").write_text("ran"))

    def late():
        time.sleep(0.3)
        (out / "thread").write_text("ran")

    threading.Thread(target=late).start()       # not a daemon: the shutdown waits for it
    import station.cli as cli
    cli.main = lambda argv=None: (print("said before the end", end=""), status)[1]
    status = cli.console_main()
    (out / "returned").write_text("ran")        # os._exit never returns here
    sys.exit(status)
""")


def _run(tmp_path, status):
    script = tmp_path / "command.py"
    script.write_text(SCRIPT)
    done = subprocess.run([sys.executable, str(script), str(tmp_path), str(status)], capture_output=True,
                          text=True, timeout=60, cwd=str(tmp_path),
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    ran = {p.name for p in tmp_path.iterdir()} - {script.name}
    return done, ran


def test_an_interrupted_command_ends_at_once_after_its_threads_and_exit_handlers(tmp_path):
    done, ran = _run(tmp_path, 130)
    assert done.returncode == 130, done.stderr
    assert done.stdout == "said before the end"           # flushed (no newline: still buffered)
    assert {"thread", "atexit"} <= ran                     # joined and run, as the shutdown would
    assert "returned" not in ran                           # ended there: the shutdown skipped


def test_a_command_that_ends_otherwise_ends_as_before(tmp_path):
    done, ran = _run(tmp_path, 2)
    assert done.returncode == 2, done.stderr
    assert done.stdout == "said before the end"
    assert {"thread", "atexit", "returned"} <= ran
