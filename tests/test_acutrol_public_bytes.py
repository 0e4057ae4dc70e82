"""Contract tests from public bytes: the Acutrol twin against the examples of the manual and the
strings of the two public clients, byte for byte, in both reply framings.

Sources (read, quoted as test data, not copied as code):

* Acutronic TM-8004-C "ACUTROL3000 Command Language (ACL)": every EXAMPLE of the commands the
  twin implements, by section (§).  Its answers are replayed field by field: the text fields
  byte for byte, the numbers to the decimals the manual prints.  The manual prints 1 to 5
  decimals for the same kind of value (``179.90000`` and ``180.0`` are both position limits,
  §4.6.6 and §4.6.2; ``10.0001`` a position, §4.10.4), the count follows each variable's
  scaling (§2.6.2.2, §4.10); the twin answers <NR2> with 6 decimals.
* IEAv-EFO/acutrol3000 (written by users of a real Acutrol3000): ``python/acutrol3000.py``
  (pyvisa over GPIB) and ``examples/routine_example.cfg``.
* AcutronicRobotics/acutrol: ``acutrol.py`` and ``ac117.json`` (a TCP socket, ``command\\r\\n``,
  the answer after its first 8 bytes).

Framings (docs/protocols.md): ``tcp``: every message answered, int32 error code and uint32
length first (little-endian), ``OK`` for a message without queries; ``gpib``: only queries
answered, one line ended by ``\\n``.

The demand semantics of issue 23 (a demand is accepted in any mode and executed when its mode
is entered, IEAv-EFO's README and routine_example.cfg) are the twin's; one manual example the
twin refused before (a mode selected before the interlock is closed, §4.5.6) now runs: the twin
selects the mode with the interlock open and servoes the axis in it when it is closed.
"""
from __future__ import annotations

import struct

import pytest

from drivers.protocols import acutrol as P
from sim_devices.twins.clock import ManualClock
from sim_devices.twins.geometry import TableGeometry
from sim_devices.twins.table import TableConfig, TableFaults, TableTwin
from sim_devices.twins.table_acutrol import AcutrolFrontEnd

FRAMINGS = ("tcp", "gpib")
def tcp_bytes(data: bytes, code: int = 0) -> bytes:
    """A reply in the tcp framing: int32 code, uint32 length, little-endian, then the data."""
    return struct.pack("<iI", code, len(data)) + data


class Acl:
    """The twin's ACL front end on a manual clock, spoken to in one framing."""

    def __init__(self, framing: str, axes: int = 3, closed: bool = True, faults=None, config=None):
        self.framing = framing
        self.clock = ManualClock()
        self.table = TableTwin(TableGeometry.default(axes), self.clock, interlocks_closed=closed,
                               faults=faults, config=config or TableConfig())
        self.fe = AcutrolFrontEnd(self.table, framing)

    def raw(self, text: str) -> bytes:
        end = b"\r\n" if self.framing == "tcp" else b"\n"
        self.table.update(self.clock.t)
        return self.fe.receive(text.encode("ascii") + end)

    def command(self, text: str) -> None:
        """A message without queries that the controller executes: ``OK`` (tcp) or nothing."""
        out = self.raw(text)
        assert out == (tcp_bytes(b"OK") if self.framing == "tcp" else b""), (text, out)
        if self.framing == "gpib":
            assert self.errors() == [], text

    def query(self, text: str) -> str:
        """A message with queries, executed without error: its answer."""
        out = self.raw(text)
        if self.framing == "tcp":
            code, length = struct.unpack("<iI", out[:8])
            assert code == 0 and length == len(out) - 8, (text, out)
            return out[8:].decode("ascii")
        assert out.endswith(b"\n") and out.count(b"\n") == 1, (text, out)
        assert self.errors() == [], text
        return out[:-1].decode("ascii")

    def refused(self, text: str) -> list[int]:
        """A message the controller refuses (in part): the error codes it queued."""
        out = self.raw(text)
        if self.framing == "tcp":
            code, length = struct.unpack("<iI", out[:8])
            assert code != 0 and length == len(out) - 8, (text, out)
        codes = self.errors()
        assert codes, text
        return codes

    def errors(self) -> list[int]:
        """Read and empty the error queue (:Status:MSG? QERROR,ALL) without touching the rest."""
        codes = [c for c, _ in self.fe.errors]
        self.fe.errors.clear()
        return codes

    def run(self, seconds: float) -> None:
        self.clock.advance(seconds)


