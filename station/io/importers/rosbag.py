"""ROS bags (ROS 1 ``.bag``; ROS 2 bag directories in sqlite3 ``.db3`` or MCAP storage) of
``sensor_msgs/Imu`` messages -> a Recording (station/io/importers/recording.py), read with the
pure-Python ``rosbags`` package.

``sensor_msgs/Imu`` carries ``linear_acceleration`` in m/s^2 and ``angular_velocity`` in rad/s
(REP 103, the message definition), so the units are fixed.  ``orientation`` and the three
covariance matrices are ignored.  Time is each message's ``header.stamp`` (the sensor's time,
the default) or, with ``stamps="bag"``, the time the recorder received it.  One topic is read:
the only Imu topic of the bag, or the one named.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from station.core.errors import UserError
from station.core.memory_cap import budget_for, memory_cap
from station.io.importers.recording import Recording

IMU_TYPE = "sensor_msgs/msg/Imu"
MAX_MESSAGES = 20_000_000
INITIAL_CAPACITY = 1 << 16       # messages the arrays hold before they first grow
STAMPS = ("header", "bag")
FORMATS = ("rosbag1", "sqlite3", "mcap")


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


RETIME_SPAN_TOLERANCE = 0.01    # --rate-hz: the stamps' span and the messages' count at R Hz agree to 1 %


LOSS_BLOCK = 51                 # messages per block of the lost-message check (a median each)


def _no_message_lost(path, topic, t: np.ndarray, rate_hz: float) -> None:
    """Before re-timing by the count: the stamps less the count's even times, r_k = t_k - k / R,
    jitter about a constant; a lost message steps them by 1 / R from there on.  The medians of
    blocks of LOSS_BLOCK messages (the jitter averaged out) two blocks apart differing by more
    than half a period is a lost message (or a step in the stamps): refused, naming where."""
    n = len(t) // LOSS_BLOCK
    if n < 3:
        return
    r = t[:n * LOSS_BLOCK] - np.arange(n * LOSS_BLOCK) / rate_hz
    med = np.median(r.reshape(n, LOSS_BLOCK), axis=1)
    jump = med[2:] - med[:-2]
    j = int(np.argmax(np.abs(jump)))
    if abs(jump[j]) > 0.5 / rate_hz:
        raise UserError(f"{path}: topic {_shown(topic)}: --rate-hz {rate_hz:g}: the stamps step by {jump[j] * 1e3:+.3g} ms "
                        f"against the count at {rate_hz:g} Hz near message {(j + 1) * LOSS_BLOCK + 1}: a message "
                        "was lost (or the stamps stepped); re-timing by the count would shift every later sample")


def read_rosbag(path, *, topic: str | None = None, stamps: str = "header", rate_hz: float | None = None) -> Recording:
    """sensor_msgs/Imu messages of ``topic``.  ``rate_hz``: re-time the messages evenly at that
    rate (a driver stamped at receive time, whose stamps jitter by the transport's delays),
    after checking that the stamps' span agrees with the messages' count at that rate (a lost
    message would shift every later sample: refused, naming both)."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    if stamps not in STAMPS:
        raise UserError(f"--stamps: one of {', '.join(STAMPS)}, not {stamps!r}")
    if not path.exists():
        raise UserError(f"{path}: no such file or directory")
    for file in [path] if not path.is_dir() else sorted(path.iterdir()):
        if not (file.is_file() or file.is_dir()):        # a FIFO hung the reader
            raise UserError(f"{file}: not a regular file (a FIFO, device or socket): cannot read it as a ROS bag")
    size = sum(f.stat().st_size for f in ([path] if not path.is_dir() else path.iterdir()) if f.is_file())
    with memory_cap(budget_for(size), str(path)):
        return _read(path, AnyReader, topic, stamps, rate_hz)


def _read(path, AnyReader, topic, stamps, rate_hz) -> Recording:
    try:
        reader = AnyReader([path], default_typestore=_typestore())
        reader.open()
    except MemoryError:
        raise
    except Exception as e:        # rosbags raises its own error types for every kind of bad bag
        raise UserError(f"{path}: not a readable ROS bag: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    try:
        connections = _connections(reader, path)
        imu = [c for c in connections if c.msgtype == IMU_TYPE]
        topics = sorted({c.topic for c in imu})
        if topic is None:
            if len(topics) != 1:
                others = sorted({f"{_shown(c.topic)} ({_shown(c.msgtype)})" for c in connections})
                raise UserError(f"{path}: {len(topics)} {IMU_TYPE} topics ({', '.join(map(_shown, topics)) or 'none'}): "
                                + ("name one with --topic" if topics else f"the bag has {', '.join(others)[:300]}"))
            topic = topics[0]
        elif topic not in topics:
            raise UserError(f"{path}: no {IMU_TYPE} topic {_shown(topic)} (Imu topics: "
                            f"{', '.join(map(_shown, topics)) or 'none'})")
        conns = [c for c in imu if c.topic == topic]
        count = _stated_count(path, topic, conns)
        # the arrays grow as messages come: the count the bag states (its index, a ROS 2 bag's
        # metadata.yaml) is bytes from outside, a hint for the first size only
        t_ns = np.empty(min(count, INITIAL_CAPACITY), dtype=np.int64)
        data = np.empty((len(t_ns), 6))
        k = 0
        for conn, bag_ns, raw in _guarded(reader.messages(connections=conns), path, topic):
            if k >= MAX_MESSAGES:
                raise UserError(f"{path}: topic {_shown(topic)}: more than {MAX_MESSAGES} messages")
            if k >= len(t_ns):
                grow = max(2 * len(t_ns), 1024)
                t_ns = np.resize(t_ns, grow)
                data = np.resize(data, (grow, 6))
            try:
                msg = reader.deserialize(raw, conn.msgtype)
                a, w = msg.linear_acceleration, msg.angular_velocity
                data[k] = (a.x, a.y, a.z, w.x, w.y, w.z)
                t_ns[k] = (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                           if stamps == "header" else bag_ns)
            except MemoryError:
                raise
            except Exception as e:
                raise UserError(f"{path}: topic {_shown(topic)}: message {k + 1}: cannot be decoded as {IMU_TYPE}: "
                                f"{str(e)[:120] or type(e).__name__}") from None
            k += 1
    finally:
        try:
            reader.close()
        except Exception:     # noqa: BLE001 - closing a damaged bag: what was read (or refused) stands
            pass
    t_ns, data = t_ns[:k], data[:k]
    if k and stamps == "header" and np.all(t_ns == t_ns[0]):
        raise UserError(f"{path}: topic {_shown(topic)}: every header stamp is {t_ns[0]} ns: the driver does not "
                        "stamp its messages; use --stamps bag (the recorder's time)")
    t = (t_ns - (t_ns[0] if k else 0)).astype(float) * 1e-9
    time_from = f"{'header.stamp' if stamps == 'header' else 'bag receive time'} of {_shown(topic)}"
    if rate_hz is not None:
        if not (np.isfinite(rate_hz) and 0.01 <= rate_hz <= 1e6):
            raise UserError(f"--rate-hz {rate_hz}: must be a sample rate within 0.01 Hz - 1 MHz")
        span, even = (float(t[-1]) if k else 0.0), (k - 1) / rate_hz
        if k > 1 and abs(span - even) > RETIME_SPAN_TOLERANCE * even:
            raise UserError(f"{path}: topic {_shown(topic)}: --rate-hz {rate_hz:g}: {k} messages at {rate_hz:g} Hz span "
                            f"{even:.3f} s, their stamps {span:.3f} s: messages were lost or the rate is not "
                            f"{rate_hz:g} Hz (re-timing would shift every later sample)")
        _no_message_lost(path, topic, t, rate_hz)
        t = np.arange(k, dtype=float) / rate_hz
        time_from = f"message count at {rate_hz:g} Hz (--rate-hz; the stamps agree with it)"
    info = {"format": "ROS bag", "topic": topic, "stamps": stamps, "rate_hz": rate_hz,
            "ignored": "orientation and the covariance matrices", "first_stamp_ns": int(t_ns[0]) if k else None}
    return Recording(source=str(path), t=t, accel=data[:, :3], gyro=data[:, 3:], accel_unit="m/s^2",
                     gyro_unit="rad/s", lines=np.arange(1, k + 1), where="message",
                     time_from=time_from, time_option="--rate-hz" if rate_hz is not None else "", info=info)


def _shown(text) -> str:
    """A topic or type name from a bag, for a one-line message: as it is when printable, else
    quoted with its escapes (a newline in a name cannot split the message); at most 80 characters."""
    shown = text if text.isprintable() else repr(text)
    return shown if len(shown) <= 80 else shown[:77] + "..."


def _connections(reader, path) -> list:
    """The bag's connections, each with a topic and a message type that are text (a ROS 2 bag's
    metadata.yaml is a file from outside: a list or a number there is refused, naming the bag)."""
    try:
        connections = list(reader.connections)
    except Exception as e:       # noqa: BLE001 - the reader's own parse of a damaged index
        raise UserError(f"{path}: not a readable ROS bag: {str(e).splitlines()[0][:120] if str(e) else type(e).__name__}") from None
    for c in connections:
        for field, value in (("topic", c.topic), ("message type", c.msgtype)):
            if not isinstance(value, str):
                raise UserError(f"{path}: a connection's {field} is {str(value)[:40]!r}, not text (a damaged "
                                "index or metadata.yaml)")
    return connections


def _stated_count(path, topic, conns) -> int:
    """The messages of ``conns`` the bag states (its index; a ROS 2 bag's metadata.yaml): a whole
    number >= 0 each, at most MAX_MESSAGES in all, else the bag is refused naming the field."""
    total = 0
    for c in conns:
        n = c.msgcount
        if not isinstance(n, int) or isinstance(n, bool) or n < 0:
            raise UserError(f"{path}: topic {_shown(topic)}: the bag's message count is {str(n)[:40]!r}, not a whole "
                            "number >= 0 (a damaged index or metadata.yaml)")
        total += n
    if total > MAX_MESSAGES:
        raise UserError(f"{path}: topic {_shown(topic)}: {total} messages, more than {MAX_MESSAGES}")
    return total


def _guarded(messages, path, topic):
    """The messages, a damaged bag (rosbags' own errors, and AssertionError, struct.error, ... of
    its readers on flipped bytes) a UserError naming the file."""
    k = 0
    while True:
        try:
            item = next(messages)
        except StopIteration:
            return
        except (UserError, MemoryError):      # MemoryError: the caller's memory_cap names it
            raise
        except Exception as e:    # noqa: BLE001 - bytes from outside: any failure of the reader
            raise UserError(f"{path}: topic {_shown(topic)}: damaged after {k} message(s): "
                            f"{str(e).splitlines()[0][:120] if str(e) else type(e).__name__}") from None
        k += 1
        yield item


def write_imu_bag(path, t_s, accel_mps2, gyro_rads, *, fmt: str = "mcap", topic: str = "/imu/data",
                  frame_id: str = "imu_link", start_ns: int = 1_700_000_000_000_000_000,
                  compression: str | None = None) -> Path:
    """Write samples as sensor_msgs/Imu messages into a new bag (``rosbag1``: a .bag file;
    ``sqlite3``/``mcap``: a ROS 2 bag directory), header stamps and bag times from ``t_s``; no
    orientation (its covariance[0] = -1, as the message definition asks), covariances 0;
    ``compression`` ("bz2" or "lz4") compresses a ROS 1 bag's chunks, as ``rosbag record -j``/``--lz4``."""
    from rosbags.typesys.stores.ros2_humble import (builtin_interfaces__msg__Time as Time,
                                                    geometry_msgs__msg__Quaternion as Quaternion,
                                                    geometry_msgs__msg__Vector3 as Vector3,
                                                    sensor_msgs__msg__Imu as Imu, std_msgs__msg__Header as Header)

    if fmt not in FORMATS:
        raise ValueError(f"fmt: one of {FORMATS}")
    path = Path(path)
    store = _typestore()
    no_orientation = np.zeros(9)
    no_orientation[0] = -1.0
    zero = np.zeros(9)

    def messages():
        for k in range(len(t_s)):
            ns = start_ns + int(round(t_s[k] * 1e9))
            a, w = accel_mps2[k], gyro_rads[k]
            msg = Imu(header=Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame_id),
                      orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=no_orientation,
                      angular_velocity=Vector3(x=float(w[0]), y=float(w[1]), z=float(w[2])), angular_velocity_covariance=zero,
                      linear_acceleration=Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2])),
                      linear_acceleration_covariance=zero)
            yield ns, msg

    if fmt == "rosbag1":
        from rosbags.rosbag1 import Writer as Writer1

        writer = Writer1(path)
        if compression:
            writer.set_compression(Writer1.CompressionFormat[compression.upper()])
        with writer:
            conn = writer.add_connection(topic, IMU_TYPE, typestore=store)
            for ns, msg in messages():
                writer.write(conn, ns, store.serialize_ros1(msg, IMU_TYPE))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    with Writer2(path, version=9, storage_plugin=plugin) as writer:
        conn = writer.add_connection(topic, IMU_TYPE, typestore=store)
        for ns, msg in messages():
            writer.write(conn, ns, store.serialize_cdr(msg, IMU_TYPE))
    return path
