"""The recording writer: a crash-safe ROS 2 MCAP file (rosbag2's conventions) with the run's parameters inside.

Writing
-------
``McapRecorder(path, *, parameters=None, metadata=None, chunk_size=256 * 1024, compression="zstd",
flush_interval=1.0)``
    Opens ``path`` (truncating it) and starts an MCAP file with ``profile="ros2"``,
    ``library="bldc_actuator <version>"``. ``parameters``: an :class:`~bldc_actuator.params.ActuatorParams`
    or the flat dotted dict of :func:`bldc_actuator.params.to_flat` (non-model keys such as ``node.*`` or
    ``preset`` may ride along; ``None`` values are left out: a params file cannot say "not set");
    ``metadata``: extra ``str -> str`` pairs for the metadata record.
    ``compression`` (``"zstd"``, ``"lz4"`` or ``"none"``) and ``flush_interval`` (wall seconds, ``None``
    = off) are keyword extensions of the team API; the defaults suit the node.
``add_topic(topic, msg_type, qos=None) -> channel id``
    ``msg_type``: ``"sensor_msgs/msg/JointState"`` (``"sensor_msgs/JointState"`` and the message class
    are accepted too). Registers the schema once per type (encoding ``ros2msg``: the ``.msg`` text and
    every dependency after a line of 80 ``=`` and ``MSG: pkg/Type``, exactly as rosbag2's
    ``message_definition_cache`` builds it) and one channel per topic (``message_encoding="cdr"``,
    metadata ``offered_qos_profiles`` in rosbag2's YAML layout (metadata version 9: enum names as strings)
    and ``topic_type_hash``, the ``RIHS01_...`` hash from ``share/<pkg>/msg/<Type>.json``, empty when not
    found). ``qos``: an ``rclpy.qos.QoSProfile`` (``publisher.qos_profile``), a list of them, or ``None``
    for KEEP_LAST 10 / RELIABLE / VOLATILE. Idempotent for the same topic and type; another type on a
    known topic is an error. Pass fully resolved names (``publisher.topic_name``).
``write(topic, msg, t_ns)``
    ``rclpy.serialization.serialize_message(msg)``; ``log_time = publish_time = t_ns`` (integer
    nanoseconds of SIMULATION time, >= 0); ``sequence`` counts 1, 2, 3 ... per channel, so a gap means a
    lost message. An unknown topic is added on the fly with the message's type and the default QoS.
``write_serialized(topic, data, t_ns)``
    The same for CDR bytes you already have (the topic must have been added).
``set_parameters(parameters)``
    Replaces the recorded parameters; the LAST value is in the final record. Each change is also written
    at once as an ``"update"`` record (with the simulation time of the last message written), so a
    crashed run keeps its parameter history.
``close()``
    Writes the final metadata record ``"bldc_actuator"`` = ``{"parameters_yaml": <YAML text in the node's
    params-file layout (params.dump_yaml)>, **metadata, "record": "final", "finalized_by": ...,
    "messages_written": ..., "last_time_ns": ..., "recorder": ...}``, then the MCAP summary and footer,
    fsyncs and closes the file. Idempotent; safe from ``finally``, ``atexit`` and signal handlers; raises
    at most once (a second call after a failed close returns quietly).
``with McapRecorder(...) as rec:``
    Closes on exceptions too (the file is finalized and readable; a close error then is reported as a
    warning and never masks the original exception).
``messages_written`` (int), ``bytes_written`` (int: bytes in the file plus an estimate of the open chunk),
``closed`` (bool), ``path``.

No ``rosbag2`` metadata record is written (rosbag2 then reads topics, counts and times from the MCAP
Statistics record, which this writer always emits); run data lives under our own record name.

Memory
------
Flat over any duration: the file is written by :class:`~bldc_actuator.recording.mcap_stream.McapStreamWriter`
(the same records as ``mcap.writer.Writer``), which keeps the summary's chunk index in an anonymous temporary
file beside the recording instead of one Python object per chunk (``mcap.writer.Writer`` retains ~45 B per
channel per chunk until ``finish()``: ~40-80 MB per hour for a 12-joint node). What stays in memory is the open
chunk, the schemas and channels, per-channel counts and one entry per metadata record.

Crash safety
------------
Messages are grouped in chunks. The file is written WITHOUT user-space buffering: when a chunk is
complete it is in the operating system's hands, so a crash of the process (exception, ``os._exit``,
SIGKILL) loses at most the chunk being filled; :func:`read_recording` and ``bldc-actuator record-info``
recover everything before it from an unfinalized file by streaming it record by record. A chunk closes
when it exceeds ``chunk_size`` bytes (uncompressed) or, with messages pending, ``flush_interval`` wall
seconds after its first message. At the node's default rates (joint_states, ~/phase_currents, ~/q_axis_state
(15 labelled values), ~/winding_temperature and ~/housing_temperature at 1 kHz, /diagnostics at 10 Hz:
5010 messages and 0.73 MB of uncompressed message records per simulated second, measured by
``benchmarks/bench_mcap.py``; the file grows by about 0.16 MB/s with zstd), a 256 KiB chunk holds about
360 ms of simulated data (about 340 ms with ``node.publish_clock``): a crash loses at most that, and at
most ``flush_interval`` (1 s) of wall time in slow runs. Power loss is another matter: only ``close()``
fsyncs.

Finalizing on Ctrl-C / SIGTERM: the recorder registers ``close`` with :mod:`atexit` (which covers an
uncaught KeyboardInterrupt or SystemExit); :func:`install_signal_finalizer` adds SIGINT/SIGTERM handlers
that close the file and then behave as before (KeyboardInterrupt for SIGINT, SystemExit(143) for a default
SIGTERM, or the previous Python handler). rclpy's own C-level handlers stay in the chain (they are
re-installed on top), so a spinning executor still wakes up. A signal that arrives in the middle of a
``write`` in the main thread is deferred to the end of that write, so the file is never cut mid-record.
Typical node use::

    rec = McapRecorder(path, parameters=params.to_flat(), metadata={"node": name})
    uninstall = install_signal_finalizer(rec)       # after rclpy.init() is fine
    for pub in publishers: rec.add_topic(pub.topic_name, pub.msg_type, pub.qos_profile)
    try:
        rclpy.spin(node)                             # callbacks call rec.write(pub.topic_name, msg, t_ns)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rec.close(); uninstall(); node.destroy_node(); rclpy.try_shutdown()
"""