def same_answer(got: str, manual: str) -> None:
    """``got`` answers as the manual's example: the same fields, text fields byte for byte,
    numbers equal to the decimals the manual prints."""
    g_fields = [f.split(",") for f in got.split(";")]
    m_fields = [f.split(",") for f in manual.split(";")]
    assert [len(f) for f in g_fields] == [len(f) for f in m_fields], (got, manual)
    for g, m in zip(sum(g_fields, []), sum(m_fields, [])):
        m = m.strip()
        try:
            value = float(m)
        except ValueError:
            assert g.strip() == m, (got, manual)
            continue
        decimals = len(m.partition(".")[2])
        assert round(float(g), decimals) == value, (got, manual)


@pytest.fixture(params=FRAMINGS)
def acl(request):
    return Acl(request.param)


# ------------------------------------------------------------------ 1. chains keep their subsystem
def test_the_manuals_limit_chain_executes_all_four_parts(acl):
    """TM-8004 §4.6.2: ':LIM:H P,4,180.0;L P,4,-180.0;R P,4,100.0;A P,4,2000.0', answered
    '180.0;-180.0;100.0;2000.0'.  Axis 4 does not exist on a 3-axis twin: each of the four parts
    is refused for its axis (PARAMETER OUT OF RANGE), none as a command not recognized; on the
    twin's last axis all four execute."""
    assert acl.refused(":LIM:H P,4,180.0;L P,4,-180.0;R P,4,100.0;A P,4,2000.0") == [P.ERR_RANGE] * 4
    acl.command(":LIM:H P,3,180.0;L P,3,-180.0;R P,3,100.0;A P,3,2000.0")
    same_answer(acl.query(":LIM:H? P,3;L? P,3;R? P,3;A? P,3"), "180.0;-180.0;100.0;2000.0")
    assert acl.table.axes[2].limits["P"] == [100.0, 2000.0]


def test_a_refused_header_leaves_the_parser_in_its_subsystem(acl):
    """TM-8004 §2.3: the parser location is the last colon before the last mnemonic; a
    misspelt command does not send the rest of the chain back to the root."""
    assert acl.refused(":Limit:Hx P,1,5;A P,1,200;R P,1,50") == [P.ERR_UNKNOWN]
    assert acl.table.axes[0].limits["P"] == [50.0, 200.0]
    # a refused argument, too (PARAMETER OUT OF RANGE: beyond the absolute limit)
    assert acl.refused(":L:R P,1,5000;A P,1,300") == [P.ERR_RANGE]
    assert acl.table.axes[0].limits["P"] == [50.0, 300.0]
    # a bad argument list (a syntax error) keeps the subsystem as well
    assert acl.refused(":Read:Position? 1,2;Rate? 1") == [P.ERR_SYNTAX]
    # the manual's own error example still refuses both halves (§2.1, misuse of ';')
    assert acl.refused(":Dem;Pos 3,10.50000") == [P.ERR_UNKNOWN, P.ERR_UNKNOWN]


# ------------------------------------------------------------------ 2. High/LowPosition (§4.6.6, §4.6.7)
def test_high_and_low_position_limits_as_the_manual_writes_them(acl):
    for text in (":LIM:HPOS P,2,179.0", ":L:H R,3,45.0;H R,1,90.0", ":L:H 1,-180",
                 ":LIM:LPOS S,2,-179.0", ":L:L T,3,-45.0;H T,3,45.0", ":L:L P,1,50.0;H P,1,100.0",
                 ":Limit:HighPosition P,3,179.9", ":Limit:LowPosition P,3,-45"):
        acl.command(text)
    same_answer(acl.query(":LIM:HPOS? P,3"), "179.90000")       # §4.6.6
    same_answer(acl.query(":LIM:LPOS? P,3"), "-45.00000")       # §4.6.7
    same_answer(acl.query(":L:H? 2"), "179.0")                  # <axis> only: position mode's
    same_answer(acl.query(":L:L? 2;:L:L? S,2;:L:H? R,3;H? R,1;H? T,3;L? T,3"),
                "-180.0;-179.0;45.0;90.0;45.0;-45.0")
    same_answer(acl.query(":L:L? P,1;H? P,1"), "50.0;100.0")
    # limits on the limits (§4.6.1): the twin's absolute position limits are -180 and 180
    assert acl.refused(":L:H P,1,181") == [P.ERR_RANGE]
    assert acl.refused(":L:L P,9,0") == [P.ERR_RANGE]


