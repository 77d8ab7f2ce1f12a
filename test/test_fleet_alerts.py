"""Fleet alerts (bldc_actuator.fleet.alerts) and the honesty of the tracked uncertainties they rest on:

* the drift test keeps its false-alarm rate on stable series from three recordings on, whether the stated
  uncertainties are honest or all too small by the same factor (the fleet's pooled over-dispersion), and finds
  the issue's creeping friction after four days;
* the off-nominal test alerts from ONE recording when a value is beyond the tolerance and many combined sd,
  and not when a value is many sd but within tolerance (a real 1 % unit-to-unit difference);
* the projected date a limit is reached is the straight line's;
* the tracked estimator's stated sd covers the TRUE parameter on generated logs with known truth: short,
  noise-free closed-loop logs (where the fit's own sd was 5-50x too small or too large) and noisy ones.
"""

from __future__ import annotations

import datetime as dt
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bldc_actuator.fleet import alerts as A  # noqa: E402

T0 = dt.datetime(2026, 1, 1, 8, tzinfo=dt.timezone.utc)


def _rows(aid, values, sds, nominal, parameter="coulomb_friction", days=None, params_file="p.yaml"):
    days = days if days is not None else range(len(values))
    return [{"recording": f"/x/{aid}/{d}.mcap", "joint": "", "actuator_id": aid,
             "start_time": (T0 + dt.timedelta(days=float(d))).isoformat(), "source": "tracked",
             "effect": "coulomb_friction", "parameter": parameter, "value": v, "uncertainty": s, "unit": "N*m",
             "nominal": nominal, "status": "ok", "params_file": params_file}
            for d, v, s in zip(days, values, sds)]


# ------------------------------------------------------------------------------------------ drift test

@pytest.mark.parametrize("n", [3, 4, 6])
def test_drift_test_false_alarm_rate_with_honest_uncertainties(n):
    """Stable series, each recording with its own (honest) sd: alarm rate ~ alpha (binomial band)."""
    rng = np.random.default_rng(100 + n)
    alpha, trials = 0.01, 4000
    t = np.arange(n, dtype=float)
    alarms = 0
    for _ in range(trials):
        u = rng.uniform(0.5, 2.0, n)
        v = 1.0 + u * rng.normal(size=n)
        alarms += A.drift_test(t, v, u, alpha=alpha)["alert"]
    assert 40 - 3 * 6.3 <= alarms <= 40 + 3 * 6.3, alarms       # binomial(4000, 0.01): 40 +- 6.3


def test_drift_test_pools_overdispersion_across_the_fleet():
    """Every stated sd 3x too small (model-form scatter between days): the pooled Birge ratio finds ~9 and the
    alarm rate of 4-recording series stays at alpha; without pooling (F = 1) it would be far above."""
    rng = np.random.default_rng(7)
    alpha, fleets, per_fleet, n = 0.01, 150, 20, 4
    t = np.arange(n, dtype=float)
    alarms = naive = 0
    b2s = []
    for _ in range(fleets):
        series = []
        for _ in range(per_fleet):
            u = rng.uniform(0.5, 2.0, n)
            series.append((t, 1.0 + 3.0 * u * rng.normal(size=n), u))
        b2, dof, _ = A.overdispersion(series)
        b2s.append(b2)
        for s in series:
            alarms += A.drift_test(*s, b2=b2, dof_pool=dof, alpha=alpha)["alert"]
            naive += A.drift_test(*s, alpha=alpha)["alert"]
    total = fleets * per_fleet                                  # 3000 series: alpha -> 30 +- 5.5
    assert np.median(b2s) == pytest.approx(9.0, rel=0.2)
    assert alarms <= 30 + 3 * 5.5, alarms
    assert naive > 10 * 30, naive


def test_the_issue_friction_creep_is_drifting_after_four_days_and_off_nominal_on_day_two():
    values = [0.010, 0.016, 0.022, 0.027, 0.034, 0.040]
    sds = [1e-4] * 6
    stable = [_rows(f"robot{k}/hip", list(0.010 + 1e-4 * np.random.default_rng(k).normal(size=6)), sds, 0.010)
              for k in (2, 3)]
    for days in (1, 2, 3, 4):
        rows = _rows("robot1/knee", values[:days], sds[:days], 0.010) + [r for s in stable for r in s[:days]]
        ev = A.evaluate(rows, A.Options(limits={"coulomb_friction": 0.05}))
        kinds = {(a["actuator_id"], a["parameter"]): a["kinds"] for a in ev["alerts"]}
        if days == 1:
            assert kinds == {}                                   # 0.010 is the nominal
        else:
            assert list(kinds) == [("robot1/knee", "coulomb_friction")]
            assert "off_nominal" in kinds[("robot1/knee", "coulomb_friction")]
        if days >= 3:
            assert "drifting" in kinds[("robot1/knee", "coulomb_friction")]
    a = ev["alerts"][0]
    assert a["first"]["value"] == 0.010 and a["last"]["value"] == 0.027 and a["n"] == 4
    assert a["rate_per_day"] == pytest.approx(0.0057, rel=0.05)
    # the limit: 0.05 N*m is reached by the fitted line ~ (0.05 - 0.027) / 0.0057 = 4 days after day 3
    when = dt.datetime.fromisoformat(a["limit"]["projected_date"])
    assert (when - T0).total_seconds() / 86400 == pytest.approx(3 + (0.05 - 0.0271) / 0.0057, abs=0.3)
    assert "robot1/knee" in a["message"] and "0.027" in a["message"] and "projected" in a["message"]