from __future__ import annotations

import atexit
import math
import os
import signal
import sys
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from .base import (DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_INTERVAL, LIBRARY, MESSAGE_ENCODING, METADATA_NAME,
                   PARAMETERS_KEY, PROFILE, RESERVED_METADATA_KEYS, SCHEMA_ENCODING, RecorderClosedError,
                   RecordingWriteError)
from .mcap_stream import McapStreamWriter
from .parameters import render_parameters
from .typesys import message_definition, qos_yaml, type_hash, type_name

_MCAP_MESSAGE_OVERHEAD = 1 + 8 + 2 + 4 + 8 + 8 + 16  # record header + fields + message index entry


class _DirectFile:
    """Unbuffered write-only file for mcap.Writer: every write goes straight to the OS (a crash of the
    process loses nothing that the writer already handed over). Not an io.RawIOBase on purpose: the
    writer would wrap that in a BufferedWriter."""

    def __init__(self, path: Path):
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0), 0o644)
        self.pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        total = len(view)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
        self.pos += total
        return total

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def truncate(self, size: int) -> None:
        """Cut the file back to ``size`` bytes (drop a partly written chunk after a failed write)."""
        os.ftruncate(self._fd, size)
        os.lseek(self._fd, size, os.SEEK_SET)
        self.pos = size

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


@dataclass
class _Channel:
    id: int
    topic: str
    type: str
    msg_class: Any = None
    sequence: int = 0


