"""Shared test harness for bldc_actuator.

Fixtures
    shared_data_dir        Path to the real recordings (``../shared/data`` beside the repo, or
                           ``$BLDC_SHARED_DIR/data``); skips the test when absent.
    ros_context            a fresh ``rclpy.context.Context`` initialised on its own ROS domain id;
                           skips when rclpy is not importable.
    ros_executor           a SingleThreadedExecutor on ``ros_context`` spinning in a daemon thread; add your
                           nodes to it (``ros_executor.add_node(node)``); they are destroyed at teardown.
    colcon_install_prefix  session-wide ``colcon build`` of this package (see ``colcon_install``).

Plain helpers (``from conftest import wait_for, scaled, colcon_install, colcon_env``)
    wait_for(predicate, timeout)   poll instead of sleeping a fixed time (``timeout`` scaled by the load).
    scaled(seconds)                a wall-clock bound sized for this machine's load: pass it to every
                                   ``timeout=`` (subprocess, communicate, Popen.wait, Client) in a test.
    timeout_factor()               the factor ``scaled`` applies (see its docstring).

Timeouts: pytest-timeout's per-test ``timeout`` (setup.cfg) is multiplied by ``timeout_factor()`` when each test
starts, so a hung test still fails (after a bounded time) while a slow test on a loaded machine does not.
    colcon_install(workdir)        colcon-build a copy of the package under ``workdir``, return the install prefix.
    colcon_env(prefix)             environment that runs the colcon-installed scripts against that prefix.

Markers (applied automatically where a fixture implies them): ``ros`` (uses rclpy),
``shared_data`` (needs ../shared/data), ``slow`` (seconds or more; deselect with ``-m "not slow"``);
``one_kernel_path`` (set by hand: not rerun on the pure-Python kernel pass of scripts/test.sh).
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

# No DDS discovery traffic off this host, whatever the caller's environment says. Must precede rclpy.init().
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("MPLBACKEND", "Agg")

REPO_ROOT = Path(__file__).resolve().parents[1]
# ...and no DDS socket on another interface: the Fast DDS transport profile that binds every UDP socket to
# 127.0.0.1 (with shared memory beside it). ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST alone leaves them on 0.0.0.0
# and the external interface (docs/node.md, "DDS on loopback"). Inherited by the processes tests start.
FASTDDS_PROFILE = REPO_ROOT / "config" / "fastdds_localhost.xml"
os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(FASTDDS_PROFILE)   # Fast DDS 3 (Kilted wheels)
PACKAGE = "bldc_actuator"

# ROS domain ids used by tests: DOMAIN_ID_BASE..DOMAIN_ID_MAX (101 is the last id whose DDS ports stay
# below the Linux ephemeral range). Under pytest-xdist each worker gets its own slice.
# BLDC_TEST_DOMAIN_RANGE=LO-HI narrows them (two test runs on one machine, e.g. two checkouts, in disjoint ranges).
DOMAIN_ID_BASE, DOMAIN_ID_MAX = (
    int(x) for x in os.environ.get("BLDC_TEST_DOMAIN_RANGE", "40-101").split("-", 1)
)
_domain_counter = itertools.count()


# -------------------------------------------------------------------------------------------- timeouts

#: the largest load factor applied (a hung test at load 20 on 2 cores still fails after 10 x its bound)
MAX_TIMEOUT_FACTOR = 10.0


def timeout_factor() -> float:
    """How much longer than on a quiet machine a wall-clock bound should be: ``$BLDC_TEST_TIMEOUT_FACTOR`` if set,
    else from the load average: ``1 + load / cores`` (the larger of the 1- and 5-minute loads), within
    [1, MAX_TIMEOUT_FACTOR]. A quiet machine: 1; load 4 on 2 cores: 3 (a runnable process gets ~2/5 of a core,
    and ``nice`` less); load 14 on 2 cores: 8."""
    env = os.environ.get("BLDC_TEST_TIMEOUT_FACTOR")
    if env:
        try:
            factor = float(env)
        except ValueError:
            raise pytest.UsageError(
                f"BLDC_TEST_TIMEOUT_FACTOR={env!r}: expected a number >= 1 (a multiplier of wall-clock bounds)")
        if not factor >= 1.0:
            raise pytest.UsageError(
                f"BLDC_TEST_TIMEOUT_FACTOR={env!r}: expected a number >= 1 (a multiplier of wall-clock bounds)")
        return factor
    try:
        load = max(os.getloadavg()[:2])
    except OSError:          # no load average on this platform
        return 1.0
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return min(MAX_TIMEOUT_FACTOR, max(1.0, 1.0 + load / max(1, cores)))


def scaled(seconds: float) -> float:
    """``seconds`` (a bound that holds on a quiet machine) times :func:`timeout_factor` now."""
    return seconds * timeout_factor()


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem):
    """Scale the test's pytest-timeout bound (its ``timeout`` marker, else the ini ``timeout``) by the load as
    it starts; pytest-timeout reads the marker in its own wrapper of this hook, which runs after this one."""
    marker = item.get_closest_marker("timeout")
    args, kwargs = (list(marker.args), dict(marker.kwargs)) if marker is not None else ([], {})
    base = kwargs.pop("timeout", None)
    if base is None and args:
        base = args.pop(0)
    if base is None and item.config.pluginmanager.hasplugin("timeout"):
        base = item.config.getoption("timeout", None) or item.config.getini("timeout")
    if base and float(base) > 0:       # 0: no timeout
        # the same marker (its method, func_only) with the scaled bound, ahead of the test's own
        item.add_marker(pytest.mark.timeout(float(base) * timeout_factor(), *args, **kwargs), append=False)
    yield


# --------------------------------------------------------------------------------------------- markers


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "ros: uses rclpy (a ROS context, nodes, topics)")
    config.addinivalue_line("markers", "slow: takes seconds or more; deselect with -m 'not slow'")
    config.addinivalue_line("markers", "shared_data: needs the real recordings in ../shared/data")
    config.addinivalue_line(
        "markers", "one_kernel_path: a check of the layers above the kernel (e.g. a diagnosis round trip) that "
        "runs on one kernel path; scripts/test.sh's pure-Python pass deselects it (the kernel's two paths are "
        "compared in test_kernel_paths.py and by the physics tests on both)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    implied = {
        "ros_context": "ros",
        "ros_executor": "ros",
        "shared_data_dir": "shared_data",
        "colcon_install_prefix": "slow",
    }
    for item in items:
        for fixture_name, marker in implied.items():
            if fixture_name in getattr(item, "fixturenames", ()):
                item.add_marker(marker)


def pytest_report_header(config: pytest.Config) -> list[str]:
    import importlib.util

    shared = find_shared_data_dir()
    return [
        f"bldc_actuator: repo={REPO_ROOT} ROS_AUTOMATIC_DISCOVERY_RANGE="
        f"{os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']} "
        f"rclpy={'yes' if importlib.util.find_spec('rclpy') else 'no'} "
        f"shared_data={shared if shared else 'absent'}"
    ]


# ------------------------------------------------------------------------------------------ shared data


def find_shared_data_dir() -> Path | None:
    """The real-recordings folder: ``$BLDC_SHARED_DIR/data`` if that variable is set (it names the
    ``shared/`` folder), else ``<repo>/../shared/data``; ``None`` when it does not exist."""
    env = os.environ.get("BLDC_SHARED_DIR")
    shared = Path(env).expanduser() if env else REPO_ROOT.parent / "shared"
    data = shared / "data"
    return data.resolve() if data.is_dir() else None


@pytest.fixture(scope="session")
def shared_data_dir() -> Path:
    data = find_shared_data_dir()
    if data is None:
        where = os.environ.get("BLDC_SHARED_DIR") or str(REPO_ROOT.parent / "shared")
        pytest.skip(f"shared recordings not found: no data/ folder in {where} (set BLDC_SHARED_DIR)")
    return data


# ------------------------------------------------------------------------------------------------- ROS


def next_domain_id() -> int:
    """A ROS domain id not used by any other test of this run (ids cycle only after a whole slice)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    workers = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    ids = DOMAIN_ID_MAX - DOMAIN_ID_BASE + 1
    span = max(1, ids // workers)
    return DOMAIN_ID_BASE + (index * span + next(_domain_counter) % span) % ids


@pytest.fixture
def ros_context():
    """An rclpy Context of its own on a unique domain id; shut down after the test."""
    rclpy = pytest.importorskip("rclpy", reason="rclpy not importable (pip install .[wheels] or source ROS)")
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(context=context, domain_id=next_domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@pytest.fixture
def ros_executor(ros_context):
    """A SingleThreadedExecutor on ``ros_context`` spinning in a daemon thread.

    Create nodes with ``context=ros_context`` and ``ros_executor.add_node(node)``; at teardown the executor
    stops and every node still added to it is destroyed.
    """
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=ros_context)

    def spin() -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass

    thread = threading.Thread(target=spin, name="ros_executor", daemon=True)
    thread.start()
    try:
        yield executor
    finally:
        executor.shutdown(timeout_sec=5.0)
        thread.join(timeout=5.0)
        for node in executor.get_nodes():
            node.destroy_node()


def wait_for(predicate: Callable[[], object], timeout: float = 5.0, interval: float = 0.01):
    """Poll ``predicate`` until it returns something truthy (returned) or ``scaled(timeout)`` seconds pass
    (returns the last falsy value, so ``assert wait_for(...)`` reads naturally). ``timeout`` is the bound on a
    quiet machine; a passing wait returns as soon as the predicate holds, so the scaling costs nothing."""
    deadline = time.monotonic() + scaled(timeout)
    while True:
        value = predicate()
        if value or time.monotonic() >= deadline:
            return value
        time.sleep(interval)


# ----------------------------------------------------------------------------------------------- colcon

# top-level entries of the checkout that are not part of the package source
_NOT_SOURCE = {".git", ".venv", "build", "install", "log", "out", ".pytest_cache", ".ci"}


def colcon_executable() -> str | None:
    """``colcon`` next to the running interpreter (the project venv), else on PATH."""
    beside = Path(sys.executable).parent / "colcon"
    return str(beside) if beside.exists() else shutil.which("colcon")


def colcon_install(workdir: Path, source: Path = REPO_ROOT, timeout: float = 600.0) -> Path:
    """``colcon build`` a copy of the package in ``workdir`` and return the package's install prefix
    (``workdir/install/bldc_actuator``: ``lib/bldc_actuator/<executables>``, ``share/bldc_actuator/...``,
    ``lib/pythonX.Y/site-packages/bldc_actuator``). Skips the calling test when colcon is missing.

    The build runs with the current interpreter's colcon (no ``--symlink-install``: it breaks with
    setuptools >= 80), logs and COLCON_HOME inside ``workdir``, so nothing is written to the checkout.
    """
    colcon = colcon_executable()
    if colcon is None:
        pytest.skip("colcon not installed (pip install colcon-common-extensions, or .[test])")
    workdir = Path(workdir)
    src = workdir / "src" / PACKAGE
    src.mkdir(parents=True, exist_ok=True)
    for entry in source.iterdir():
        if entry.name in _NOT_SOURCE or entry.name.endswith(".egg-info"):
            continue
        if entry.is_dir():
            shutil.copytree(
                entry, src / entry.name, dirs_exist_ok=True,
                ignore=shutil.ignore_patterns("__pycache__", "*.pyc"),
            )
        else:
            shutil.copy2(entry, src / entry.name)
    env = dict(os.environ, COLCON_HOME=str(workdir / "colcon_home"))
    cmd = [
        colcon, "--log-base", str(workdir / "log"),
        "build", "--base-paths", str(src),
        "--build-base", str(workdir / "build"), "--install-base", str(workdir / "install"),
        "--event-handlers", "console_cohesion+", "desktop_notification-", "status-", "terminal_title-",
    ]  # fmt: skip
    result = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=scaled(timeout))
    if result.returncode != 0:
        pytest.fail(
            f"colcon build failed (exit {result.returncode}): {' '.join(cmd)}\n"
            f"--- stdout ---\n{result.stdout[-6000:]}\n--- stderr ---\n{result.stderr[-4000:]}",
            pytrace=False,
        )
    return workdir / "install" / PACKAGE


