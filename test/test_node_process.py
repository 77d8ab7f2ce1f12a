"""actuator_node as a program: the pip console script and the colcon-installed executable, with parameter
files, presets, --record, node.max_sim_time, SIGINT and SIGTERM (the recording is finalized every time)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("mcap")

from conftest import PACKAGE, colcon_env, next_domain_id, scaled, wait_for  # noqa: E402

from bldc_actuator.recording import read_recording, summarize  # noqa: E402

pytestmark = pytest.mark.ros


def venv_script() -> Path:
    script = Path(sys.executable).parent / "actuator_node"
    if not script.exists():
        pytest.skip("actuator_node console script not installed beside this interpreter (pip install -e .)")
    return script


def env_for(base: dict | None = None) -> dict:
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(next_domain_id())
    return env


def params_file(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text("/**/bldc_actuator:\n  ros__parameters:\n" + body)
    return path


def test_console_script_runs_to_max_sim_time_with_params_file(tmp_path):
    pfile = params_file(tmp_path, "    drive:\n      bus_voltage: 36.0\n    node:\n      time_factor: 0.0\n"
                                  "      max_sim_time: 0.2\n      joint_name: wrist\n")
    rec = tmp_path / "run.mcap"
    result = subprocess.run([str(venv_script()), "--record", str(rec), "--ros-args", "--params-file", str(pfile)],
                            env=env_for(), capture_output=True, text=True, timeout=scaled(60))
    assert result.returncode == 0, result.stdout + result.stderr
    info = summarize(rec)
    assert info["finalized"] and info["end_ns"] == 200_000_000
    assert info["parameters"]["drive.bus_voltage"] == 36.0 and info["parameters"]["node.joint_name"] == "wrist"


def test_bad_parameter_exits_with_a_clear_message(tmp_path):
    result = subprocess.run([str(venv_script()), "--ros-args", "-p", "drive.trip_temperature:=50.0"],
                            env=env_for(), capture_output=True, text=True, timeout=scaled(60))
    assert result.returncode == 2
    assert "drive.trip_temperature" in result.stderr and "derate_temperature" in result.stderr
    assert "Traceback" not in result.stderr


def test_unknown_top_level_parameter_exits_2_naming_the_nearest():
    """``-p presett:=ak80_9`` (a typo of ``preset``) must not run the built-in motor: exit 2, named."""
    result = subprocess.run([str(venv_script()), "--ros-args", "-p", "presett:=ak80_9"],
                            env=env_for(), capture_output=True, text=True, timeout=scaled(60))
    assert result.returncode == 2, result.stdout + result.stderr
    assert "presett" in result.stderr and "did you mean 'preset'" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("sig, executor", [(signal.SIGINT, "single"), (signal.SIGTERM, "single"),
                                           (signal.SIGINT, "events"), (signal.SIGTERM, "events")])
def test_signal_finalizes_the_recording(tmp_path, sig, executor):
    if executor == "events":
        pytest.importorskip("rclpy.experimental", reason="EventsExecutor needs ROS 2 Kilted or newer")
    rec = tmp_path / "sig.mcap"
    proc = subprocess.Popen([str(venv_script()), "--record", str(rec), "--executor", executor], env=env_for(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # running at real time: the file appears when the node opens it (before it starts stepping), and
        # grows when the first chunk (a few hundred ms of simulation) is written: wait for that
        assert wait_for(lambda: rec.exists() and rec.stat().st_size > 0 or proc.poll() is not None, 30)
        # wait for two growths: on a loaded machine the first can be the channel/schema records alone (a run
        # at load 8 once ended with 0 joint states recorded)
        for _ in range(2):
            size0 = rec.stat().st_size if rec.exists() else 0
            assert wait_for(lambda: rec.stat().st_size > size0 or proc.poll() is not None, 30)
        time.sleep(0.2)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=scaled(30))
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err          # a requested stop is a clean exit
    assert "Traceback" not in err
    recording = read_recording(rec)
    assert recording.finalized, recording.issues
    js = recording.topics["/joint_states"]
    assert len(js) > 50 and [t for t, _ in js] == sorted(t for t, _ in js)
    assert recording.metadata["record"] == "final"


def test_exception_in_the_node_still_finalizes_the_recording(tmp_path):
    rec = tmp_path / "crash.mcap"
    code = (
        "import sys\n"
        "from bldc_actuator import model, node\n"
        "calls = [0]\n"
        "orig = model.Actuator.step_ns\n"
        "def broken(self, dt):\n"
        "    calls[0] += 1\n"
        "    if calls[0] > 100: raise ZeroDivisionError('injected fault')\n"
        "    return orig(self, dt)\n"
        "model.Actuator.step_ns = broken\n"
        f"sys.exit(node.main(['actuator_node', '--record', {str(rec)!r},\n"
        "                    '--ros-args', '-p', 'node.time_factor:=0.0']))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], env=env_for(), capture_output=True, text=True, timeout=scaled(60))
    assert result.returncode != 0 and "injected fault" in result.stderr
    recording = read_recording(rec)
    assert recording.finalized and len(recording.topics["/joint_states"]) == 101


def test_colcon_installed_node_runs_with_params_file_and_preset(colcon_install_prefix: Path, tmp_path):
    exe = colcon_install_prefix / "lib" / PACKAGE / "actuator_node"
    assert exe.is_file()
    pfile = params_file(tmp_path, "    preset: ak80_9\n    drive:\n      bus_voltage: 48.0\n"
                                  "    node:\n      time_factor: 0.0\n      max_sim_time: 0.1\n")
    rec = tmp_path / "colcon.mcap"
    result = subprocess.run([str(exe), "--ros-args", "--params-file", str(pfile), "-p", f"node.record:={rec}"],
                            env=env_for(colcon_env(colcon_install_prefix)), cwd=tmp_path,
                            capture_output=True, text=True, timeout=scaled(120))
    assert result.returncode == 0, result.stdout + result.stderr
    recording = read_recording(rec)
    assert recording.finalized
    p = recording.params()
    assert p.drive.bus_voltage == 48.0 and p.gear.gear_ratio == 9.0   # file over preset; preset from share/
    assert recording.parameters["preset"] == "ak80_9"
    assert len(recording.topics["/joint_states"]) == 101
