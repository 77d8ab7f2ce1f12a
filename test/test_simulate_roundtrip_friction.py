"""Issue #24 (b): the project's own simulator, logged at 1 kHz, diagnosed against its preset.

``bldc-actuator simulate`` of ak80_9 with the Coulomb friction doubled (0.0298 -> 0.06 N*m), a current chirp inside
the voltage limit, CSV at 1 kHz (read through its input profile, no --map) -> ``bldc-actuator diagnose --params
ak80_9`` must name coulomb_friction at 0.06 N*m, not "physics outside the catalogue". The log is noise-free: the
closed-loop replay reproduces the current to ~0.0007 A of 1.06 A RMS, and a +0.00014 A change of that current
error used to count as "worsens the simulated current", refusing a finding that took the simulated velocity error
from 16 to 1.03 rad/s (judge.simulated.OTHER_CHANNEL_RESOLUTION).
"""

from __future__ import annotations

import json

import pytest

from bldc_actuator import cli
from bldc_actuator.params import dump_yaml, load_preset


@pytest.fixture(scope="module")
def doubled_coulomb_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("roundtrip")
    truth = load_preset("ak80_9").replace(**{"effects.coulomb_friction": 0.06})
    dump_yaml(truth, d / "truth.yaml")
    assert cli.main(["simulate", "--params", str(d / "truth.yaml"), "--profile", "chirp", "--amplitude", "1.5",
                     "--f0", "1", "--f1", "50", "--duration", "10", "--rate", "1000", "--no-plot",
                     "--out", str(d / "run")]) == 0
    cli.main(["diagnose", "--params", "ak80_9", str(d / "run.csv"), "--no-plots", "--quiet",
              "--json", str(d / "report.json")])
    return json.loads((d / "report.json").read_text())


def test_doubled_coulomb_friction_is_named_from_a_1khz_simulate_log(doubled_coulomb_report):
    rep = doubled_coulomb_report
    found = {f["effect"]: f for f in rep["findings"]}
    assert "coulomb_friction" in found, rep["verdict"]
    assert rep["verdict_kind"] == "found", rep["verdict"]
    assert "physics outside the catalogue" not in rep["verdict"], rep["verdict"]
    assert found["coulomb_friction"]["parameters"]["coulomb_friction"] == pytest.approx(0.06, rel=0.05)
    coulomb = [r for r in rep["rejected"] if r["effect"] == "coulomb_friction"
               and "worsens" in str(r.get("reason", ""))]
    assert not coulomb, coulomb
