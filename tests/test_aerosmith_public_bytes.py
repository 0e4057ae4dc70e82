"""Contract with the public client of the three-letter dialect: ``IdealAerosmithTable``
(actigraph/RateTableSweepGUI, RateSweepGUI.py).  Its exact bytes, both directions, over a real
pseudo-terminal against the twin (docs/protocols.md, ``aerosmith``):

* ``request(buf)`` writes ``buf + '\\r\\n'`` (``'ACL%d'``, ``'HOF%f'``... as its methods format
  them) and reads two lines, each up to a ``\\r``, stripped: the reply, then the prompt;
* ``jog()`` writes ``'JOG%d\\r\\n'`` and reads nothing; the next request first writes
  ``'STA\\r\\n'`` and reads two lines (``eatReturn``);
* ``stop()`` writes ``'STO'`` with no terminator and reads nothing.
"""
from __future__ import annotations

import time

import pytest
import serial

from drivers.registry import open_table
from drivers.table import TableSettings
from sim_devices.truth import default_truth
from sim_devices.twins.serve import BenchOptions, BenchServer

SPEED = 50.0
ANSWERED = b"\r\n>\r\n"           # a reply line without a value, then the prompt line
REFUSED = b"?\r\n>\r\n"


@pytest.fixture(params=[False, True], ids=["answered", "silent-motion"])
def bench(request):
    with BenchServer(default_truth(3), BenchOptions(
            speed=SPEED, axes=1, table_protocol="aerosmith",
            table_silent_motion=request.param)) as server:
        line = serial.Serial(server.table_path, timeout=0.05)
        line.got = 0                    # bytes read from the twin so far
        try:
            yield server, line, request.param
        finally:
            line.close()


def _send(server, line, data: bytes, expect: int) -> bytes:
    """Write ``data``; everything the twin answered: at least ``expect`` bytes, then every byte
    the twin wrote for it.  Once the twin's loop has served the command (``served``), the bytes
    it sent since the line opened are counted (``table_port.sent_bytes``): those not read yet
    are waited for (none is left unread, however late).  Before, 0.1 s of silence was taken for
    the end of the answer: 7 s of the file's 8 s of wall time."""
    line.write(data)
    out = bytearray()
    deadline = time.monotonic() + 2.0
    while len(out) < expect and time.monotonic() < deadline:
        out += line.read(max(1, line.in_waiting))
    server.served()
    port = server.table_port
    sent = port.sent_bytes + port.backlog
    deadline = time.monotonic() + 2.0
    while line.got + len(out) < sent and time.monotonic() < deadline:
        out += line.read(sent - line.got - len(out))
    line.got += len(out)
    assert line.got == sent, f"{sent - line.got} bytes sent by the twin not read in 2 s"
    return bytes(out)


def _client_lines(data: bytes) -> list[str]:
    """The lines the client's readline() takes from ``data``: up to each ``\\r``, stripped."""
    lines, buf = [], ""
    for ch in data.decode("ascii"):
        buf += ch
        if buf.endswith("\r"):
            lines.append(buf.strip())
            buf = ""
    assert not buf.strip(), f"left over after the last \\r: {buf!r}"
    return lines


# the client's request() strings, formatted by its own methods
SETTINGS = ["ACL%d" % 100, "VEL%d" % 60, "MOV%d" % 90, "HOM"]
NOT_SIMULATED = ["DIR1", "DIR0", "HOF%f" % 1.5, "RMO%d" % 10, "SAV", "ZER%d" % 0,
                 "AMP%f" % 5.0, "FRQ%f" % 0.5, "PER%d" % 2, "CYC%d" % 3]


def test_the_queries_answer_a_value_line_then_the_prompt_line(bench):
    server, line, _ = bench
    assert _send(server, line, b"STA\r\n", 6) == b"1\r\n>\r\n"              # getStatus: int()
    assert _send(server, line, b"PPO\r\n", 11) == b"0.0000\r\n>\r\n"        # getPosition: float()
    assert _send(server, line, b"PVE\r\n", 11) == b"0.0000\r\n>\r\n"        # getVelocity: float()
    assert _send(server, line, b"MCO1\r\n", 6) == b"1\r\n>\r\n"             # isMoving: '1' = at rest
    assert _client_lines(b"1\r\n>\r\n") == ["1", ">"]


@pytest.mark.parametrize("command", SETTINGS + NOT_SIMULATED)
def test_every_request_of_the_client_is_answered_by_two_lines(bench, command):
    server, line, _ = bench
    got = _send(server, line, (command + "\r\n").encode(), len(ANSWERED))
    assert got == (REFUSED if command in NOT_SIMULATED else ANSWERED)
    assert len(_client_lines(got)) == 2


