"""Issue #25, symptom 4: the fleet on three demo recordings of the UNMODIFIED ak80_9 must not cry wolf and must exit.

Before: ``bldc-actuator fleet`` alerted "off nominal" on Coulomb (0.0548 +- 0.0019 N*m against the true and nominal
0.0298, "+84 %, 13 sd") and on viscous damping (-1.0e-4 for 1e-5) while the fitted values made the held-out error
worse and ``diagnose`` said "not found"; it exited 0 when every file failed and on an invalid ``--params``.

Root causes tested here: the tracked fit skipped diagnose's sub-sample alignment of the logged current to the motion
(the friction pair absorbed the misalignment's residual), and the off-nominal alert had no acceptance rule of its own
(a value many sd off was an alert whatever the held-out data said). Now the tracked context is prepared as diagnose
prepares it, and an off-nominal alert needs the change to pass the rule a diagnose finding passes (diagnose's own
verdict where it ran, else the same selection gate and significance judge: ``health.support``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bldc_actuator.fleet import alerts as A  # noqa: E402

#: generous: the command takes ~1-2 min for three demo files on a loaded 2-core machine; a process that does not
#: exit after its outputs (the issue's hang) runs into it
CLI_TIMEOUT_S = 1200


@pytest.fixture(scope="module")
def demo_files(tmp_path_factory):
    """Three demo recordings of the unmodified ak80_9 (the demo runs lock-step: one run, copied)."""
    pytest.importorskip("rclpy", reason="rclpy not importable: cannot run the demo node")
    from conftest import next_domain_id

    from bldc_actuator.demo import run_demo

    root = tmp_path_factory.mktemp("demo_fleet")
    run_demo("ak80_9", root / "run", domain_id=next_domain_id(), plot=False, quiet=True)
    files = []
    for k in (1, 2, 3):
        d = root / f"demo{k}"
        d.mkdir()
        shutil.copy(root / "run" / "demo.mcap", d / "demo.mcap")
        files.append(d / "demo.mcap")
    return root, files


def _preset_file() -> Path:
    return REPO / "config" / "ak80_9.yaml"


@pytest.mark.slow
@pytest.mark.ros
def test_tracked_friction_of_the_demo_is_the_true_one_and_not_a_finding(demo_files):
    from bldc_actuator.diagnosis.io.cleaning import clean
    from bldc_actuator.diagnosis.io.loaders import load
    from bldc_actuator.fleet.health import track
    from bldc_actuator.params import load_yaml

    _, files = demo_files
    p = load_yaml(_preset_file())
    sig = clean(load(files[0], params=p), params=p)
    got = {t.parameter: t for t in track(sig, p)}
    c, b = got["coulomb_friction"], got["viscous_damping"]
    # the truth is the nominal: 0.0298 N*m, 1e-5 N*m*s/rad (before: 0.0548 +- 0.0019 and -1.0e-4 +- 8.6e-6)
    assert abs(c.value - 0.0298) < 3 * c.uncertainty + 0.05 * 0.0298, (c.value, c.uncertainty)
    assert b.value > 0 and abs(b.value - 1e-5) < 3 * b.uncertainty + 1e-5, (b.value, b.uncertainty)
    # nothing is missing from this model: no tracked change passes the finding rule
    for t in got.values():
        assert not t.supported, (t.parameter, t.support)
    assert "not supported" in c.support


@pytest.mark.slow
@pytest.mark.ros
def test_fleet_cli_on_three_demo_recordings_exits_with_no_alert(demo_files, tmp_path):
    """The command as a user runs it (full diagnosis, local cluster), in a subprocess that must exit by itself."""
    root, _ = demo_files
    out = tmp_path / "out"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    cmd = [sys.executable, "-m", "bldc_actuator.cli", "fleet", str(root / "demo*" / "demo.mcap"),
           "--params", str(_preset_file()), "--out", str(out), "--workers", "2", "--no-progress"]
    t0 = time.monotonic()
    p = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=CLI_TIMEOUT_S)
    print(f"fleet CLI: exit {p.returncode} after {time.monotonic() - t0:.0f} s\n{p.stdout}\n{p.stderr[-3000:]}")
    assert p.returncode == 0, p.stderr[-3000:]
    doc = json.loads((out / "alerts.json").read_text())
    assert doc["alerts"] == [], [a["message"] for a in doc["alerts"]]
    assert "0 alert(s)" in p.stdout and "ALERT" not in p.stdout
    assert doc["summary"]["recordings"] == 3 and doc["failures"] == []
    # the one rule: what diagnose did not find is not supported in the table either
    import pyarrow.parquet as pq

    rows = [r for r in pq.read_table(out / "fleet.parquet").to_pylist() if r["source"] == "tracked"]
    assert rows and not any(r["supported"] for r in rows if not r["accepted"])
    fr = [r for r in rows if r["parameter"] == "coulomb_friction"]
    assert len(fr) == 3 and all(abs(r["value"] - 0.0298) < 0.003 for r in fr), [r["value"] for r in fr]


def _row(value, sd, nominal, **kw):
    return dict({"recording": "/x/a/0.mcap", "joint": "", "actuator_id": "a", "start_time": "2026-01-01T08:00:00+00:00",
                 "source": "tracked", "effect": "coulomb_friction", "parameter": "coulomb_friction", "value": value,
                 "uncertainty": sd, "unit": "N*m", "nominal": nominal, "status": "ok", "params_file": "p.yaml"}, **kw)


def test_off_nominal_alert_needs_the_finding_rule():
    # 84 % off and 13 sd (the numbers): an alert only when the change is supported like a finding
    assert A.evaluate([_row(0.0548, 0.0019, 0.0298, supported=False, support="not supported: ΔBIC -5.8")])["alerts"] == []
    ev = A.evaluate([_row(0.0548, 0.0019, 0.0298, supported=True, support="passed")])
    assert [a["kinds"] for a in ev["alerts"]] == [["off_nominal"]]
    # the CSV table's text cells
    assert A.evaluate([_row(0.0548, 0.0019, 0.0298, supported="False")])["alerts"] == []
    assert A.evaluate([_row(0.0548, 0.0019, 0.0298, supported="True")])["alerts"] != []
    # an unsupported value beyond tolerance and sd is kept as evidence in the series, not alerted
    s = A.evaluate([_row(0.0548, 0.0019, 0.0298, supported=False, support="why")])["series"][0]
    latest = s["off_nominal"]["latest"]
    assert latest["beyond_tolerance_and_sigma"] and not latest["off"] and latest["support"] == "why"


def test_the_row_rule_follows_diagnose_where_it_ran():
    from bldc_actuator.fleet.health import Tracked
    from bldc_actuator.fleet.run import supported

    t = Tracked("coulomb_friction", "coulomb_friction", "N*m", 0.05, 0.001, 0.03, supported=True, support="passed")
    assert supported(t, False, "not found: ΔBIC -5.8 <= 10")[0] is False       # diagnose tested it: its verdict
    assert supported(t, True, "accepted: coulomb_friction = 0.05 ± 0.001")[0] is True
    assert supported(t, False, "") == (True, "passed")                         # not tested (--tracked-only)
    t.supported = False
    assert supported(t, False, "")[0] is False


def test_exit_code_when_every_file_fails(tmp_path, capsys):
    from bldc_actuator.cli import main

    for k in range(2):
        (tmp_path / f"bad{k}.mcap").write_bytes(b"not an mcap file" * 10)
    rc = main(["fleet", str(tmp_path / "*.mcap"), "--params", str(_preset_file()), "--out", str(tmp_path / "o"),
               "--workers", "1", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1, err
    assert "none of the 2 file(s) could be diagnosed" in err
    assert (tmp_path / "o" / "alerts.json").exists()          # the failures are still written


def test_invalid_params_exit_code_names_field_range_and_unit(tmp_path, capsys):
    from bldc_actuator.cli import main

    text = _preset_file().read_text()
    assert "phase_resistance:" in text
    bad = tmp_path / "bad.yaml"
    bad.write_text("\n".join(("      phase_resistance: -0.5" if ln.strip().startswith("phase_resistance:") else ln)
                             for ln in text.splitlines()))
    rec = tmp_path / "r.mcap"
    rec.write_bytes(b"x")
    rc = main(["fleet", str(rec), "--params", str(bad), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "motor.phase_resistance" in err and "ohm" in err and "outside" in err
    assert not (tmp_path / "o").exists()                      # refused before any work was sent out
    # the same through a params map
    pm = tmp_path / "pm.yaml"
    pm.write_text(f"'*': {bad}\n")
    assert main(["fleet", str(rec), "--params-map", str(pm), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert "motor.phase_resistance" in capsys.readouterr().err


def test_shutdown_ends_worker_processes_a_failed_close_left_behind():
    """A cluster whose close times out (a loaded machine) must not leave its worker processes for the
    interpreter's exit to wait on: shutdown ends them."""
    from bldc_actuator.fleet.run import shutdown

    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])

    class Worker:
        pid = proc.pid

    class StuckCluster:
        workers = {"w0": Worker()}

        def close(self, timeout=None):
            raise TimeoutError("close timed out")

    try:
        ended = shutdown(None, StuckCluster(), timeout=1.0)
        assert ended == [proc.pid]
        assert proc.wait(timeout=60) is not None
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.mark.slow
def test_the_finding_rule_supports_a_real_change_and_refuses_none(tmp_path):
    """The rule can pass: one output-side CSV log of an actuator whose friction is +50 % and R_ha +30 % off the
    parameter file: both tracked changes are supported (an off-nominal alert follows); the same log of the
    nominal actuator: no change is supported."""
    from benchmarks import fleet_gen as G
    from bldc_actuator.diagnosis.io.cleaning import clean
    from bldc_actuator.diagnosis.io.loaders import load
    from bldc_actuator.fleet.health import track

    import numpy as np

    nominal = G.nominal_params()
    base = G.true_params(nominal, G.Unit("r/j", "output_csv"), 0, 30, np.random.default_rng(5)).replace(**{
        "effects.coulomb_friction": nominal.effects.coulomb_friction,
        "thermal.housing_to_ambient_resistance": nominal.thermal.housing_to_ambient_resistance,
        "motor.torque_constant_q": nominal.motor.torque_constant_q,
        "motor.viscous_damping": nominal.motor.viscous_damping})
    off = base.replace(**{"effects.coulomb_friction": 1.5 * nominal.effects.coulomb_friction,
                          "thermal.housing_to_ambient_resistance": 1.3 * nominal.thermal.housing_to_ambient_resistance})
    got = {}
    for name, p in (("nominal", base), ("off", off)):
        G.write_output_csv(tmp_path / f"{name}.csv", G.simulate(p, 15.0, 250.0, np.random.default_rng(7)))
        sig = clean(load(tmp_path / f"{name}.csv", params=nominal), params=nominal)
        got[name] = {t.parameter: t for t in track(sig, nominal)}
    for par in ("coulomb_friction", "housing_to_ambient_resistance"):
        t = got["off"][par]
        assert t.supported, (par, t.value, t.support)
        assert t.support.startswith("passed")
    rows = [dict(_row(t.value, t.uncertainty, t.nominal), parameter=t.parameter, supported=t.supported,
                 support=t.support) for t in got["off"].values() if t.status == "ok"]
    alerted = {a["parameter"] for a in A.evaluate(rows)["alerts"]}
    assert {"coulomb_friction", "housing_to_ambient_resistance"} <= alerted, alerted
    assert not [t.parameter for t in got["nominal"].values() if t.supported], \
        {t.parameter: t.support for t in got["nominal"].values()}
