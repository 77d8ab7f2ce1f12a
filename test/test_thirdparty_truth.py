"""The third-party concealed set's conversion of a motulator run into this project's recording (frames at the edge).

motulator scales its space vectors to the peak value (amplitude invariant); this project's ``_q`` frame is power
invariant. A converted run must keep the physics: the same electrical power ``v_d i_d + v_q i_q`` as motulator's
``(3/2) Re(u i*)``, the same torque ``K_q i_q`` as motulator's machine torque, the same d-q currents as
:func:`bldc_actuator.frames.abc_to_dq` of motulator's own phase currents, and a recording whose channels agree
with the true motion. Skips cleanly without motulator (it lives in the peers venv: bash benchmarks/peers/setup.sh).
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

motulator = pytest.importorskip("motulator")
REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.concealed import thirdparty as T  # noqa: E402
from bldc_actuator import frames  # noqa: E402


@pytest.fixture(scope="module")
def run():
    from importlib.metadata import version

    major_minor = tuple(int(x) for x in version("motulator").split(".")[:2])
    if major_minor < (0, 6):
        pytest.skip(f"motulator {version('motulator')}: the drive API used here needs >= 0.6 (Python >= 3.12)")
    case = replace(T.get_case("tp_kt"), plant={"psi_f_ratio": 1.15})
    return T.simulate(case, 0.6, seed=5)


def test_conversion_preserves_power_and_torque(run):
    par = run["par"]
    i_amp = run["mdl_i_dq"]                                    # motulator: rotor frame, peak-value scaled
    u_amp = run["mdl_u_ab"] * np.exp(-1j * run["mdl_theta_m"])
    p_motulator = 1.5 * (u_amp * np.conj(i_amp)).real
    i_q, u_q = T.to_q(i_amp), T.to_q(u_amp)
    p_ours = u_q.real * i_q.real + u_q.imag * i_q.imag
    assert np.max(np.abs(p_motulator)) > 0.05                  # the run moves: real power flows
    np.testing.assert_allclose(p_ours, p_motulator, atol=1e-12 * np.max(np.abs(p_motulator)))
    K_q = T.torque_constant_q(par["n_p"], par["psi_f"])
    assert np.max(np.abs(run["mdl_tau_M"])) > 0.02
    np.testing.assert_allclose(K_q * i_q.imag, run["mdl_tau_M"], atol=1e-12)   # L_d = L_q: no reluctance torque
    # the nominal file's K_q is motulator's psi_f of the nominal machine in this frame
    assert T.torque_constant_q(par["n_p"], T.PSI_F) == pytest.approx(T.NOMINAL_BASE["motor.torque_constant_q"],
                                                                     rel=1e-12)


def test_conversion_agrees_with_this_projects_transform_of_the_phase_currents(run):
    """The power-invariant d-q of motulator's three phase currents (bldc_actuator.frames, not the √(3/2) factor)."""
    from motulator.common.utils import complex2abc

    i_ab = run["mdl_i_dq"] * np.exp(1j * run["mdl_theta_m"])    # stationary frame, peak-value scaled
    a, b, c = (np.array(x) for x in zip(*[complex2abc(z) for z in i_ab]))
    d, q = frames.abc_to_dq(a, b, c, run["mdl_theta_m"])
    np.testing.assert_allclose(d + 1j * q, T.to_q(run["mdl_i_dq"]), atol=1e-12)


def test_recording_channels_follow_the_true_motion(run):
    """Logged at 10 kHz (every control sample), no noise: the encoder angle's derivative is the measured speed,
    K_q i_q - J dω/dt (logged current, true K and J) equals motulator's total load torque (1 %), and the shaft
    sensor (between the motor with its drag and the external load) reads the external load."""
    rec = T.to_recording(run, rate=10000.0, seed=0, torque_sensor=True, noise=False)
    t = rec["time"]
    assert np.allclose(np.diff(t), 1e-4, atol=1e-9)
    w_from_pos = np.gradient(rec["position"], t)
    assert np.sqrt(np.mean((w_from_pos[2:-2] - rec["velocity"][2:-2]) ** 2)) < 0.01 * np.max(np.abs(rec["velocity"]))
    K, J = run["par"]["psi_f"] * run["par"]["n_p"] * math.sqrt(1.5), run["par"]["J"]
    drive = K * rec["current"]
    lhs = drive - J * np.gradient(rec["true_omega"], t)
    err = np.sqrt(np.mean((lhs[5:-5] - run["tau_L"][5:-5]) ** 2))
    assert err < 0.01 * np.sqrt(np.mean(drive ** 2)), err
    np.testing.assert_allclose(rec["torque"], run["tau_ext"])


def test_motulators_current_controller_has_no_back_emf_feed_forward():
    """The drive's truth behind ``drive.decoupling_enabled: false``: motulator's CurrentVectorController (the one the
    set uses) outputs nothing at zero current error whatever the speed (no feed-forward term), and held at a
    constant speed with zero current its complex-vector integrator settles to the back-EMF j ω ψ_f: the integrator
    carries it. Its output is driven through the machine's rotor-frame voltage equation (Euler, 100 µs)."""
    from motulator.drive import model
    import motulator.drive.control.sm as sm

    D = T.simulation_spec(T.get_case("tp_null"))["drive"]
    par = model.SynchronousMachinePars(n_p=D["n_p"], R_s=D["R_s"], L_d=D["L_d"], L_q=D["L_q"], psi_f=D["psi_f"])
    cfg = sm.CurrentVectorControllerCfg(i_s_max=D["i_max_q"] / math.sqrt(1.5),
                                        alpha_c=2 * math.pi * D["alpha_c_hz"], T_s=T.T_S, sensorless=False)
    cc = sm.CurrentVectorController(par, cfg).current_ctrl
    w_e = D["n_p"] * 20.0                                        # 20 rad/s mechanical
    back_emf = 1j * w_e * par.psi_f                              # 1.2 V (amplitude invariant)
    assert cc.compute_output(0j, 0j) == 0j                       # at speed, no error: no voltage at all
    i, first = 0j, None
    for k in range(400):                                         # 40 ms at zero current reference
        u = cc.compute_output(0j, i)
        cc.update(T.T_S, u, w_e)
        i += T.T_S * (u - par.R_s * i - 1j * w_e * (par.L_d * i + par.psi_f)) / par.L_d
        first = i if k == 0 else first
    assert abs(first) > 0.5 * abs(back_emf) * T.T_S / par.L_d    # the back-EMF drives the first step's current
    assert abs(cc.u_i - back_emf) < 0.01 * abs(back_emf)         # the integrator carries the back-EMF
    assert abs(i) < 1e-3
