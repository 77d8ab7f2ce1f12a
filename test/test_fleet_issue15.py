"""Issue #15 as a user meets it: three actuators, daily 30 s closed-loop logs, one actuator's Coulomb friction
creeping 0.010 -> 0.016 -> 0.022 -> 0.027 N*m (nominal 0.010), the last log of a stable actuator cut short
(an MCAP its recorder never finalized). After four days ``bldc-actuator fleet`` (full diagnosis) raises
EXACTLY ONE alert, on the drifting actuator's friction, with its evidence and the projected date of the
user's limit; no alert on the stable actuators; one row per recording x joint x parameter; the unfinalized
recording carried as a warning; and the same run through a Dask scheduler with two workers on 127.0.0.1
(started and stopped here) gives identical tracked values and alerts."""

from __future__ import annotations

import datetime as dt
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import scaled

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks import fleet_gen as G  # noqa: E402

FRICTION = (0.010, 0.016, 0.022, 0.027)
DAYS = 4


@pytest.fixture(scope="module")
def issue_fleet(tmp_path_factory):
    pytest.importorskip("rclpy", reason="rclpy not importable: cannot write ROS messages")
    root = tmp_path_factory.mktemp("issue15")
    units = [G.Unit("robot1/knee", "mcap", None, schedule={"effects.coulomb_friction": FRICTION}),
             G.Unit("robot1/hip", "mcap", None, schedule={"effects.coulomb_friction": (0.010,)}),
             G.Unit("robot2/knee", "mcap", None, schedule={"effects.coulomb_friction": (0.010,)})]
    truth = G.generate(root, days=DAYS, duration=30.0, rate=250.0, units=units, loop="closed",
                       nominal_overrides={"effects.coulomb_friction": 0.010}, unfinalized=1)
    assert truth["unfinalized"] and "robot2/knee" in truth["unfinalized"][0]
    return root, truth


def _cli(root, out, *extra):
    from bldc_actuator.cli import main

    return main(["fleet", str(root / "**" / "*.mcap"), "--params", str(root / "params.yaml"), "--out", str(out),
                 "--no-progress", "--limit", "coulomb_friction=0.05", *extra])


@pytest.fixture(scope="module")
def local(issue_fleet, tmp_path_factory):
    import pyarrow.parquet as pq

    root, _ = issue_fleet
    out = tmp_path_factory.mktemp("issue15_out")
    assert _cli(root, out, "--workers", "2") == 0
    return out, pq.read_table(out / "fleet.parquet").to_pylist(), json.loads((out / "alerts.json").read_text())


def test_exactly_one_alert_the_drifting_friction(local):
    out, rows, doc = local
    assert [(a["actuator_id"], a["parameter"]) for a in doc["alerts"]] == [("robot1/knee", "coulomb_friction")]
    a = doc["alerts"][0]
    assert set(a["kinds"]) == {"off_nominal", "drifting"}
    # evidence: first and last value with sd (each covering its true value), rate, recordings, limit date
    assert abs(a["first"]["value"] - FRICTION[0]) < 3 * a["first"]["sd"] + 5e-4
    assert abs(a["last"]["value"] - FRICTION[-1]) < 3 * a["last"]["sd"] + 5e-4
    assert a["n"] == DAYS and len(a["recordings"]) == DAYS and all("robot1/knee" in r for r in a["recordings"])
    true_rate = (FRICTION[-1] - FRICTION[0]) / (DAYS - 1)
    assert abs(a["rate_per_day"] - true_rate) < 3 * a["rate_se_per_day"] + 0.1 * true_rate
    lim = a["limit"]
    assert lim["limit"] == 0.05 and not lim["reached"]
    days = (dt.datetime.fromisoformat(lim["projected_date"]) - dt.datetime.fromisoformat(a["first"]["start_time"]))
    assert days.total_seconds() / 86400 == pytest.approx((0.05 - FRICTION[0]) / true_rate, abs=1.0)   # ~7 days
    # stable actuators: every parameter tested, none alerted
    stable = [s for s in doc["series"] if s["actuator_id"] != "robot1/knee"]
    assert len(stable) == 10 and not any(s["alert"] for s in stable)
    assert all(s["drift"]["tested"] for s in stable)


