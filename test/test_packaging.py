"""Packaging works in both worlds: colcon/ament_python (ROS install layout) and pip (venv + ROS wheels)."""

from __future__ import annotations

import configparser
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

import pytest
from conftest import DOMAIN_ID_BASE, DOMAIN_ID_MAX, PACKAGE, REPO_ROOT, colcon_env, next_domain_id, scaled, wait_for

import bldc_actuator

EXECUTABLES = {"actuator_node": "bldc_actuator.node:main", "bldc-actuator": "bldc_actuator.cli:main"}
EXEC_DEPENDS = {
    "rclpy", "std_msgs", "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs",
    "python3-numpy", "python3-scipy", "python3-yaml",
}  # fmt: skip


def source_presets() -> set[str]:
    return {p.name for p in (REPO_ROOT / "config").glob("*.yaml")}


# ------------------------------------------------------------------------------------- static checks


def test_package_xml_is_ament_python_format_3():
    root = ET.parse(REPO_ROOT / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == PACKAGE
    assert root.findtext("version") == bldc_actuator.__version__, "package.xml and __init__.__version__ differ"
    assert root.findtext("license") == "Apache-2.0"
    assert root.find("maintainer").get("email")
    assert root.findtext("export/build_type") == "ament_python"
    assert EXEC_DEPENDS <= {e.text for e in root.findall("exec_depend")}
    assert "python3-pytest" in {e.text for e in root.findall("test_depend")}


def test_ament_marker_license_and_script_dirs():
    assert (REPO_ROOT / "resource" / PACKAGE).is_file()
    assert "Apache License" in (REPO_ROOT / "LICENSE").read_text() and "Version 2.0" in (REPO_ROOT / "LICENSE").read_text()
    cfg = configparser.ConfigParser(interpolation=None)
    cfg.read(REPO_ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == f"$base/lib/{PACKAGE}"
    assert cfg["install"]["install_scripts"] == f"$base/lib/{PACKAGE}"


def _installed_distribution() -> metadata.Distribution:
    try:
        return metadata.distribution(PACKAGE)
    except metadata.PackageNotFoundError:
        pytest.skip("bldc_actuator is not pip-installed in this interpreter (colcon/source run)")


def test_pip_metadata_keeps_ros_wheels_out_of_install_requires():
    dist = _installed_distribution()
    unconditional = [r for r in dist.requires or [] if "extra ==" not in r]
    assert [re.split(r"[\s<>=!~;\[]", r, maxsplit=1)[0] for r in unconditional] == ["setuptools"]
    extras = set(dist.metadata.get_all("Provides-Extra") or [])
    assert {"wheels", "test"} <= extras
    ros = [r for r in dist.requires if r.startswith("ros-")]
    assert ros and all('extra == "wheels"' in r for r in ros)


def test_console_scripts_declared():
    dist = _installed_distribution()
    scripts = {ep.name: ep.value for ep in dist.entry_points if ep.group == "console_scripts"}
    assert scripts == EXECUTABLES


def test_readme_commands_are_the_scripts():
    readme = (REPO_ROOT / "README.md").read_text()
    for command in ("bash scripts/demo.sh", "bash scripts/test.sh"):
        assert command in readme
        assert (REPO_ROOT / command.split()[1]).is_file()


@pytest.mark.slow
def test_test_sh_treats_no_collected_tests_as_success():
    if Path(sys.prefix).resolve() != (REPO_ROOT / ".venv").resolve():
        pytest.skip("runs scripts/test.sh, which uses <repo>/.venv; this interpreter is not that venv")
    result = subprocess.run(
        ["bash", str(REPO_ROOT / "scripts" / "test.sh"), "-q", "-p", "no:cacheprovider", "-k", "no_such_test_xyz"],
        capture_output=True, text=True, timeout=scaled(300),
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert "collected no tests" in result.stderr


def _fresh(code: str) -> str:
    """Run ``code`` in a new interpreter (this one has imported everything already); its stdout."""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=scaled(120),
                            cwd=REPO_ROOT, env={k: v for k, v in os.environ.items() if k != "PYTHONSTARTUP"})
    assert result.returncode == 0, result.stderr
    return result.stdout


HEAVY = ("numpy", "scipy", "numba", "rclpy", "mcap", "mcap_ros2", "matplotlib", "yaml", "dask")


def test_package_face_imports_light_and_without_ros():
    """``import bldc_actuator`` pulls in no heavy dependency (the face's names import on first use)."""
    out = _fresh(f"import sys, bldc_actuator; print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    assert out.strip() == "[]"


def test_package_face_exports_the_public_api_without_ros():
    """Every exported name resolves (to the object its module defines) without importing rclpy."""
    out = _fresh("import sys, bldc_actuator as ba\n"
                 "for n in ba.__all__: getattr(ba, n)\n"
                 "print('rclpy' in sys.modules)")
    assert out.strip() == "False"
    from bldc_actuator import model, params, recording, simulate
    from bldc_actuator.diagnosis import pipeline

    assert {"Actuator", "BatchActuator", "ActuatorParams", "load_preset", "frames", "simulate_profile",
            "McapRecorder", "read_recording", "diagnose"} <= set(bldc_actuator.__all__)
    assert bldc_actuator.Actuator is model.Actuator and bldc_actuator.load_preset is params.load_preset
    assert bldc_actuator.McapRecorder is recording.McapRecorder and bldc_actuator.diagnose is pipeline.diagnose
    assert bldc_actuator.simulate_profile is simulate.simulate_profile
    assert bldc_actuator.frames.__name__ == "bldc_actuator.frames"
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        bldc_actuator.no_such_name  # noqa: B018


# ------------------------------------------------------------------------------------------ colcon build


def test_colcon_build_installs_ros_layout(colcon_install_prefix: Path):
    prefix = colcon_install_prefix
    for exe in EXECUTABLES:  # where `ros2 run bldc_actuator <exe>` looks
        path = prefix / "lib" / PACKAGE / exe
        assert path.is_file() and os.access(path, os.X_OK), f"{path} missing or not executable"
        assert not (prefix / "bin" / exe).exists()
    share = prefix / "share" / PACKAGE
    assert (share / "package.xml").read_bytes() == (REPO_ROOT / "package.xml").read_bytes()
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    assert {p.name for p in (share / "config").glob("*.yaml")} == source_presets()
    # the input profiles (log formats as data) ship with it, every one
    assert {p.name for p in (share / "config" / "input_profiles").glob("*.yaml")} == \
        {p.name for p in (REPO_ROOT / "config" / "input_profiles").glob("*.yaml")} != set()
    assert list(prefix.glob(f"lib/python3*/site-packages/{PACKAGE}/__init__.py"))


def test_colcon_installed_cli_runs_from_install(colcon_install_prefix: Path):
    prefix = colcon_install_prefix
    env = colcon_env(prefix)
    # cwd away from the checkout: `python -c` puts the cwd first on sys.path
    where = subprocess.run(
        [sys.executable, "-c", "import bldc_actuator; print(bldc_actuator.__file__)"],
        env=env, cwd=prefix, capture_output=True, text=True, timeout=scaled(60), check=True,
    ).stdout.strip()  # fmt: skip
    assert Path(where).resolve().is_relative_to(prefix.resolve()), where
    result = subprocess.run(
        [str(prefix / "lib" / PACKAGE / "bldc-actuator"), "--help"],
        env=env, cwd=prefix, capture_output=True, text=True, timeout=scaled(60),
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert "bldc-actuator" in result.stdout
    # the installed diagnosis/io finds every input profile in the install's share/, not in the checkout
    found = subprocess.run(
        [sys.executable, "-c", "from bldc_actuator.diagnosis.io import input_profiles as ip\n"
         "for p in ip.available(): print(p.name, p.path)"],
        env=env, cwd=prefix, capture_output=True, text=True, timeout=scaled(60), check=True,
    ).stdout.split("\n")  # fmt: skip
    found = dict(line.split(" ", 1) for line in found if line)
    assert set(found) == {p.stem for p in (REPO_ROOT / "config" / "input_profiles").glob("*.yaml")} != set()
    assert all(Path(path).resolve().is_relative_to(prefix.resolve()) for path in found.values()), found


# ------------------------------------------------------------------------------- the ROS test harness


def test_domain_ids_stay_in_range_and_do_not_repeat_soon():
    ids = [next_domain_id() for _ in range(DOMAIN_ID_MAX - DOMAIN_ID_BASE + 1)]
    assert all(DOMAIN_ID_BASE <= i <= DOMAIN_ID_MAX for i in ids)
    span = (DOMAIN_ID_MAX - DOMAIN_ID_BASE + 1) // int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    assert len(set(ids[:span])) == span


def test_ros_harness_round_trip(ros_context, ros_executor):
    """rclpy from the venv works on a private domain, localhost only, with the conftest fixtures."""
    from rclpy.node import Node
    from std_msgs.msg import Float64

    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert DOMAIN_ID_BASE <= ros_context.get_domain_id() <= DOMAIN_ID_MAX
    talker = Node("harness_talker", context=ros_context)
    listener = Node("harness_listener", context=ros_context)
    received: list[float] = []
    listener.create_subscription(Float64, "harness_topic", lambda m: received.append(m.data), 10)
    publisher = talker.create_publisher(Float64, "harness_topic", 10)
    ros_executor.add_node(talker)
    ros_executor.add_node(listener)
    assert wait_for(lambda: publisher.get_subscription_count() > 0, timeout=10.0), "no discovery"
    publisher.publish(Float64(data=1.5))
    assert wait_for(lambda: received, timeout=5.0) == [1.5]