def test_a_move_then_motion_complete(bench):
    """MCO1 answers 0 while the axis moves and 1 once it is within 1 deg of the target, at rest.
    Judged at the device time each answer was given, not by when the client asked: at SPEED 50
    the 90 deg move (about 3.5 s of device time) lasts 70 ms of wall time, and a client
    descheduled that long on a loaded machine asked after the move had ended (the test used to
    require the first answer to be 0, and failed under load)."""
    server, line, _ = bench
    answers = []
    handlers = server.table_frontend.handlers
    mco = handlers["motion_complete"]

    def logged(*args):
        value = mco(*args)
        answers.append((server.step_clock.now(), value))
        return value

    handlers["motion_complete"] = logged
    t_move = server.step_clock.now()
    assert _send(server, line, b"MOV90\r\n", 5) == ANSWERED
    deadline = time.monotonic() + 5.0
    while _send(server, line, b"MCO1\r\n", 6) != b"1\r\n>\r\n":
        assert time.monotonic() < deadline
    assert abs(server.table.read_position(1) - 90.0) <= 1.0
    assert _send(server, line, b"PPO\r\n", 12).startswith(b"90.0")
    for t, value in answers:
        pos, rate, _ = server.table.axis_states(t)
        at_rest = abs(rate[0, 0]) <= server.table.config.rate_resolution_dps
        assert value == int(at_rest and abs(pos[0, 0] - 90.0) <= 1.0)
        if t < t_move + 1.5:                   # 89 deg at 60 deg/s at most cannot be done yet
            assert value == 0


def test_jog_then_a_request_as_the_client_does_it(bench):
    server, line, silent = bench
    got = _send(server, line, b"JOG30\r\n", 0 if silent else len(ANSWERED))
    assert got == (b"" if silent else ANSWERED)
    assert server.table.axes[0].mode == "rate"
    time.sleep(0.05)                                                  # at 30 deg/s
    # eatReturn: STA, two lines read, then the request itself
    got = _send(server, line, b"STA\r\n", 7) + _send(server, line, b"PVE\r\n", 12)
    assert got == b"13\r\n>\r\n30.0000\r\n>\r\n"
    lines = _client_lines((b"" if silent else ANSWERED) + got)
    eaten, answer = lines[:2], lines[2:4]
    # with the motion commands answered, the client eats JOG's answer and reads STA's as the
    # answer to its request: one exchange behind (docs/protocols.md)
    assert answer == (["30.0000", ">"] if silent else ["13", ">"])
    assert eaten == (["13", ">"] if silent else ["", ">"])


def test_a_bare_sto_stops_without_a_terminator(bench):
    server, line, silent = bench
    _send(server, line, b"JOG30\r\n", 0 if silent else len(ANSWERED))
    time.sleep(0.05)
    got = _send(server, line, b"STO", 0 if silent else len(ANSWERED))         # no terminator at all
    assert got == (b"" if silent else ANSWERED)
    assert server.table.axes[0].mode == "position"                  # executed at once
    # the client's next command, a second later, is not glued to it
    assert _send(server, line, b"STA\r\n", 6).endswith(b"\r\n>\r\n") and b"?" not in got


@pytest.mark.parametrize("end", [b"\r", b"\n", b"\r\n"])
def test_each_terminator_ends_a_command_once(bench, end):
    server, line, _ = bench
    assert _send(server, line, b"STA" + end, 6) == b"1\r\n>\r\n"
    assert _send(server, line, b"ACL50" + end, len(ANSWERED)) == ANSWERED
    assert _send(server, line, b"XYZ" + end, len(REFUSED)) == REFUSED


def test_the_driver_always_terminates_and_reads_both_framings(bench):
    server, _, _ = bench
    with open_table(server.table_path, "aerosmith", TableSettings()) as table:
        sent = []
        write = table.port.write
        table.port.write = lambda data: (sent.append(data), write(data))[1]
        table.set_rate(1, 10.0)
        table.stop()
        assert all(d.endswith(b"\r") and d.count(b"\r") == 1 for d in sent)
        assert b"STO\r" not in sent
        i, j = sent.index(b"JOG10\r"), sent.index(b"JOG0\r")      # the rate, then the stop
        assert i < j and sent[i + 1] == sent[j + 1] == b"STA\r"
        mov = max(k for k, d in enumerate(sent) if d.startswith(b"MOV"))
        assert mov > j and sent[mov - 1] == b"PPO\r"                 # held where it rests