_serialize_message: Callable[[Any], bytes] | None = None


def _serializer() -> Callable[[Any], bytes]:
    global _serialize_message
    if _serialize_message is None:
        from rclpy.serialization import serialize_message

        _serialize_message = serialize_message
    return _serialize_message


def _check_time(t_ns: Any) -> int:
    t = int(t_ns)
    if t != t_ns or not 0 <= t < 2**64:
        raise ValueError(f"t_ns: expected integer nanoseconds of simulation time in [0, 2**64), got {t_ns!r}")
    return t



class McapRecorder:
    """Writes a ROS 2 MCAP recording; see the module docstring for the API and guarantees."""

    def __init__(self, path, *, parameters: Any = None, metadata: Mapping[str, str] | None = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, compression: str = "zstd",
                 flush_interval: float | None = DEFAULT_FLUSH_INTERVAL):
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1024:
            raise ValueError(f"chunk_size: expected an integer >= 1024 [bytes], got {chunk_size!r}")
        kinds = {"zstd": "zstd", "lz4": "lz4", "none": "", "": ""}
        if compression not in kinds:
            raise ValueError(f"compression: expected one of zstd, lz4, none, got {compression!r}")
        if flush_interval is not None and not (flush_interval > 0 and math.isfinite(flush_interval)):
            raise ValueError(f"flush_interval: expected a positive number of seconds or None, "
                             f"got {flush_interval!r}")
        user_meta: dict[str, str] = {}
        for key, value in (metadata or {}).items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise TypeError(f"metadata: keys and values must be str, got {key!r}: {value!r}")
            if key in RESERVED_METADATA_KEYS:
                raise ValueError(f"metadata: key {key!r} is reserved "
                                 f"(reserved: {', '.join(sorted(RESERVED_METADATA_KEYS))})")
            user_meta[key] = value
        # render before opening the file: bad parameters must not leave an empty file behind
        rendered = render_parameters(parameters) if parameters is not None else None

        self.path = Path(path)
        self._lock = threading.Lock()
        self._busy: set[int] = set()        # threads inside a critical section (see install_signal_finalizer)
        self._deferred_signal: tuple[int, Any] | None = None
        self._signal_finalizer: _SignalFinalizer | None = None
        self._closed = False
        self._finalized_by = "close()"
        self._metadata = user_meta
        self._parameters_yaml: str | None = None
        self._parameters_flat: dict[str, Any] | None = None
        self._channels: dict[str, _Channel] = {}
        self._schemas: dict[str, int] = {}
        self._last_t_ns: int | None = None
        self._pending = 0                   # messages in the open chunk
        self._pending_bytes = 0
        self._chunk_opened = 0.0
        self._flush_interval = flush_interval
        self.messages_written = 0
        self.write_error: OSError | None = None   #: the OS error that stopped the recording, if any

        self._sink = _DirectFile(self.path)
        try:
            # not mcap.writer.Writer: it keeps every chunk's index in memory (see mcap_stream)
            self._writer = McapStreamWriter(self._sink, chunk_size=chunk_size, compression=kinds[compression],
                                            index_dir=self.path.resolve().parent)
            self._writer.start(profile=PROFILE, library=LIBRARY)
            self._flush_chunk = self._writer.flush
            if rendered is not None:
                self._parameters_yaml, self._parameters_flat = rendered
                self._write_metadata("initial")
        except BaseException:
            self._sink.close()
            raise
        atexit.register(self._atexit_close)

    # -- properties -------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def bytes_written(self) -> int:
        return self._sink.pos + self._pending_bytes

    @property
    def topics(self) -> dict[str, str]:
        return {t: c.type for t, c in self._channels.items()}

    # -- topics -----------------------------------------------------------------------------------
    def add_topic(self, topic: str, msg_type: Any, qos: Any = None) -> int:
        if not isinstance(topic, str) or not topic:
            raise ValueError(f"topic: expected a non-empty topic name, got {topic!r}")
        name = type_name(msg_type)
        cls = msg_type if isinstance(msg_type, type) else None
        channel = self._channels.get(topic)
        if channel is not None:
            if channel.type != name:
                raise ValueError(f"topic {topic!r} is already recorded as {channel.type}, not {name}")
            if cls is not None and channel.msg_class is None:
                channel.msg_class = cls
            return channel.id
        qos_text = qos_yaml(qos)
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                self._check_open()
                channel = self._channels.get(topic)
                if channel is not None:  # added by another thread meanwhile
                    if channel.type != name:
                        raise ValueError(f"topic {topic!r} is already recorded as {channel.type}, not {name}")
                    return channel.id
                schema_id = self._schemas.get(name)
                if schema_id is None:
                    text = message_definition(name)
                    if text is None:
                        warnings.warn(f"no .msg definition found for {name} (searched share/{name.split('/')[0]}"
                                      f" in AMENT_PREFIX_PATH, beside the Python package and in {sys.prefix}); "
                                      "schema left empty as rosbag2 does: only readers that know the type can "
                                      "decode this topic", RuntimeWarning, stacklevel=2)
                        schema_id = self._writer.register_schema(name=name, encoding="", data=b"")
                    else:
                        schema_id = self._writer.register_schema(name=name, encoding=SCHEMA_ENCODING,
                                                                 data=text.encode("utf-8"))
                    self._schemas[name] = schema_id
                channel_id = self._writer.register_channel(
                    topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=schema_id,
                    metadata={"offered_qos_profiles": qos_text, "topic_type_hash": type_hash(name)})
                self._channels[topic] = _Channel(channel_id, topic, name, cls)
        finally:
            self._busy.discard(ident)
        self._fire_deferred_signal()
        return channel_id

    # -- messages ---------------------------------------------------------------------------------
    def write(self, topic: str, msg: Any, t_ns: int) -> None:
        channel = self._channels.get(topic)
        cls = type(msg)
        if channel is None:
            self.add_topic(topic, cls)
            channel = self._channels[topic]
        if channel.msg_class is not cls:
            if channel.msg_class is None and type_name(cls) == channel.type:
                channel.msg_class = cls
            else:
                raise TypeError(f"topic {topic!r} records {channel.type}, got a {cls.__module__}.{cls.__name__}")
        self._add(channel, _serializer()(msg), t_ns)

    def write_serialized(self, topic: str, data: bytes, t_ns: int) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            raise KeyError(f"topic {topic!r} is not recorded yet: call add_topic(topic, msg_type) first")
        self._add(channel, bytes(data), t_ns)

    def _add(self, channel: _Channel, data: bytes, t_ns: int) -> None:
        t = int(t_ns)
        if t != t_ns or t < 0 or t >= 18446744073709551616:
            _check_time(t_ns)  # raises with the message
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                if self._closed:
                    raise RecorderClosedError(f"recording {self.path} is closed ({self._finalized_by}); "
                                              f"message on {channel.topic} not written")
                pos = self._sink.pos
                channel.sequence += 1
                try:
                    self._writer.add_message(channel.id, log_time=t, data=data, publish_time=t,
                                             sequence=channel.sequence)
                except OSError as exc:
                    self._fail(exc, pos)
                self.messages_written += 1
                if self._last_t_ns is None or t > self._last_t_ns:
                    self._last_t_ns = t
                if self._sink.pos != pos:   # the chunk (with this message) went to the file
                    self._pending = self._pending_bytes = 0
                else:
                    self._pending += 1
                    self._pending_bytes += len(data) + _MCAP_MESSAGE_OVERHEAD
                    if self._flush_interval is not None:
                        now = time.monotonic()
                        if self._pending == 1:
                            self._chunk_opened = now
                        elif now - self._chunk_opened >= self._flush_interval:
                            self._guarded(self._flush_chunk)
                            self._pending = self._pending_bytes = 0
        finally:
            self._busy.discard(ident)
        if self._deferred_signal is not None:
            self._fire_deferred_signal()

    def flush(self) -> None:
        """Close the open chunk now (it goes to the file; compression works per chunk)."""
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                self._check_open()
                if self._pending:
                    self._guarded(self._flush_chunk)
                    self._pending = self._pending_bytes = 0
        finally:
            self._busy.discard(ident)
        self._fire_deferred_signal()

    # -- parameters and metadata ------------------------------------------------------------------
    def set_parameters(self, parameters: Any) -> None:
        text, flat = render_parameters(parameters)
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                self._check_open()
                if text != self._parameters_yaml:
                    first = self._parameters_yaml is None
                    self._parameters_yaml, self._parameters_flat = text, flat
                    self._guarded(self._write_metadata, "initial" if first and not self.messages_written else "update")
        finally:
            self._busy.discard(ident)
        self._fire_deferred_signal()

    @property
    def parameters(self) -> dict[str, Any] | None:
        return None if self._parameters_flat is None else dict(self._parameters_flat)

    def _write_metadata(self, kind: str) -> None:
        data: dict[str, str] = {}
        if self._parameters_yaml is not None:
            data[PARAMETERS_KEY] = self._parameters_yaml
        data.update(self._metadata)
        data["record"] = kind
        data["recorder"] = LIBRARY
        data["messages_written"] = str(self.messages_written)
        data["last_time_ns"] = "" if self._last_t_ns is None else str(self._last_t_ns)
        if kind == "final":
            data["finalized_by"] = self._finalized_by
        self._writer.add_metadata(METADATA_NAME, data)

    # -- write errors -----------------------------------------------------------------------------
    def _guarded(self, fn, *args):
        """Run a writer call that may write to the file; on an OS error stop recording (see :meth:`_fail`)."""
        pos = self._sink.pos
        try:
            return fn(*args)
        except OSError as exc:
            self._fail(exc, pos)

    def _fail(self, exc: OSError, good_pos: int) -> None:
        """A write failed: cut the file back to ``good_pos`` (the end of the last complete chunk and its
        indexes, so readers see a clean unfinalized recording), close it and raise
        :class:`RecordingWriteError`. Called with the lock held."""
        self._closed = True
        self._finalized_by = f"write error: {exc.strerror or exc}"
        self.write_error = exc
        try:
            self._sink.truncate(good_pos)
        except OSError:
            pass   # the partly written chunk stays; readers stop at the last complete one anyway
        finally:
            self._sink.close()
            self._writer.close_index()
            atexit.unregister(self._atexit_close)
        raise RecordingWriteError(exc.errno, f"{exc.strerror or exc}; recording stopped, file kept up to its last "
                                  f"complete chunk ({good_pos} bytes)", str(self.path)) from exc

    # -- closing ----------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise RecorderClosedError(f"recording {self.path} is closed ({self._finalized_by})")

    def close(self) -> None:
        self._close("close()")

    def _close(self, reason: str) -> None:
        if self._closed:
            return
        ident = threading.get_ident()
        self._busy.add(ident)
        try:
            with self._lock:
                if self._closed:
                    return
                self._finalized_by = reason
                error: BaseException | None = None
                good = self._sink.pos   # the end of the last chunk the writer handed over
                try:
                    try:
                        self._write_metadata("final")
                    except BaseException as exc:  # still try to write the summary
                        error = exc
                    try:
                        self._writer.finish()
                        self._sink.fsync()
                    except OSError as exc:   # disk full while finalizing: keep what was complete
                        self._fail(exc, good)
                    self._closed = True
                    self._pending = self._pending_bytes = 0
                finally:
                    self._closed = True
                    self._sink.close()
                    self._writer.close_index()
                    atexit.unregister(self._atexit_close)
                if error is not None:
                    raise error
        finally:
            self._busy.discard(ident)
            self._fire_deferred_signal()

    def _atexit_close(self) -> None:
        try:
            self._close("atexit")
        except Exception as exc:  # noqa: BLE001 - nothing can handle it at exit
            print(f"bldc_actuator.recording: could not finalize {self.path}: {exc}", file=sys.stderr)

    def _fire_deferred_signal(self) -> None:
        deferred = self._deferred_signal
        if deferred is None or threading.get_ident() in self._busy or self._signal_finalizer is None:
            return
        self._deferred_signal = None
        self._signal_finalizer.finish(*deferred)

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close()
            return False
        try:
            self._close(f"exception {exc_type.__name__}")
        except Exception as close_exc:  # noqa: BLE001 - never mask the original exception
            warnings.warn(f"could not finalize {self.path} after {exc_type.__name__}: {close_exc}",
                          RuntimeWarning, stacklevel=2)
        return False

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return (f"McapRecorder({str(self.path)!r}, {state}, {len(self._channels)} topics, "
                f"{self.messages_written} messages)")