def test_the_position_limits_leave_the_other_prefixes_as_they_were():
    for text, key in ((":L:A P,1,10", "limit_acceleration"), (":L:R P,1,10", "limit_rate"),
                      (":L:H P,1,10", "limit_high"), (":L:L P,1,10", "limit_low"),
                      (":L:H 1,10", "limit_high_axis"), (":LIM:HPOS? P,3", "limit_high_query"),
                      (":L:H? 2", "limit_high_axis_query"), (":LIM:LPOS? P,3", "limit_low_query"),
                      (":limit:absolute? 1", "limit_absolute_query"),
                      (":limit ALL,P,100,100,1", "limit_set"), (":I:C 1", "interlock_close"),
                      (":R:A 1", "read_acceleration"), (":R:V 1082", "read_variable"),
                      (":D:D 1,2", "demand_delta"), (":D:O 1,1,1,1", "demand_oscillator"),
                      (":con:osc? 1", "configure_oscillator_query"),
                      (":Con:Osc 1", "configure_oscillator_query"),
                      (":Con:Osc 2,Disab,2.000000,0.100000,Pos,Log", "configure_oscillator")):
        assert P.parse_command(text).command.key == key, text


def test_continuous_axes_ignore_the_position_limits(acl):
    """§4.6.6: "used only if the ACP is set for LIMITED motion"; §4.7.4: continuous rotary
    axes take the least path.  The twin's axes are continuous."""
    acl.command(":L:L P,1,-10;H P,1,10;:Mode:Position 1;:Demand:Position 1,90")
    acl.run(30.0)
    same_answer(acl.query(":Read:Position? 1"), "90.0000")


# ------------------------------------------------------------------ 3. the status byte (§3.10, §4.11)
def test_the_status_byte_examples_of_the_manual():
    """§3.10: '*STB?' -> '65' (bit 6 MSS and bit 0 SI).  The other example, '2' (bit 1 ACP
    without MSS), needs the ACP summary, which the twin does not simulate; the rule it shows
    (a set bit that *SRE does not enable leaves MSS clear) is checked with bit 7 below."""
    for framing in FRAMINGS:
        acl = Acl(framing, faults=TableFaults(trip_axis=1, trip_at_s=0.0))
        assert acl.query("*SRE?") == "1"            # power-up: SI enabled (unverified)
        assert acl.query("*STB?") == "65"
        acl.command(":INT:RES")
        assert acl.query("*STB?") == "0"
        acl.command("*SRE 0")                       # §3.9 example
        assert acl.query("*SRE?") == "0"
        acl.command("*SRE 32")
        assert acl.query("*SRE?") == "32"           # §3.9 example


def test_bit_7_stays_while_the_error_queue_holds_messages(acl):
    """§4.11.4: "the status bit remains true as long as the queue is not empty"; *STB? does
    not empty it; MSS only for a bit *SRE enables (§3.10: 'at least one enabled event')."""
    def ask(text):                                  # the answer, the queue left alone
        out = acl.raw(text)
        return (out[8:] if acl.framing == "tcp" else out[:-1]).decode()

    acl.raw(":Demand:Posn 3,10.5")                  # §2.1 error example
    assert ask("*STB?;:Status:STB?") == "128;128"
    assert ask("*STB?") == "128"
    acl.fe.sre = P.STB_SI | P.STB_EQ
    assert ask(":Status:STB?") == "192"
    message = ask(":Status:MSG? QERROR,ALL")
    assert message.startswith(f"{P.ERR_UNKNOWN},") and ";" not in message
    assert ask("*STB?") == "0"
    assert acl.query(":Status:MSG? QERROR") == ""  # an empty queue: a null string, no error
    acl.raw(":Demand:Posn 3,10.5")
    acl.raw(":Demand:Posn 3,10.5")
    assert ask("*STB?") == "192"
    assert ask(":Status:MSG? QERROR,1").startswith(f"{P.ERR_UNKNOWN},")
    assert ask("*STB?") == "192"                    # one message left
    acl.command("*CLS")
    assert ask("*STB?") == "0"
    acl.raw(":Demand:Posn 3,10.5")
    acl.command(":Status:MSGCLR QERROR")
    assert ask("*STB?") == "0"


