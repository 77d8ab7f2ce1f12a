"""Issue #24, symptom 8: backlash seen from the rotor angle alone (gear 9, a 4 mrad dead zone behind the spring,
load behind it, motor encoder only) stays "not decidable" -- the load follows the dead zone through the spring's
mean stiffness, a softer spring to the rotor -- and the report says which experiment decides AND what each of the
two candidates, fitted to this recording, predicts for it: the fitted spring (no lost motion at a slow low-torque
reversal) and a dead zone behind a stiffer spring whose load follows the recorded rotor as the spring's does
(the lost motion its width), with the deflection a load encoder would read over this motion from the
simulator's load equation driven by the recorded rotor (:func:`..frame.transmission.spring_or_dead_zone`).

The recording of ``test_compliance_diagnosis.py`` (the project's simulator, a PD position loop, 1 kHz)."""

from __future__ import annotations

from bldc_actuator.diagnosis.effects import backlash, transmission_compliance
from bldc_actuator.diagnosis.pipeline import diagnose

from test_compliance_diagnosis import NOMINAL, TRUTH, reference
from test_issue14_judge_helpers import closed_loop_recording

GAP = 0.004                      # rad, output side


def test_backlash_from_the_rotor_alone_is_not_decidable_and_each_candidate_predicts_the_deciding_experiment():
    spring_name, dz_name = transmission_compliance.EFFECT.name, backlash.EFFECT.name
    truth = TRUTH.replace(**{"gear.backlash": GAP})
    rep = diagnose(closed_loop_recording(truth, NOMINAL, reference, duration=16.0, seed=5), NOMINAL)
    d = rep.to_dict()
    assert "not decidable" in d["verdict"] and dz_name in d["verdict"], d["verdict"]
    (al,) = [a for a in d["aliases"] if set(a["effects"]) == {spring_name, dz_name}]
    assert "load_position" in al["experiment"] and "What each would show" in al["experiment"]
    pred = al["predictions"]
    spring, dz = pred[spring_name], pred[dz_name]
    k_fit = d["findings"][0]["parameters"]["transmission_stiffness"]
    assert spring["stiffness"] == k_fit and spring["lost_motion"] == 0.0
    # the dead-zone candidate: a stiffer spring with a gap, fitted so that its load follows the recorded rotor
    # as the fitted spring's does -- what the rotor cannot tell apart ...
    assert dz["stiffness"] > k_fit
    assert dz["load_angle_rms_difference"] < 0.25 * spring["deflection_rms"], pred
    # ... and the deciding experiment separates them: a lost motion at the reversal of the order of the true gap
    # (recovered from the rotor alone, given the dead-zone form), none behind the spring
    assert 0.5 * GAP < dz["lost_motion"] < 1.5 * GAP, pred
    assert dz["deflection_p2p"] > 0 and spring["deflection_p2p"] > 0
