"""No process of a command is alive after it returns (issue 27, item 3).

The command runs under a *child subreaper* (prctl PR_SET_CHILD_SUBREAPER): every process it
started, and every process those started, that outlives its own parent is handed to the
subreaper instead of to init.  So the moment `station` returns, the subreaper's children tell
whether anything it started was still there (running, or ended and never waited for: a process
killed but not awaited still had its memory to free, on the machine's CPU and outside the
command's time).  No sleep, no timing: one waitpid(-1, WNOHANG) right after the command returns.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux's")

# Runs `station ARGV` (its console entry, as a user runs it) as the subreaper's child, then
# reports its exit status and every process handed to the subreaper by then (pid, state, command).
SUBREAPER = r"""
import ctypes, json, os, subprocess, sys
libc = ctypes.CDLL(None, use_errno=True)
assert libc.prctl(36, 1, 0, 0, 0) == 0          # PR_SET_CHILD_SUBREAPER (linux/prctl.h)
proc = subprocess.Popen([sys.executable, "-c", "import sys; from station.cli import console_main; "
                         "sys.argv[0] = 'station'; sys.exit(console_main())", *sys.argv[1:]],
                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
_, err = proc.communicate()
left = []
while True:                                       # what outlived the command, handed to us
    try:
        pid, _ = os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        break                                     # nothing: every process was awaited
    if pid == 0:                                  # one still running: name it, then end it
        for name in os.listdir("/proc"):
            if name.isdigit():
                try:
                    stat = open(f"/proc/{name}/stat").read()
                except OSError:
                    continue
                fields = stat.rsplit(")", 1)[1].split()
                if int(fields[1]) == os.getpid():
                    left.append([int(name), fields[0], open(f"/proc/{name}/cmdline").read().replace("\0", " ")])
                    os.kill(int(name), 9)
        os.waitpid(-1, 0)
        continue
    left.append([pid, "ended, never awaited", ""])
print(json.dumps({"status": proc.returncode, "left": left, "stderr": err.decode(errors="replace")[-2000:]}))
"""


def run_reaped(*argv) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    done = subprocess.run([sys.executable, "-c", SUBREAPER, *map(str, argv)], capture_output=True, text=True,
                          env=env, timeout=240)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("command", ["estimate", "diagnose-report", "report"])
def test_nothing_a_command_started_outlives_it(optimal9_run, tmp_path, command):
    argv = {"estimate": ["estimate", optimal9_run, "-o", tmp_path / "cal.yaml"],
            "diagnose-report": ["diagnose", optimal9_run, "--auto", "--report", tmp_path / "page"],
            "report": ["report", optimal9_run, "-o", tmp_path / "page.html"]}[command]
    result = run_reaped(*argv)
    assert result["status"] in (0, 3), result["stderr"]
    assert result["left"] == [], f"processes alive or never awaited after `station {command}` returned: {result['left']}"
