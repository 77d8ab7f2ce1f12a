"""The complex-vector current controller's stable speed range (bldc_actuator/current_loop_stability.py) against the
kernel that runs the law (kernel.control_tick): the eigenvalues of the tick-to-tick closed-loop matrix predict the
rate at which a current deviation decays or grows in the simulated actuator, and the speed where it turns unstable;
the parameter file, the actuator and the CLI say so where the motor can outrun the loop."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from bldc_actuator import current_loop_stability as S
from bldc_actuator import params as P
from bldc_actuator.model import Actuator

#: the third-party benchmark's joint: AK80-9-like, 21 pole pairs, motulator's drive tuning (500 Hz at 10 kHz, a
#: whole period of computation delay); the bus raised so the voltage circle stays out of the way of the linear loop
JOINT = {"motor.winding": "wye", "motor.pole_pairs": 21, "motor.phase_resistance": 0.13, "motor.q_inductance": 8.0e-5,
         "motor.torque_constant_q": 0.0743, "motor.resistance_temperature_enabled": False,
         "motor.magnet_temperature_enabled": False, "drive.bus_voltage": 1000.0, "drive.current_loop_rate": 1.0e4,
         "drive.current_loop_bandwidth": 500.0, "drive.current_loop_delay": 1.0e-4, "drive.decoupling_enabled": False,
         "drive.current_controller": "complex_vector"}
T_C, P_POLES, R, L = 1.0e-4, 21, 0.13, 8.0e-5


def _deviation_rate(params: P.ActuatorParams, omega: float, ticks: int = 600) -> tuple[float, np.ndarray]:
    """Run the actuator at the prescribed constant rotor speed ``omega`` after a current step; the per-tick
    factor of the current's tick-to-tick change |i[k+1] - i[k]| (a log-linear fit over ticks 100-300, before any
    voltage limit), and those changes."""
    act = Actuator(params)
    act.prescribe_motion(omega)
    act.set_current_command(0.5)
    i, v = [], []
    for _ in range(ticks):
        act.step(T_C)
        st = act.state
        i.append(complex(st.i_d, st.i_q))
        v.append(abs(complex(st.v_d, st.v_q)))
    assert max(v[:300]) < 0.5 * 1000.0 / math.sqrt(2)     # inside the 1000 V bus's voltage circle: a linear loop
    d = np.abs(np.diff(i))
    k = np.arange(100, 300)
    return math.exp(np.polyfit(k, np.log(d[k]), 1)[0]), d


@pytest.mark.filterwarnings("ignore::bldc_actuator.params.ParameterWarning")   # the 1000 V bus: said below
@pytest.mark.parametrize("delay_fraction, feedforward, bandwidth", [(1.0, False, 500.0), (1.0, True, 500.0),
                                                                    (0.5, False, 800.0)],
                         ids=["whole-period delay", "with feed-forward", "half-period delay"])
def test_the_kernel_settles_just_inside_the_limit_and_diverges_just_outside(delay_fraction, feedforward, bandwidth):
    a, r = 2 * math.pi * bandwidth * T_C, R * T_C / L
    theta = S.angle_limit(a, r, 1.0, feedforward, delay_fraction)
    assert 0.2 < theta < 0.5                     # p w T_c: far below the PI law's ~1.2 rad
    params = P.ActuatorParams().replace(**{**JOINT, "drive.current_loop_delay": delay_fraction * T_C,
                                           "drive.decoupling_enabled": feedforward,
                                           "drive.current_loop_bandwidth": bandwidth})
    for f in (0.97, 1.03):
        omega = f * theta / (P_POLES * T_C)
        rho = float(S.spectral_radius(f * theta, a, r, 1.0, feedforward, delay_fraction))
        rate, d = _deviation_rate(params, omega)
        # the kernel's deviation decays/grows per period exactly by the predicted largest eigenvalue
        assert rate == pytest.approx(rho, rel=1e-6), (f, rate, rho)
        if f < 1:
            assert rho < 1 and d[-1] < 1e-2 * d[100]            # settles
        else:
            assert rho > 1 and d[299] > 5 * d[100] and d[-1] > 100.0   # diverges: 100 A per tick on a 0.5 A step


@pytest.mark.filterwarnings("ignore::bldc_actuator.params.ParameterWarning")
def test_without_delay_the_limit_is_far_higher_and_the_kernel_agrees():
    a, r = 2 * math.pi * 500.0 * T_C, R * T_C / L
    theta = S.angle_limit(a, r, 1.0, False, 0.0)
    assert theta > 3 * S.angle_limit(a, r)      # the delay is what costs the range
    params = P.ActuatorParams().replace(**{**JOINT, "drive.current_loop_delay": 0.0})
    rate, d = _deviation_rate(params, 0.97 * theta / (P_POLES * T_C))
    assert rate == pytest.approx(float(S.spectral_radius(0.97 * theta, a, r, 1.0, False, 0.0)), rel=1e-6)
    assert rate < 1 and d[-1] < 1e-2 * d[100]


def test_speed_limit_of_a_parameter_set_and_what_to_change():
    """The third-party joint on a 24 V bus: unstable above 0.384 rad per period = 183 rad/s while the motor runs
    up to 228 rad/s at no load; the remedies the message names each make the loop stable up to that speed."""
    params = P.ActuatorParams().replace(**{**JOINT, "drive.bus_voltage": 24.0})
    lim = P.current_loop_limit(params)
    assert lim.angle_limit == pytest.approx(0.384, abs=1e-3)
    assert lim.speed_limit == pytest.approx(lim.angle_limit / (P_POLES * T_C))
    assert lim.max_speed == pytest.approx(24.0 / math.sqrt(2) / 0.0743)
    assert not lim.stable and lim.stable_at([0.0, -150.0, 180.0]) and not lim.stable_at([-190.0])
    msg = lim.message()
    for words in ("drive.current_controller", "drive.current_loop_rate", "drive.current_loop_bandwidth",
                  f"{lim.speed_limit:.4g} rad/s", f"{lim.speed_limit_rpm:.0f} rpm", "drive.bus_voltage"):
        assert words in msg, words
    for fix in ({"drive.current_loop_rate": 1.01 * lim.rate_needed(),
                 "drive.current_loop_delay": 1.0 / (1.01 * lim.rate_needed())},
                {"drive.current_loop_bandwidth": 0.99 * lim.bandwidth_allowed()},
                {"drive.current_controller": "pi"}):
        fixed = params.replace(**fix)
        assert P.current_loop_limit(fixed) is None or P.current_loop_limit(fixed).stable, fix
    f_slow = 0.97 * lim.rate_needed()
    slower = {"drive.current_loop_rate": f_slow, "drive.current_loop_delay": 1 / f_slow}
    assert not P.current_loop_limit(params.replace(**slower)).stable
    # the PI law is not limited here; a slower bus keeps the motor inside the range
    assert P.current_loop_limit(params.replace(**{"drive.current_controller": "pi"})) is None
    assert P.current_loop_limit(params.replace(**{"drive.bus_voltage": 18.0})).stable


def test_the_user_is_warned_where_the_parameters_are_read_and_the_actuator_is_built(tmp_path, capsys):
    params = P.ActuatorParams().replace(**{**JOINT, "drive.bus_voltage": 24.0})
    assert any("complex_vector is unstable" in w for w in P.sanity_warnings(params))
    assert not any("unstable" in w for w in P.sanity_warnings(params.replace(**{"drive.bus_voltage": 18.0})))
    path = tmp_path / "joint.yaml"
    P.dump_yaml(params, path)
    with pytest.warns(P.ParameterWarning, match="complex_vector is unstable above"):
        P.load_yaml(path)
    with pytest.warns(P.ParameterWarning, match="drive.current_loop_rate >= "):
        Actuator(params)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Actuator(params.replace(**{"drive.bus_voltage": 18.0}))      # inside the range: silent
