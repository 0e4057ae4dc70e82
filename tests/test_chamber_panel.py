"""The chamber's panel on its pseudo-terminal (sim_devices/twins/chamber_panel.py): a reply that
nobody read does not wait for the next reader (review of 28a7a67..main, item 3).  Before, after
``echo hello > PANEL; echo 61 > PANEL`` a reader asking ``SET?`` first read the stale
``ERR unknown command 'hello'``."""
import os
import select
import time

import pytest

from sim_devices.chamber import ChamberAir
from sim_devices.twins.chamber_panel import ChamberPanel

ROOM_C = 25.0
WAIT_S = 10.0       # a bound for a loaded machine, never waited out when the condition holds


@pytest.fixture
def panel():
    p = ChamberPanel(ChamberAir(ROOM_C), 60.0, (-40.0, 85.0))
    yield p
    p.close()


def _serve_until(panel, done, now=0.0) -> None:
    """The serving loop's turns (as station sim serve's) until ``done()``."""
    deadline = time.monotonic() + WAIT_S
    while not done():
        assert time.monotonic() < deadline, "the panel did not do it in time"
        readable, _, _ = select.select([panel.port], [], [], 0.05)
        panel.serve(readable, now)


def _echo(panel, text: str) -> None:
    """``echo TEXT > PANEL``: open, write a line, close; nothing is read."""
    with open(panel.path, "w") as f:
        f.write(text + "\n")


def _ask(panel, fd, question: bytes) -> bytes:
    """A reader's question and the whole lines it reads back."""
    os.write(fd, question)
    got = bytearray()
    lines = question.count(b"\n")

    def answered():
        while select.select([fd], [], [], 0)[0]:
            got.extend(os.read(fd, 4096))
        return got.count(b"\n") >= lines

    _serve_until(panel, answered)
    return bytes(got)


def test_a_reader_gets_the_answer_to_its_question_not_what_an_echo_left(panel):
    _echo(panel, "hello")
    _serve_until(panel, lambda: panel.port.unread() > 0)        # the ERR line, held by the line
    _echo(panel, "61")
    _serve_until(panel, lambda: panel.setpoint_c == 61.0)
    assert panel.port.unread() == 0                              # the unread ERR dropped
    fd = os.open(panel.path, os.O_RDWR | os.O_NOCTTY)
    try:
        assert _ask(panel, fd, b"SET?\n") == b"61\r\n"
        # a refusal still answers the one who asks; and questions sent together are answered
        # together, in order
        reply = _ask(panel, fd, b"hot\n").decode()
        assert reply.startswith("ERR unknown command 'hot'") and reply.count("\n") == 1, reply
        assert _ask(panel, fd, b"SET?\nAIR?\n") == b"61\r\n25.000\r\n"
    finally:
        os.close(fd)


def test_a_query_nobody_read_is_dropped_too(panel):
    """``echo SET? > PANEL`` (an answer nobody reads), then a setpoint: the reader who asks next
    reads the setpoint now in force, not the old answer."""
    _echo(panel, "SET?")
    _serve_until(panel, lambda: panel.port.unread() > 0)
    _echo(panel, "SET 40")
    _serve_until(panel, lambda: panel.setpoint_c == 40.0)
    fd = os.open(panel.path, os.O_RDWR | os.O_NOCTTY)
    try:
        assert _ask(panel, fd, b"SET?\n") == b"40\r\n"
    finally:
        os.close(fd)