def test_the_public_pyvisa_clients_interlock_check_holds():
    """IEAv-EFO check_error(): '*stb?' == '65\\n' means an interlock fault; a refused command
    alone (bit 7) is not 65."""
    acl = Acl("gpib", faults=TableFaults(trip_axis=1, trip_at_s=5.0))
    acl.raw(":mode:synt 1")                         # its stop() sends this; not simulated
    assert acl.raw("*stb?") == b"128\n"
    acl.errors()
    acl.run(6.0)
    assert acl.raw(":interlock? 1") == b"Fault\n"
    assert acl.raw("*stb?") == b"65\n"


def test_the_station_driver_ignores_a_queue_left_by_an_earlier_session():
    """gpib framing: bit 7 now stays set while the queue holds messages; the driver empties it
    at connect (*CLS) instead of reading every later message as refused."""
    from drivers.base import TableSettings
    from drivers.registry import open_table
    from sim_devices.truth import default_truth
    from sim_devices.twins.serve import BenchOptions, BenchServer
    import serial

    with BenchServer(default_truth(3), BenchOptions(speed=50.0, axes=1, table_framing="gpib")) as server:
        with serial.serial_for_url(server.table_path, timeout=1.0) as raw:
            raw.write(b":Demand:Posn 1,10.5\n:mode:synt 1\n")       # two errors queued
            raw.write(b"*STB?\n")
            assert raw.readline() == b"128\n"
        with open_table(f"{server.table_path}#gpib", "acutrol", TableSettings()) as table:
            table.reset_interlocks()
            assert table.close_interlocks().ok
            assert table.read_modes() == ["off"]
        assert not server.table_frontend.errors


# ------------------------------------------------------------------ 4. limits up to the public figures
def test_limits_up_to_the_manual_and_the_public_client(acl):
    assert TableConfig().max_rate_dps == 1000.0 and TableConfig().max_accel_dps2 == 8300.0
    acl.command(":LIM:ACC P,1,1500.0")                             # §4.6.2 example
    same_answer(acl.query(":LIM:ACC? P,1"), "1500.0")
    # IEAv-EFO set_limits(lim_acc=8300, lim_rate=1000)
    for text in (":lim:acc pos,1,8300", ":lim:acc rate,1,8300", ":lim:acc synt,1,8300",
                 ":lim:rate pos,1,1000", ":lim:rate rate,1,1000", ":lim:rate synt,1,1000"):
        acl.command(text)
    assert acl.table.axes[0].limits == {"P": [1000.0, 8300.0], "R": [1000.0, 8300.0]}
    rate, acc, jerk, low, high, vtrip = (float(v) for v in acl.query(":limit:absolute? 1").split(","))
    assert (rate, acc, low, high) == (1000.0, 8300.0, -180.0, 180.0)
    assert acl.refused(":lim:acc pos,1,8301") == [P.ERR_RANGE]
    assert acl.refused(":lim:rate rate,1,1000.5") == [P.ERR_RANGE]


# ------------------------------------------------------------------ 5. the missing forms
def test_configure_oscillator(acl):
    """§4.2.19; IEAv-EFO set_oscillation(): ':con:osc 1,Enable,2.0,0.1,Pos,Lin', ':con:osc? 1'."""
    assert acl.query(":con:osc? 1") == "Disable, 5.000000, 0.100000, Position, Logarithmic"
    acl.command(":con:osc 1,Enable,2.0,0.1,Pos,Lin")
    assert acl.query(":con:osc? 1") == "Enable, 2.000000, 0.100000, Position, Linear"
    acl.command(":Con:Osc 2,Disab,2.000000,0.100000,Pos,Log")     # §4.2.19 example
    acl.command(":Con:Osc 1,Enable,5,0.1,Accel,Log")
    assert acl.query(":Con:Osc 1") == "Enable, 5.000000, 0.100000, Acceleration, Logarithmic"
    assert acl.refused(":con:osc 1,Maybe,2.0,0.1,Pos,Lin") == [P.ERR_RANGE]
    assert acl.refused(":con:osc 1,Enable,2.0,0.1,Jerk,Lin") == [P.ERR_RANGE]
    assert acl.refused(":con:osc 1,Enable,-2.0,0.1,Pos,Lin") == [P.ERR_RANGE]
    assert acl.refused(":con:osc? 4") == [P.ERR_RANGE]