class _SignalFinalizer:
    def __init__(self, recorder: McapRecorder, signals: Iterable[int]):
        self.recorder = recorder
        self.previous: dict[int, Any] = {}
        for signum in signals:
            prev = signal.getsignal(signum)
            if prev == signal.SIG_IGN:
                continue  # an ignored signal stays ignored
            self.previous[signum] = prev
        for signum in self.previous:
            signal.signal(signum, self.handle)

    def handle(self, signum, frame) -> None:
        rec = self.recorder
        if threading.get_ident() in rec._busy:
            rec._deferred_signal = (signum, frame)  # finished at the end of the interrupted write
            return
        self.finish(signum, frame)

    def finish(self, signum, frame) -> None:
        try:
            self.recorder._close(f"signal {signal.Signals(signum).name}")
        except Exception as exc:  # noqa: BLE001 - the signal's own effect must still happen
            print(f"bldc_actuator.recording: could not finalize {self.recorder.path}: {exc}", file=sys.stderr)
        prev = self.previous.get(signum)
        if callable(prev):
            prev(signum, frame)
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt
        else:
            raise SystemExit(128 + signum)

    def uninstall(self) -> None:
        for signum, prev in self.previous.items():
            if signal.getsignal(signum) == self.handle:
                signal.signal(signum, prev if prev is not None else signal.SIG_DFL)
        if self.recorder._signal_finalizer is self:
            self.recorder._signal_finalizer = None


