"""``diagnose_robot()``: one report for a robot — the body's findings from its MJCF, then each joint's.

1. Every recorded joint's motion at the output (:func:`.motion.joint_motion`) and the nominal body's torque on
   each joint (:meth:`.inverse.BodyModel.torques`, ``mj_inverse``).
2. Each joint's mechanical equation with that torque as its known load; the body's mass errors fitted jointly
   over all joints (:func:`.mass.fit_masses`).
3. The accepted mass changes written into the body; each joint diagnosed by :func:`..pipeline.diagnose` with the
   CORRECTED body's torque as its known load (``load_torque``), so its actuator effects (friction, K_t, ...) are
   found, judged by the joint's window replay (the body's torque from the recorded states as the replay's known
   load) and written back per joint.

Usage::

    from bldc_actuator.diagnosis.body.robot import diagnose_robot
    report = diagnose_robot({"joint1": sig1, ...}, params, "robot.xml", joint_map={"joint1": "shoulder"})
    report.body.findings, report.joints["joint1"].findings, report.to_dict()
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ...params import ActuatorParams
from ..effects import registry
from ..frame import equation_error as ee
from ..pipeline import DiagnoseOptions, diagnose
from ..report.document import DiagnosisReport
from ..threads import SingleThreadedBLAS
from .inverse import BodyModel
from .joints import JointMap
from .mass import BodyDiagnosis, fit_masses
from .motion import has_torque_sensor, joint_motion, with_load


@dataclass
class RobotReport:
    """The robot's diagnosis: the body's findings and one :class:`DiagnosisReport` per recorded joint."""

    model: str
    joint_map: JointMap
    body: BodyDiagnosis
    joints: dict[str, DiagnosisReport]
    notes: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        named = [f.sentence() for f in self.body.findings]
        per = [f"{j}: {r.verdict}" for j, r in self.joints.items()]
        return "; ".join((["body: " + "; ".join(named)] if named else ["body: nothing missing"]) + per)

    def to_dict(self) -> dict[str, Any]:
        return {"method": "robot: MJCF inverse dynamics + per-joint diagnosis", "model": self.model,
                "joint_map": self.joint_map.to_dict(), "body": self.body.to_dict(),
                "joints": {j: r.to_dict() for j, r in self.joints.items()}, "notes": list(self.notes)}

    def write_json(self, path: str | Path) -> None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(self.to_dict(), indent=2, ensure_ascii=False, default=float) + "\n")

    def write_markdown(self, directory: str | Path, *, plots: bool = True) -> Path:
        """``report.md`` for the robot (the body's findings, a line per joint) and each joint's own report in
        ``<directory>/<joint>/report.md``."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        lines = [f"# Robot diagnosis: {Path(self.model).name if self.model else 'MJCF model'}", "",
                 "Joints (recording -> MJCF): " + ", ".join(f"{a} -> {b}" for a, b in
                                                             self.joint_map.to_dict()["joints"].items()), "",
                 "## The body", ""]
        if self.body.findings:
            lines += [f"- **{f.sentence()}**" for f in self.body.findings]
        else:
            lines.append("- nothing missing in the body's mass properties")
        lines += [f"- tested, not accepted: body {f.body!r} {f.delta_mass:+.3g} kg: {f.reason}" for f in self.body.rejected]
        lines += [f"- {n}" for n in self.body.notes + self.notes]
        lines += ["", "## Joints", ""]
        for j, r in self.joints.items():
            sub = r.write_markdown(d / j, plots=plots)
            lines.append(f"### {j} ({self._model_name(j)})")
            lines.append("")
            lines.append(f"{r.verdict} ([report]({sub.relative_to(d).as_posix()}))")
            for f in r.findings:
                pars = ", ".join(f"{k}={v:.4g}" for k, v in f["parameters"].items() if isinstance(v, (int, float)))
                lines.append(f"- {f['effect']}: {pars}")
            lines.append("")
        path = d / "report.md"
        path.write_text("\n".join(lines) + "\n")
        return path

    def _model_name(self, joint: str) -> str:
        return self.joint_map.to_dict()["joints"].get(joint, joint)


def _per_joint(params, joints) -> dict[str, ActuatorParams]:
    if isinstance(params, ActuatorParams):
        return {j: params for j in joints}
    missing = [j for j in joints if j not in params]
    if missing:
        raise ValueError(f"params: no actuator parameters for joint(s) {', '.join(missing)}")
    return {j: params[j] for j in joints}


def _load_words(model_joint: str, corrected: bool) -> str:
    return (f"load_torque: the body's torque on MJCF joint {model_joint} from mujoco.mj_inverse over the recorded "
            f"motion ({'with the body findings written in' if corrected else 'the MJCF nominal'})")


def _as_joint(sig, p: ActuatorParams, tau_out, qdd, inertia_out: float, why: str):
    """The joint's recording and parameters for its own diagnosis: the body's mean inertia on the joint moves with
    the rotor (``J + M̄_jj / N²``), the rest of the body's torque (``τ_body - M̄_jj q̈``: gravity, the other joints'
    accelerations, velocity terms, the pose's change of inertia) is the known load. The mechanical equation is the
    same either way; the joint's window replay then integrates its motion on the inertia it really has, not on the
    rotor alone under a prescribed inertial torque (which no simulated speed can follow)."""
    n_gear = p.gear.gear_ratio
    p_j = p.replace(**{"motor.rotor_inertia": p.motor.rotor_inertia + inertia_out / (n_gear * n_gear)})
    return with_load(sig, tau_out - inertia_out * qdd, why + f"; less its mean inertia {inertia_out:.4g} kg*m^2 "
                     "times the joint's acceleration, which moves with the rotor"), p_j