def test_the_generic_limit_form(acl):
    """§4.6 ':Limit <axis|ALL>,<mode>,<rate_lim>,<acc_lim>,<jerk_lim>'; IEAv-EFO
    routine_example.cfg ':limit ALL,P,100,100,1' and ':limit ALL,R,100,100,1'."""
    acl.command(":limit ALL,P,100,100,1")
    acl.command(":limit ALL,R,100,100,1")
    for ax in acl.table.axes:
        assert ax.limits == {"P": [100.0, 100.0], "R": [100.0, 100.0]}
    acl.command(":Limit 2,Synthesis,50,60,70")
    same_answer(acl.query(":L:R? S,2;A? S,2"), "50.0;60.0")
    # all checked before any is set
    assert acl.refused(":limit ALL,P,200,9000,1") == [P.ERR_RANGE]
    assert acl.table.axes[0].limits["P"] == [100.0, 100.0]
    assert acl.refused(":limit 1,P,100,100,0") == [P.ERR_RANGE]


def test_read_variable(acl):
    """§4.10.3 ':Read:Variable? <variable>' (axis * 1000 + number; ':R:V' as its examples
    write it); the numbers the manuals give: x000/x001 demands (TM-9374A table 3-1), x082,
    x083, x176 estimated position, rate, acceleration (TM-9374A), x163 (TM-8004 §4.2.5)."""
    acl.command(":Mode:Position 2;:Demand:Position 2,30")
    acl.run(20.0)
    acl.command(":Mode:Rate 1;:Demand:Rate 1,10")
    acl.run(20.0)
    same_answer(acl.query(":R:V? 2000;V? 2082;V? 2163;V? 2083;V? 2176"), "30.0;30.0;30.0;0.0;0.0")
    same_answer(acl.query(":Read:Variable? 1001;V? 1083;V? 1176"), "10.0;10.0;0.0")
    same_answer(acl.query(":R:V 1001,2000"), "10.0,30.0")
    # the manual's examples name variables the twin does not back: refused, the chain goes on
    assert acl.refused(":R:V 3100") == [P.ERR_RANGE]                  # §4.10.3 (x100, axis 3)
    out = acl.raw(":R:V? 1021;V? 2083")                              # §4.10.3
    assert acl.errors() == [P.ERR_RANGE]
    assert out.endswith(b"0.000000" + (b"\n" if acl.framing == "gpib" else b""))
    assert acl.refused(":R:V 4082") == [P.ERR_RANGE]                  # no axis 4
    assert acl.refused(":R:V 1xyz") == [P.ERR_RANGE]


def test_demand_oscillator_and_delta_queries(acl):
    acl.command(":DEM:OSC 1,10.0,2.50,90")                          # §4.3.4
    same_answer(acl.query(":DEM:OSC? 1"), "10.000;2.5000;90.00000")   # §4.3.4
    acl.command(":dem:osc 1,0,0,0")                                  # IEAv-EFO send_oscillation(0, 0)
    same_answer(acl.query(":D:O? 1"), "0.0;0.0;0.0")
    assert acl.refused(":dem:osc 1,1,-1,0") == [P.ERR_RANGE]
    acl.command(":Mode:Position 1;Position 2")
    acl.command(":D:D 2,1")
    acl.command(":DEM:Delta 1,-45.0")                                # §4.3.2
    same_answer(acl.query(":DEM:DEL? 2;DEL? 1"), "1.00000;-45.00000")  # §4.3.2
    same_answer(acl.query(":DEM:POS? 1"), "-45.0")


def test_utility_queries(acl):
    assert acl.query(":U:L?") == "OFF"                               # §4.14.2 example
    acl.command(":U:L ON")
    acl.command(":utility:lockout on")                               # AcutronicRobotics
    assert acl.query(":U:L?") == "ON"
    acl.command(":U:F F")
    assert acl.query(":U:F?") == "FLOAT"                             # §4.14.1 example
    assert acl.refused(":UTILITY:FORMAT BINARY") == [P.ERR_ILLEGAL]  # not simulated