def colcon_env(prefix: Path, base: dict[str, str] | None = None) -> dict[str, str]:
    """Environment in which the scripts of a colcon install under ``prefix`` import *that* install
    (what ``source install/setup.bash`` would add): its site-packages first on PYTHONPATH, the prefix on
    AMENT_PREFIX_PATH. The editable install in the venv sits behind PYTHONPATH, so it does not interfere.
    """
    prefix = Path(prefix)
    env = dict(os.environ if base is None else base)
    site = sorted(prefix.glob("lib/python3*/site-packages")) + sorted(prefix.glob("local/lib/python3*/dist-packages"))
    paths = [str(p) for p in site] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(prefix)] + [p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p])
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


@pytest.fixture(scope="session")
def colcon_install_prefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One colcon build of this package per test run, shared by the pytest-xdist workers (the first to ask
    builds it under a file lock in the run's common temporary folder, the others wait and reuse it); returns the
    install prefix."""
    import fcntl

    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent          # the run's folder, above each worker's own
    workdir, built = base / "colcon_ws_shared", base / "colcon_ws_shared.built"
    with open(base / "colcon_ws_shared.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)         # released when the file closes
        if not built.exists():
            shutil.rmtree(workdir, ignore_errors=True)     # a failed build of another worker
            workdir.mkdir()
            colcon_install(workdir)
            built.write_text("ok\n")
    return workdir / "install" / PACKAGE