def install_signal_finalizer(recorder: McapRecorder,
                             signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> Callable[[], None]:
    """Finalize ``recorder`` on SIGINT/SIGTERM, then act as before (see the module docstring).

    Must be called from the main thread. If rclpy's signal handlers are installed they are re-installed
    on top, so rclpy still wakes its executors and then chains to ours. Returns ``uninstall()``.
    """
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("install_signal_finalizer must be called from the main thread (Python runs signal "
                           "handlers there); the recorder's atexit finalizer is active anyway")
    rclpy_options = None
    rclpy_signals = sys.modules.get("rclpy.signals")
    if rclpy_signals is None and "rclpy" in sys.modules:
        try:
            import rclpy.signals as rclpy_signals  # noqa: PLW0621
        except Exception:  # noqa: BLE001
            rclpy_signals = None
    if rclpy_signals is not None:
        try:
            options = rclpy_signals.get_current_signal_handlers_options()
            if options != rclpy_signals.SignalHandlerOptions.NO:
                rclpy_options = options
                rclpy_signals.uninstall_signal_handlers()
        except Exception:  # noqa: BLE001 - older rclpy: leave its handlers alone
            rclpy_options = None
    finalizer = _SignalFinalizer(recorder, signals)
    if rclpy_options is not None:
        rclpy_signals.install_signal_handlers(rclpy_options)
    recorder._signal_finalizer = finalizer

    def uninstall() -> None:
        if rclpy_options is not None:
            rclpy_signals.uninstall_signal_handlers()
        finalizer.uninstall()
        if rclpy_options is not None:
            rclpy_signals.install_signal_handlers(rclpy_options)

    return uninstall