# ------------------------------------------------------------------ 6. the manual's other examples
def test_mode_examples(acl):
    """§4.7: ':MODE? 2' -> 'P'; ':M? 1;:M? 2;:M? 3' -> 'P;R;P'; the §4.7.3-5 commands."""
    for text in (":MODE:POS 3", ":M:P 2", ":M:P 1;P 2"):
        acl.command(text)
    assert acl.query(":MODE? 2") == "P"
    acl.command(":MODE:RATE 3")
    acl.command(":Mode:Position 1;Rate 2")                          # §2.2.2
    acl.command(":MODE:POS 3")
    assert acl.query(":M? 1;:M? 2;:M? 3") == "P;R;P"
    acl.command(":MODE:OFF 1")
    acl.command(":M:O 2;O 3")
    assert acl.query(":M? 1;:M? 2;:M? 3") == "O;O;O"
    acl.command(":Mode ALL,Rate")
    assert acl.query(":M? 1;:M? 2;:M? 3") == "R;R;R"
    assert acl.refused(":MODE? 7") == [P.ERR_RANGE]


def test_demand_examples(acl):
    """§2.1, §2.3, §4.3.5, §4.3.6 in position and rate mode."""
    acl.command(":M:P 1;P 2;P 3")
    for text in (":Demand:Position 3,10.5", ":Dem:Pos 3,10.50000", ":D:P 3,10.5"):   # §2.1
        acl.command(text)
        same_answer(acl.query(":DEM:POS? 3"), "10.5")
    for text in (":Demand:Posn 3,10.5", ":Dem;Pos 3,10.50000", ":D:P,3,10.5"):       # §2.1 errors
        assert acl.refused(text)
    acl.command(":DEM:POS 1,135.223")                                # §4.3.5
    same_answer(acl.query(":DEM:POS? 1"), "135.223")
    acl.command(":DEM:POS 2,170.0;POS 1,-32.19877")
    same_answer(acl.query(":DEM:POS? 2;POS? 1"), "170.00000;-32.19877")   # §4.3.5
    acl.command(":Demand:Position 1,123.45678")                      # §2.3
    acl.command(":Dem:Pos 2,0.01;:Mode:Pos 2;Rate 1")                # §2.3 (axis 2 in position mode)
    acl.command(":Mode:Rate 3")
    acl.command(":Demand:Pos 2,0.01;Rate 3,100")                     # §2.3
    acl.command(":DEM:POS 2,0.01")
    acl.command(":DEM:RATE 3,100")
    acl.command(":Mode:Rate 2")
    acl.command(":DEM:RATE 2,100.0")                                 # §4.3.6
    acl.command(":D:R 1,1.11111;R 3,45.125")                         # §4.3.6
    same_answer(acl.query(":DEM:RATE? 2;RATE? 1;RATE? 3"), "100.0;1.11111;45.125")


def test_interlock_examples():
    for framing in FRAMINGS:
        acl = Acl(framing, closed=False)
        acl.command(":INT:CLOSe 1")                                  # §4.5.1
        acl.command(":I:C 1;C 2")
        assert acl.query(":interlock? 1;:interlock? 2;:interlock? 3") == "Close;Close;Open"
        acl.command(":INT:OPEN 1")                                   # §4.5.5
        acl.command(":I:O 1;O 2;O 3")
        acl.command(":INT:RES")                                      # §4.5.6
        acl.command(":INT:RES;CLOS 1")
        assert acl.query(":Interlock:Control? 1") == "Close"        # §4.5.3's answer words


@pytest.mark.parametrize("framing", FRAMINGS)
def test_the_interlock_reset_example_sets_demand_and_mode_before_closing(framing):
    """§4.5.6: ':D:P 2,0.0;:I:R;:M:P 2;:I C 2' (set position on axis 2, reset, position mode,
    close and servo); its ':I C 2' read as ':I:C 2' (a space for a colon in the manual)."""
    acl = Acl(framing, closed=False)
    acl.command(":D:P 2,0.0;:I:R;:M:P 2;:I:C 2")
    assert acl.query(":M? 2;:Interlock? 2") == "P;Close"