def test_one_row_per_recording_joint_parameter_and_data_issues(local, issue_fleet):
    out, rows, doc = local
    _, truth = issue_fleet
    keys = [(r["recording"], r["joint"], r["parameter"]) for r in rows]
    assert len(keys) == len(set(keys))
    fr = [r for r in rows if r["parameter"] == "coulomb_friction"]
    assert len(fr) == 3 * DAYS and all(r["nominal"] == pytest.approx(0.010) for r in fr)
    # what diagnose said is in the tracked row (its accepted friction folded in, not a second row)
    knee = [r for r in fr if r["actuator_id"] == "robot1/knee"]
    assert sum(r["diagnosis"].startswith("accepted") for r in knee) >= 2, [r["diagnosis"] for r in knee]
    # held-out figures in the equation's own unit, of a physical size (they read 46171536 -> 75904637 before)
    for r in rows:
        if r["source"] == "tracked" and r["heldout_metric"]:
            assert r["heldout_before"] < 5.0 and r["heldout_after"] < 5.0, r
            assert "[" in r["heldout_metric"]
    # the unfinalized recording: values kept, status warning, the reason said, and in the report
    cut = [r for r in rows if r["recording"] == truth["unfinalized"][0]]
    assert cut and all(r["status"] == "warning" and "unfinalized" in r["data_issues"] for r in cut)
    assert all("unfinalized" not in r["data_issues"] for r in rows if r["recording"] != truth["unfinalized"][0])
    rep = (out / "report.html").read_text()
    assert rep.index("Alerts: 1") < rep.index("robot1/knee") < rep.index("Data issues") < rep.index("<h2>Actuators")
    assert "not finalized" in rep.lower() and rep.count("data:image/png;base64,") == 3


def test_dask_scheduler_with_two_workers_gives_identical_results(issue_fleet, local, tmp_path):
    """A scheduler and two worker processes on 127.0.0.1 (started here, stopped here, every wait bounded)."""
    import pyarrow.parquet as pq

    root, _ = issue_fleet
    lout, lrows, ldoc = local
    sched_file = tmp_path / "scheduler.json"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", DASK_DISTRIBUTED__WORKER__DAEMON="False")
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard", "--scheduler-file", str(sched_file)],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    out = tmp_path / "out"
    try:
        t_end = time.monotonic() + scaled(60)
        while not sched_file.exists() and time.monotonic() < t_end:
            time.sleep(0.2)
        assert sched_file.exists(), "scheduler did not start"
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                           "--host", "127.0.0.1", "--nthreads", "1", "--no-dashboard",
                                           "--death-timeout", str(int(scaled(60)))],
                                          env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout=f"{scaled(30):.0f}s") as c:
            c.wait_for_workers(2, timeout=scaled(60))
        assert _cli(root, out, "--scheduler", address) == 0
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=scaled(20))
            except subprocess.TimeoutExpired:
                p.kill()
    doc = json.loads((out / "alerts.json").read_text())
    assert doc["summary"]["workers"] == 2 and doc["summary"]["scheduler"] == address
    drows = pq.read_table(out / "fleet.parquet").to_pylist()
    key = lambda r: (r["recording"], r["joint"], r["parameter"])  # noqa: E731
    fields = ("value", "uncertainty", "status", "diagnosis", "data_issues", "heldout_before", "heldout_after")
    assert {key(r): tuple(r[f] for f in fields) for r in drows} == {key(r): tuple(r[f] for f in fields) for r in lrows}
    assert doc["alerts"] == ldoc["alerts"] and doc["series"] == ldoc["series"]
