"""Adding a linear effect is one file (issue #24, docs/effects.md section 3): the worked example of the docs (a
quadratic drag, ``c ω|ω|``, which the catalogue does not have) written into a directory of its own and registered
through the registry's discovery (``registry.add_path``), the package untouched; the diagnosis then names it on a
recording of the project's actuator with that drag applied through the public API (an external load torque at
the output, ``Actuator.set_load_torque``, from the true speed at every step), with ``c`` within its uncertainty,
and does not name it on the same recording without drag.

The drag has no simulator term (``simulated=False``), so the diagnosis runs its equation-error search and fit
without the replay judge (``replay=False``), which would have nothing to replay it with."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from bldc_actuator import voltage_timing
from bldc_actuator.diagnosis.effects import registry
from bldc_actuator.diagnosis.pipeline import DiagnoseOptions, diagnose
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.model import Actuator
from bldc_actuator.params import ActuatorParams

from test_issue14_judge_helpers import triangle_then_sines

DOC = Path(__file__).resolve().parents[1] / "docs" / "effects.md"
NOMINAL = ActuatorParams().replace(**{"gear.gear_ratio": 9.0})
#: drag coefficient [N m s^2/rad^2] (rotor side): 0.016 N m at the recording's 40 rad/s, 30 % of the peak torque
C_DRAG = 1.0e-5


def _example_module() -> tuple[str, str]:
    """(file name, source) of the docs' worked example: the python block opening with ``# effects/<name>.py``."""
    m = re.search(r"```python\n# effects/(\w+\.py)\n(.*?)```", DOC.read_text(), re.S)
    assert m, "docs/effects.md section 3 must hold the worked example (a python block opening '# effects/<name>.py')"
    return m.group(1), m.group(2)


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    name, src = _example_module()
    d = tmp_path_factory.mktemp("effect_plugin")
    (d / name).write_text(src)
    registry.add_path(d)
    try:
        yield name[:-3]
    finally:
        registry.remove_path(d)


def _recording(c: float, *, duration: float = 16.0, rate: float = 1000.0, seed: int = 7) -> Signals:
    """The PD position loop of ``test_issue14_judge_helpers.closed_loop_recording`` (15 Hz, gains from the nominal
    J and K) around the nominal actuator, with an unlogged load ``N c ω|ω|`` at the output (``ω`` the true rotor
    speed): the rotor feels ``c ω|ω|`` opposing its motion. Logged: q/d current with noise (0.03 A), the 14-bit
    encoder angle, its backward-difference speed, q/d voltage with noise (0.02 V)."""
    rng = np.random.default_rng(seed)
    act = Actuator(NOMINAL)
    n, dt = int(round(duration * rate)), 1.0 / rate
    J, K, N = NOMINAL.motor.rotor_inertia, NOMINAL.motor.torque_constant_q, NOMINAL.gear.gear_ratio
    wn = 2 * np.pi * 15.0
    kp, kd = J * wn ** 2 / K, 2 * 0.7 * J * wn / K
    q = 2 * np.pi / 2 ** 14
    t = np.arange(n) * dt
    ref = triangle_then_sines(t)
    dref = np.gradient(ref, dt)
    out = {k: np.zeros(n) for k in ("current_command", "current", "current_d", "position", "velocity", "voltage_q",
                                    "voltage_d")}
    prev = 0.0
    for k in range(n):
        s = act.state
        pos = round(s.theta / q) * q
        vel = (pos - prev) / dt if k else 0.0
        prev = pos
        cmd = min(15.0, max(-15.0, kp * (ref[k] - pos) + kd * (dref[k] - vel)))
        out["current_command"][k] = cmd
        out["current"][k] = s.i_q + 0.03 * rng.standard_normal()
        out["current_d"][k] = s.i_d + 0.03 * rng.standard_normal()
        out["position"][k], out["velocity"][k] = pos, vel
        out["voltage_q"][k] = s.v_q + 0.02 * rng.standard_normal()
        out["voltage_d"][k] = s.v_d + 0.02 * rng.standard_normal()
        act.set_load_torque(N * c * s.omega * abs(s.omega))
        act.set_current_command(cmd)
        act.step(dt)
    # logged as the project's writers log the kernel: the voltage it holds at each sample, declared as such
    timing = voltage_timing.from_metadata(voltage_timing.kernel_declaration(NOMINAL, dt), "plugin_recording")
    return Signals(t, out, source="synthetic", meta={"voltage_timing": timing})


def _findings(sig: Signals) -> dict:
    rep = diagnose(sig, NOMINAL, options=DiagnoseOptions(replay=False))
    return {f["effect"]: f for f in rep.to_dict()["findings"]}


def test_removing_the_path_forgets_the_effect(tmp_path):
    """Runs before the module's plug-in fixture exists: the registry forgets what it was given."""
    name, src = _example_module()
    (tmp_path / name).write_text(src)
    registry.add_path(tmp_path)
    assert registry.known(name[:-3])
    registry.remove_path(tmp_path)
    assert not registry.known(name[:-3])
    with pytest.raises(NotADirectoryError, match="effect plug-in path"):
        registry.add_path(tmp_path / "missing")


def test_the_example_is_found_by_the_registry_and_joins_the_library(plugin):
    from bldc_actuator.diagnosis.frame import candidates

    assert registry.known(plugin) and registry.forms(plugin) is not None
    assert plugin in DiagnoseOptions().validated_effects()
    cand = candidates.library()[plugin]
    assert cand.variants is not None and cand.record is registry.get(plugin)


def test_the_one_file_effect_is_named_with_its_coefficient(plugin):
    found = _findings(_recording(C_DRAG))
    assert plugin in found, sorted(found)
    f = found[plugin]
    c, sd = f["parameters"][plugin], f["uncertainty"][plugin]
    assert math.isfinite(sd) and 0 < sd < 0.2 * C_DRAG, (c, sd)
    assert abs(c - C_DRAG) <= 3.0 * sd, (c, sd)


def test_the_one_file_effect_is_not_named_without_drag(plugin):
    found = _findings(_recording(0.0))
    assert plugin not in found, found.get(plugin)