def test_off_nominal_needs_tolerance_and_sigma():
    # 1 % off nominal, 100 sd: a real unit-to-unit difference, within the 10 % tolerance: no alert
    ev = A.evaluate(_rows("a", [0.0101], [1e-6], 0.010))
    assert ev["alerts"] == [] and ev["series"][0]["off_nominal"]["latest"]["z"] > 50
    # 50 % off but only 2 sd (a poorly identified value): no alert
    assert A.evaluate(_rows("a", [0.015], [0.0025], 0.010))["alerts"] == []
    # 50 % off and 50 sd: an alert from this one recording
    ev = A.evaluate(_rows("a", [0.015], [1e-4], 0.010))
    assert [x["kinds"] for x in ev["alerts"]] == [["off_nominal"]]
    # a per-parameter tolerance
    assert A.evaluate(_rows("a", [0.015], [1e-4], 0.010), A.Options(tolerance={"coulomb_friction": 0.6}))["alerts"] == []


def test_fleet_reference_uses_the_fleet_baseline():
    """Nominal file off for the whole fleet (every unit 0.013 against a nominal 0.010): against the nominal all
    alert, against the fleet's own baseline none -- except the unit that is off from its peers."""
    rows = []
    for k in range(5):
        rows += _rows(f"r{k}", [0.013 + 1e-4 * k, 0.013 + 1e-4 * k], [1e-4, 1e-4], 0.010)
    rows += _rows("odd", [0.013, 0.020], [1e-4, 1e-4], 0.010)
    assert len(A.evaluate(rows)["alerts"]) == 6
    ev = A.evaluate(rows, A.Options(reference="fleet"))
    assert [a["actuator_id"] for a in ev["alerts"]] == ["odd"]


def test_bad_options_name_the_option():
    with pytest.raises(ValueError, match="--limit"):
        A.parse_assignments(["coulomb_friction"], "--limit")
    assert A.parse_assignments(["coulomb_friction=0.05"], "--limit") == {"coulomb_friction": 0.05}


# ------------------------------------------------------------------------- coverage of the stated sd

def _signals(sim: dict, gear: float):
    from bldc_actuator.diagnosis.signals import Signals

    ch = {"current": sim["i_q"], "current_command": sim["i_q_ref"], "velocity": sim["velocity_out"] * gear,
          "position": sim["position_out"] * gear, "voltage_q": sim["v_q"], "bus_voltage": sim["bus_voltage"],
          "winding_temperature": sim["T_winding"], "housing_temperature": sim["T_housing"]}
    return Signals(sim["t"], ch, "generated", meta={"gear_ratio": gear})


TRUE_FIELD = {"coulomb_friction": "effects.coulomb_friction", "viscous_damping": "motor.viscous_damping",
              "torque_constant_q": "motor.torque_constant_q", "phase_resistance": "motor.phase_resistance",
              "housing_to_ambient_resistance": "thermal.housing_to_ambient_resistance"}


@pytest.fixture(scope="module")
def coverage():
    """|value - truth| / sd of every tracked parameter on 8 short noise-free closed-loop logs (10 s) and 8
    noisy ones (30 s), generated with known truth (1 % unit-to-unit spread, warm start)."""
    from benchmarks import fleet_gen as G
    from bldc_actuator.diagnosis.io.cleaning import clean
    from bldc_actuator.fleet.health import track

    nominal = G.nominal_params()
    z: dict[tuple[str, str], list[float]] = {}
    for label, duration, noise in (("noise-free 10 s", 10.0, 0.0), ("noisy 30 s", 30.0, 1.0)):
        for k in range(8):
            rng = np.random.default_rng([77, k, int(noise)])
            p = G.true_params(nominal, G.Unit(f"u{k}", "mcap"), 0, 30, rng)
            sig = _signals(G.simulate(p, duration, 250.0, rng, noise=noise, loop="closed"), p.gear.gear_ratio)
            flat = p.to_flat()
            for t in track(clean(sig, params=nominal), nominal):
                assert t.status == "ok", (t.parameter, t.reason)
                z.setdefault((label, t.parameter), []).append((t.value - flat[TRUE_FIELD[t.parameter]]) / t.uncertainty)
    return z


def test_tracked_uncertainty_covers_the_truth(coverage):
    """Every stated sd covers the truth: |z| < 3.5 on every log (a 3.5-sd miss has probability 5e-4 per value
    when the sd is honest), and the sd is not inflated into uselessness (median |z| > 0.1)."""
    for key, zs in coverage.items():
        zs = np.abs(np.array(zs))
        assert zs.max() < 3.5, (key, np.round(zs, 1))
    allz = np.abs(np.concatenate([np.array(v) for v in coverage.values()]))
    assert np.median(allz) > 0.1, np.median(allz)


def test_cli_rejects_bad_alert_options(tmp_path, capsys):
    from bldc_actuator.cli import main

    f = tmp_path / "a.csv"
    f.write_text("t\n0\n")
    for bad, word in ((["--limit", "coulomb_friction"], "--limit"), (["--tolerance", "x=abc"], "--tolerance"),
                      (["--tolerance", "-0.5"], "--tolerance"), (["--k-sigma", "0"], "--k-sigma")):
        assert main(["fleet", str(f), "--out", str(tmp_path / "o"), *bad]) == 2
        assert word in capsys.readouterr().err