def test_read_examples(acl):
    """§4.10.1, §4.10.4, §4.10.5: '10.0001;44.1250;0.0001' once the axes are there."""
    acl.command(":L:R P,1,100;R P,2,100;R P,3,100")
    acl.command(":M:P 1;P 2;P 3")
    acl.command(":D:P 1,10.0001;P 2,44.1250;P 3,0.0001")
    acl.run(30.0)
    same_answer(acl.query(":R:P? 1;P? 2;P? 3"), "10.0001;44.1250;0.0001")
    same_answer(acl.query(":READ:POS? 1;POS 2;POS 3"), "10.0001;44.1250;0.0001")
    same_answer(acl.query(":READ:POS? 2"), "44.1250")
    same_answer(acl.query(":READ:ACC 1"), "0.0")
    same_answer(acl.query(":R:A 2;R 2;P 2"), "0.0;0.0;44.1250")
    same_answer(acl.query(":READ:RATE? 1"), "0.0")
    same_answer(acl.query(":READ:RATE? 2;POS? 1"), "0.0;10.0001")
    same_answer(acl.query(":READ:POSition 2"), "44.1250")           # §2.6.3
    assert acl.refused(":Read:Position? ALL") == [P.ERR_QUERY_ALL]


def test_common_command_examples(acl):
    """§3.2, §3.3, §3.4."""
    acl.command("*ESE 0")
    assert acl.query("*ESE?") == "0"
    acl.command("*ESE 16")
    acl.command("*ESE 255")
    assert acl.query("*ESE?") == "255"
    assert acl.query("*ESR?") == "0"
    acl.refused(":READ:POS? 9")                   # an execution error: bit 4 (IEEE 488.2)
    assert acl.query("*ESR?") == "16"
    assert acl.query("*ESR?") == "0"
    idn = acl.query("*IDN?")
    assert len(idn.split(",")) == 4 and len(idn) <= 72


# ------------------------------------------------------------------ the public clients' strings
def test_ieav_efo_acutrol3000_py_strings():
    """Every string python/acutrol3000.py sends, in its framing (GPIB: only queries answered),
    in the order of its functions; set_limits() with its defaults (8300, 1000)."""
    acl = Acl("gpib", axes=1, closed=False)
    assert "ACUTROL3000" in acl.raw("*idn?").decode()
    # initialize(): then stop() = send_oscillation(0, 0), ':mode:rate 1', ':dem:rate 1,0'
    for text in (":Interlock:Reset", ":mode:off 1", ":int:close 1"):
        assert acl.raw(text) == b""
    assert acl.raw(":mode:synt 1") == b""         # synthesis is not simulated: queued error
    assert acl.errors() == [P.ERR_ILLEGAL]
    for text in (":dem:osc 1,0,0,0", ":mode:rate 1", ":dem:rate 1,0"):
        acl.command(text)
    # check_error()
    assert acl.raw(":interlock? 1") == b"Close\n"
    assert acl.raw("*stb?") == b"0\n"
    # limits(), set_limits()
    assert len(acl.raw(":limit:absolute? 1").split(b",")) == 6
    for text in (":lim:acc pos,1,8300", ":lim:acc rate,1,8300", ":lim:acc synt,1,8300",
                 ":lim:rate pos,1,1000", ":lim:rate rate,1,1000", ":lim:rate synt,1,1000"):
        acl.command(text)
    for text, value in ((":limit:acc? pos,1", 8300.0), (":limit:acc? rate,1", 8300.0),
                        (":limit:acc? synt,1", 8300.0), (":limit:rate? pos,1", 1000.0),
                        (":limit:rate? rate,1", 1000.0), (":limit:rate? synt,1", 1000.0)):
        assert float(acl.query(text)) == value, text
    # set_oscillation()
    acl.command(":con:osc 1,Enable,2.0,0.1,Pos,Lin")
    assert acl.query(":con:osc? 1") == "Enable, 2.000000, 0.100000, Position, Linear"
    # send_rate(20): ':mode? 1' is not "Rate\n", so ':mode 1,rate' then the demand
    assert acl.raw(":mode? 1") == b"R\n"
    acl.command(":mode 1,rate")
    acl.command(":dem:rate 1,20")
    acl.run(5.0)
    pos, rate, acc = (float(x) for x in acl.query(":read:pos? 1;rate? 1;acc? 1").split(";"))
    assert rate == pytest.approx(20.0, abs=1e-3) and acc == 0.0
    assert float(acl.query(":read:rate? 1")) == pytest.approx(20.0, abs=1e-3)
    assert float(acl.query(":read:acc? 1")) == 0.0
    # send_position(30), send_delta_position(-10)
    acl.command(":int:close 1")
    acl.command(":mode 1,pos")
    acl.command(":dem:pos 1,30")
    acl.run(10.0)
    assert acl.raw(":mode? 1") == b"P\n"
    acl.command(":dem:delta 1,-10")
    acl.run(10.0)
    assert float(acl.query(":read:pos? 1")) == pytest.approx(20.0, abs=1e-4)
    # terminate()
    acl.command(":int:open 1")
    assert acl.raw(":interlock? 1") == b"Open\n"


