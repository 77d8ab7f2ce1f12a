"""A recording fault never stops the actuator: a write that fails (disk full, I/O error) stops the recording
cleanly (file cut back to its last complete chunk, still readable), and the node keeps simulating and
publishing with /diagnostics at ERROR ("recording stopped: ...")."""

from __future__ import annotations

import errno

import pytest

pytest.importorskip("mcap")

from bldc_actuator.recording import (McapRecorder, RecorderClosedError, RecordingWriteError,  # noqa: E402
                                     read_recording)


class FailingSink:
    """Wraps the recorder's file: every write fails with ``err`` once ``armed`` (a disk that fills up)."""

    def __init__(self, sink, err=errno.ENOSPC):
        self.sink, self.err, self.armed, self.failures = sink, err, False, 0
        self._write = sink.write
        sink.write = self.write

    def write(self, data):
        if self.armed:
            self.failures += 1
            raise OSError(self.err, "No space left on device" if self.err == errno.ENOSPC else "I/O error")
        return self._write(data)


def _float64():
    from std_msgs.msg import Float64
    return Float64


def test_recorder_write_error_keeps_complete_chunks(tmp_path):
    pytest.importorskip("rclpy")
    Float64 = _float64()
    path = tmp_path / "full.mcap"
    rec = McapRecorder(path, parameters={"drive.bus_voltage": 24.0}, chunk_size=1024, flush_interval=None)
    rec.add_topic("/x", Float64)
    fail = FailingSink(rec._sink)  # noqa: SLF001 - the file under the writer
    n_ok = 0
    with pytest.raises(RecordingWriteError) as info:
        for k in range(10_000):
            if k == 400:
                fail.armed = True
            rec.write("/x", Float64(data=float(k)), k * 1_000_000)
            n_ok = k + 1
    assert info.value.errno == errno.ENOSPC and "stopped" in str(info.value)
    assert rec.closed and fail.failures == 1
    with pytest.raises(RecorderClosedError):
        rec.write("/x", Float64(data=0.0), 10**12)
    rec.close()   # idempotent after a failure
    got = read_recording(path)
    values = [m.data for _, m in got.topics["/x"]]
    assert not got.finalized
    # everything up to the last complete chunk, in order, nothing invented; the open chunk is lost
    assert 300 <= len(values) <= 400 <= n_ok + 1
    assert values == [float(k) for k in range(len(values))]
    assert path.stat().st_size == rec._sink.pos  # noqa: SLF001 - cut back: no partial chunk at the end


def test_recorder_error_while_finalizing_keeps_complete_chunks(tmp_path):
    pytest.importorskip("rclpy")
    Float64 = _float64()
    path = tmp_path / "full_at_close.mcap"
    rec = McapRecorder(path, chunk_size=1024, flush_interval=None)
    rec.add_topic("/x", Float64)
    for k in range(500):
        rec.write("/x", Float64(data=float(k)), k * 1_000_000)
    FailingSink(rec._sink, errno.EIO).armed = True  # noqa: SLF001
    with pytest.raises(RecordingWriteError):
        rec.close()
    assert rec.closed
    values = [m.data for _, m in read_recording(path).topics["/x"]]
    assert 0 < len(values) < 500 and values == [float(k) for k in range(len(values))]


def test_node_keeps_running_when_the_recording_disk_fills(ros_context, ros_executor, tmp_path):
    pytest.importorskip("rclpy")
    from node_helpers import make_node

    from bldc_actuator.node import ERROR

    path = tmp_path / "node.mcap"
    node = make_node(ros_context, ros_executor, params={
        "node.lock_step": True, "node.record": str(path), "node.watchdog_timeout": 0.0,
        "node.diagnostics_rate": 50.0})
    node.plant.set_current_command(node.joints[0].name, 3.0)
    node.advance(300)
    node.recorder.flush()                   # the first 300 periods are a complete chunk on disk
    fail = FailingSink(node.recorder._sink)  # noqa: SLF001
    fail.armed = True
    t_fail = node.t_ns
    node.advance(700)                       # must not raise
    assert node.recorder is None and fail.failures == 1
    assert node.t_ns == t_fail + 700 * node.period_ns and node.periods == 1000
    assert node.plant.outputs(node.joints[0].name)["omega"] > 10.0          # still simulating the commanded current
    status = node.diagnostic_status()
    assert status.level == ERROR and "recording stopped" in status.message and "No space left" in status.message
    node.close()
    got = read_recording(path)
    js = got.topics["/joint_states"]
    assert not got.finalized and len(js) == 301          # initial state + 300 periods, nothing after
    stamps = [t for t, _ in js]
    assert stamps == sorted(stamps) and stamps[-1] < t_fail + node.period_ns