def _rotor_inertia_back(report: DiagnosisReport, nominal: ActuatorParams, used: ActuatorParams) -> DiagnosisReport:
    """The body's share of the inertia taken back out of the joint's updated parameters and its inertia findings:
    the parameter file is the actuator's."""
    share = used.motor.rotor_inertia - nominal.motor.rotor_inertia
    if report.updated_params is not None:
        report.updated_params = report.updated_params.replace(
            **{"motor.rotor_inertia": report.updated_params.motor.rotor_inertia - share})
    report.nominal_params = nominal
    names = {p.name for e in registry.by_field("motor.rotor_inertia") for p in e.params if p.field == "motor.rotor_inertia"}
    for f in report.findings:
        for name in names & set(f.get("parameters", {})):
            if isinstance(f["parameters"][name], (int, float)):
                f["parameters"][name] -= share
    report.notes.append(f"the body's mean inertia on this joint ({share:.4g} kg*m^2 at the motor) moved with the rotor "
                        "in its equations and replays; taken back out of the written parameters")
    return report


def diagnose_robot(signals: Mapping[str, Any], params, mjcf, *, joint_map: Mapping[str, str] | None = None,
                   options: DiagnoseOptions | None = None, joints_diagnosed: bool = True) -> RobotReport:
    """Diagnose a multi-joint recording (``signals``: recorded joint name -> cleaned :class:`..signals.Signals`,
    one time base) against its MJCF ``mjcf`` (path, string or MjModel) and the actuators' nominal ``params`` (one
    :class:`ActuatorParams` for every joint, or joint -> params). ``joint_map``: recorded name -> MJCF joint name
    where they differ. ``joints_diagnosed`` False: the body's findings only."""
    options = options or DiagnoseOptions()
    names = list(signals)
    if not names:
        raise ValueError("signals: expected at least one joint's recording")
    # the body's stage too (inverse dynamics, the joint-stacked mass fits): small products, where OpenBLAS's thread
    # pool only contends on a busy machine (5x slower on 2 shared cores); each joint's diagnosis already does this
    with SingleThreadedBLAS():
        return _diagnose_robot(signals, params, mjcf, names, joint_map, options, joints_diagnosed)


def _diagnose_robot(signals, params, mjcf, names, joint_map, options: DiagnoseOptions,
                    joints_diagnosed: bool) -> RobotReport:
    ps = _per_joint(params, names)
    body = BodyModel(mjcf, names, joint_map)
    model_of = {jm.recording: jm.model for jm in body.joint_map.joints}
    motion = joint_motion(signals, ps, names, fc=options.cutoff_hz)
    tau = body.torques(motion.q, motion.qd, motion.qdd)
    notes = list(body.notes)
    for j in names:
        if has_torque_sensor(signals[j]):
            notes.append(f"joint {j}: its torque sensor (after the gear) is its equation's external torque; the body's "
                         "torque is not needed there, and the gear's losses are the motor's torque K_t i N minus the "
                         "sensor's (the joint's friction findings)")
    loaded = {j: with_load(signals[j], tau[:, k], _load_words(model_of[j], False)) for k, j in enumerate(names)}
    contexts = {j: ee.prepare([(loaded[j], False)], ps[j], fc=options.cutoff_hz, holdout=options.holdout,
                              voltage_timing=options.voltage_timing) for j in names}
    found = fit_masses(contexts, body, motion, gate=options.gate, tolerance=options.tolerance,
                       max_relative_uncertainty=options.max_relative_uncertainty, tau=tau)
    reports: dict[str, DiagnosisReport] = {}
    if joints_diagnosed:
        if found.findings:
            body = body.with_mass(found.changes)
            tau = body.torques(motion.q, motion.qd, motion.qdd)
        inertia = body.joint_inertia(motion.q)
        for k, j in enumerate(names):
            sig, p_j = _as_joint(signals[j], ps[j], tau[:, k], motion.qdd[:, k], float(inertia[k]),
                                 _load_words(model_of[j], bool(found.findings)))
            reports[j] = _rotor_inertia_back(diagnose(sig, p_j, options=options), ps[j], p_j)
    src = mjcf if isinstance(mjcf, (str, Path)) and not str(mjcf).lstrip().startswith("<") else ""
    return RobotReport(str(src), body.joint_map, found, reports, notes)


def diagnose_robot_file(path, params, mjcf, *, joint_map=None, profile=None, mapping=None,
                        options: DiagnoseOptions | None = None, joints_diagnosed: bool = True) -> RobotReport:
    """:func:`diagnose_robot` of a multi-joint file (a wide CSV profile, an ``actuator_node`` MCAP of several
    joints): every joint the file holds is loaded and cleaned (:func:`..io.loaders.joints`)."""
    from ..io import cleaning, loaders

    joints = loaders.joints(path, profile)
    if not joints:
        raise ValueError(f"{path}: a robot diagnosis (--mujoco-model) needs a file of several joints; this one holds "
                         "one actuator")
    ps = _per_joint(params, joints)
    sigs = {}
    with SingleThreadedBLAS():
        for j in joints:
            raw = loaders.load(path, mapping=mapping, params=ps[j], joint=j, profile=profile)
            sigs[j] = cleaning.clean(raw, params=ps[j])
    return diagnose_robot(sigs, ps, mjcf, joint_map=joint_map, options=options, joints_diagnosed=joints_diagnosed)