def test_ieav_efo_routine_example_cfg():
    """examples/routine_example.cfg, line by line (comments after '%' dropped), on two axes
    with their interlocks closed, after moving both axes away from 0: ':d:p 1,0' ... ':m:p ALL'
    "send all axis to demanded position"; ':d:r 1,0' then ':m:r 1' "go to set demanded rate"."""
    acl = Acl("gpib", axes=2)
    acl.command(":M:P 1;P 2;:D:P 1,40;P 2,-40")
    acl.run(20.0)
    for text in (":Interlock:Reset", ":limit ALL,P,100,100,1", ":limit ALL,R,100,100,1",
                 ":d:p 1,0", ":d:p 2,0", ":m:p ALL"):
        acl.command(text)
    acl.run(20.0)
    same_answer(acl.query(":read:position 1;:read:position 2"), "0.0000;0.0000")
    acl.command(":d:r 1,0")
    acl.command(":m:r 1")
    acl.run(5.0)
    same_answer(acl.query(":read:rate 1;:m? 1"), "0.000;R")
    for text, rate in ((":d:r 1,10", 10.0), (":d:r 1,-10", -10.0), (":d:r 1,0", 0.0)):
        acl.command(text)
        acl.run(5.0)
        assert float(acl.query(":read:rate 1")) == pytest.approx(rate, abs=1e-3)


def test_ieav_efo_routine_example_cfg_limits_and_reset():
    """The lines of routine_example.cfg that need no demand semantics."""
    for framing in FRAMINGS:
        acl = Acl(framing, axes=2)
        for text in (":Interlock:Reset", ":limit ALL,P,100,100,1", ":limit ALL,R,100,100,1"):
            acl.command(text)
        same_answer(acl.query(":limit:rate? P,2;:limit:acc? R,1"), "100.0;100.0")


def test_acutronicrobotics_acutrol_strings_over_tcp():
    """acutrol.py and ac117.json: 'command\\r\\n', every setting answered 'OK' after 8 bytes;
    its numbers formatted '06.3f'."""
    acl = Acl("tcp", axes=1, closed=False)
    ok = tcp_bytes(b"OK")
    assert ok == b"\x00\x00\x00\x00\x02\x00\x00\x00OK"
    for text in (":utility:lockout on", ":interlock:open 1", ":interlock:reset 1", ":interlock:close 1"):
        assert acl.raw(text) == ok, text                              # startup
    # command_rate(0.5 rad/s) from MODE_NONE
    assert acl.raw(":mode:rate 1") == ok
    deg = format(57.2957795 * 0.5, "06.3f")
    assert acl.raw(":demand:rate 1, " + deg) == ok
    acl.run(5.0)
    assert float(acl.raw(":read:rate 1")[8:]) == pytest.approx(float(deg), abs=1e-3)
    assert 0.0 <= float(acl.raw(":read:position 1")[8:]) < 360.0
    # command_position(1.0 rad) from MODE_RATE: command_rate(0) first
    assert acl.raw(":demand:rate 1, " + format(0.0, "06.3f")) == ok
    acl.run(5.0)
    assert acl.raw(":mode:position 1") == ok
    deg = format((57.2957795 * 1.0) % 360, "06.3f")
    assert acl.raw(":demand:position 1, " + deg) == ok
    acl.run(10.0)
    assert float(acl.raw(":read:position 1")[8:]) == pytest.approx(float(deg), abs=1e-4)
    assert acl.raw(":demand:position 1, " + format((57.2957795 * 6.0) % 360, "06.3f")) == ok
    for text in (":mode:off 1", ":interlock:open 1"):
        assert acl.raw(text) == ok, text                              # shutdown
