"""``bldc-actuator export-mujoco``: the closest MuJoCo ``<dcmotor>`` for a parameter file, and where it departs.

MuJoCo's ``<dcmotor>`` (4.0) is a brushed-DC equivalent: ``v = (R/K) τ_ff + K l̇`` clamped to a scalar ``Vmax``,
``L di/dt = v - R i - K l̇``, torque ``K i`` clamped to ``K I_max``, a one-node thermal model that raises R. The
closest one for a PMSM actuator of this project (power-invariant q-axis values, motor side; ``gear`` = N):

* ``resistance`` = R (phase, wye-equivalent), ``motorconst`` = K_t_q K_t_q, ``inductance`` = L_q;
* ``input="ff"``: the control is the motor-side torque τ_out/N (the current-controlled drive's torque command);
  ``controller`` Vmax = the radius of the inverter's voltage circle (``frames.voltage_limit_q`` × modulation);
* ``saturation`` current = ``drive.current_limit``;
* ``thermal``: one node, R_th = R_wh + R_ha (the same steady state), C = C_w (the same initial rate), the copper
  coefficient, reference and ambient temperatures;
* on the joint: ``armature`` = J N², ``damping`` = (b + c_e) N², ``frictionloss`` = (τ_c + τ_h) N.

What it cannot carry (shown by :func:`compare`): the voltage CIRCLE (at speed the d-axis voltage ``-p ω L i_q``
takes part of |v| ≤ V_max, the scalar clamp ignores it), the discrete PI current loop and its bandwidth, the
two-node network and the drive's derating and trip, Stribeck/asymmetric friction, the gear's load-independent
terms only.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import frames
from ..params import ActuatorParams, load_preset


@dataclass(frozen=True)
class DcMotorEquivalent:
    """The ``<dcmotor>`` numbers (motor side unless ``_out``) and the joint's (output side)."""

    resistance: float          #: R [Ω]
    motorconst: float          #: K_t = K_e [N·m/A]
    inductance: float          #: L [H]
    v_max: float               #: controller Vmax [V]: the voltage circle's radius
    current_max: float         #: saturation current [A]
    gear: float                #: N
    thermal_resistance: float  #: R_th [K/W]
    thermal_capacitance: float  #: C [J/K]
    tempcoef: float            #: copper coefficient [1/K] (0 when R(T) is off)
    reftemp: float             #: [°C]
    ambient: float             #: [°C]
    armature_out: float        #: joint armature [kg·m²]
    damping_out: float         #: joint damping [N·m·s/rad]
    frictionloss_out: float    #: joint dry friction [N·m]


def dcmotor_equivalent(params: ActuatorParams) -> DcMotorEquivalent:
    m, d, th, e, N = params.motor, params.drive, params.thermal, params.effects, params.gear.gear_ratio
    return DcMotorEquivalent(
        resistance=m.phase_resistance, motorconst=m.torque_constant_q, inductance=m.q_inductance,
        v_max=frames.voltage_limit_q(d.bus_voltage, m.winding) * d.modulation_limit, current_max=d.current_limit,
        gear=N, thermal_resistance=th.winding_to_housing_resistance + th.housing_to_ambient_resistance,
        thermal_capacitance=th.winding_heat_capacity,
        tempcoef=m.copper_temperature_coefficient if m.resistance_temperature_enabled else 0.0,
        reftemp=m.reference_temperature, ambient=th.ambient_temperature,
        armature_out=m.rotor_inertia * N * N, damping_out=(m.viscous_damping + e.iron_loss_eddy) * N * N,
        frictionloss_out=(e.coulomb_friction + e.iron_loss_hysteresis) * N)


def _g(x: float) -> str:
    return f"{x:.6g}"


def dcmotor_xml(eq: DcMotorEquivalent, joint: str = "joint", name: str | None = None) -> str:
    """The ``<dcmotor>`` element (control: the motor-side torque, ``ctrl = τ_out / gear``)."""
    return (f'<dcmotor name="{name or joint + "_motor"}" joint="{joint}" gear="{_g(eq.gear)}" input="ff" '
            f'resistance="{_g(eq.resistance)}" motorconst="{_g(eq.motorconst)} {_g(eq.motorconst)}" '
            f'inductance="{_g(eq.inductance)} 0" controller="0 0 0 0 0 {_g(eq.v_max)}" '
            f'saturation="0 {_g(eq.current_max)} 0" thermal="{_g(eq.thermal_resistance)} '
            f'{_g(eq.thermal_capacitance)} 0 {_g(eq.tempcoef)} {_g(eq.reftemp)} {_g(eq.ambient)}"/>')


def joint_attributes(eq: DcMotorEquivalent) -> str:
    return (f'armature="{_g(eq.armature_out)}" damping="{_g(eq.damping_out)}" '
            f'frictionloss="{_g(eq.frictionloss_out)}"')


def mjcf_fragment(eq: DcMotorEquivalent, joint: str = "joint", source: str = "") -> str:
    """An MJCF file to include: a default class for the joint and the actuator."""
    return f"""<!-- closest MuJoCo <dcmotor> for {source or 'an actuator parameter set'} (bldc-actuator export-mujoco).
     ctrl = output torque / gear [N*m]. Not representable: the voltage circle (a scalar Vmax here), the PI
     current loop, the two-node thermal network with derating and trip, Stribeck/asymmetric friction. -->
<mujoco>
  <default>
    <default class="{joint}_actuator">
      <joint {joint_attributes(eq)}/>
    </default>
  </default>
  <actuator>
    {dcmotor_xml(eq, joint)}
  </actuator>
</mujoco>
"""


# -- side-by-side run ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ProfileSpec:
    """The command profile of :func:`compare`: a moderate torque step the speed runs into the voltage limit
    with, then the full torque against a load, long enough to heat the winding."""

    tau_step_out: float = 5.0        #: first command [N·m]
    t_high: float = 0.5              #: when the second starts [s]
    tau_high_out: float | None = None  #: second command [N·m] (default: the current limit's torque)
    load_fraction: float = 0.9       #: load from t_high on, as a fraction of tau_high_out
    duration: float = 150.0          #: [s]
    inertia_out: float = 0.01        #: the flywheel's own inertia [kg·m²]


@dataclass(frozen=True)
class Comparison:
    """Both runs on the same body and profile, sampled every ``1/rate`` s, and the figures that differ."""

    t: np.ndarray
    command_out: np.ndarray
    speed_out: dict             #: model name -> [rad/s]
    torque_out: dict            #: model name -> torque applied to the joint [N·m]
    T_winding: dict             #: model name -> [°C]
    figures: dict               #: name -> (this model, dcmotor, unit)


def _flywheel_xml(spec: ProfileSpec, h: float, actuator: str = "") -> str:
    return f"""<mujoco><option timestep="{h}" gravity="0 0 0"/><worldbody><body name="disc">
    <joint name="joint" type="hinge" axis="0 0 1"/><inertial pos="0 0 0" mass="1"
    diaginertia="{spec.inertia_out} {spec.inertia_out} {spec.inertia_out}"/></body></worldbody>{actuator}</mujoco>"""


def compare(params: ActuatorParams, spec: ProfileSpec = ProfileSpec(), *, h: float = 1e-3,
            record_every: int = 10) -> Comparison:
    """Run this model (:class:`CoupledSim`) and the exported ``<dcmotor>`` on the same flywheel and profile."""
    import mujoco

    from .coupling import CoupledSim

    eq = dcmotor_equivalent(params)
    tau_high = spec.tau_high_out if spec.tau_high_out is not None else (
        params.drive.current_limit * params.motor.torque_constant_q * eq.gear)
    n = int(round(spec.duration / h))
    n_fine = int(round(1.5 / h))         # every step for the first 1.5 s (current loop, voltage limit)

    def profile(t):
        return (spec.tau_step_out, 0.0) if t < spec.t_high else (tau_high, spec.load_fraction * tau_high)

    # this model
    sim = CoupledSim(_flywheel_xml(spec, h), {"joint": params})
    rec = {"t": [], "cmd": [], "w": [], "tau": [], "T": [], "ilim": [], "w_dc": [], "tau_dc": [], "T_dc": []}
    for k in range(n):
        cmd, load = profile(sim.t)
        sim.set_torque_command("joint", cmd)
        sim.set_load_torque("joint", load)
        sim.step(h)
        if k < n_fine or k % record_every == 0:
            js = sim.joint_state("joint")
            rec["t"].append(sim.t)
            rec["cmd"].append(cmd)
            rec["w"].append(js.velocity)
            rec["tau"].append(js.effort)
            rec["T"].append(js.outputs["T_winding"])
            rec["ilim"].append(js.outputs["current_limit_effective"])
    # the dcmotor, on a body with the same joint mechanics
    xml = _flywheel_xml(spec, h, f"<actuator>{dcmotor_xml(eq, 'joint')}</actuator>").replace(
        'type="hinge" axis="0 0 1"', f'type="hinge" axis="0 0 1" {joint_attributes(eq)}')
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for k in range(n):
        t = k * h
        cmd, load = profile(t)
        data.ctrl[0] = cmd / eq.gear
        data.qfrc_applied[0] = -load
        mujoco.mj_step(model, data)
        if k < n_fine or k % record_every == 0:
            rec["w_dc"].append(float(data.qvel[0]))
            rec["tau_dc"].append(float(data.qfrc_actuator[0]))
            rec["T_dc"].append(eq.ambient + float(data.act[0]))   # its activation 0: temperature above ambient
    a = {key: np.array(val) for key, val in rec.items()}
    t = a["t"]
    first = t < spec.t_high

    last_first = np.nonzero(first)[0][-1]
    loaded = np.nonzero(t >= spec.t_high + 0.5)[0][0]
    derate = np.nonzero(a["ilim"] < params.drive.current_limit * (1.0 - 1e-9))[0]
    t_derate = float(t[derate[0]]) if len(derate) else math.nan
    figures = {
        "torque, mean over the first body step (1 ms)": (a["tau"][0], a["tau_dc"][0], "N*m"),
        f"voltage-limited speed at {spec.tau_step_out:g} N*m, no load": (a["w"][last_first], a["w_dc"][last_first],
                                                                        "rad/s"),
        f"speed under the {spec.load_fraction * tau_high:.3g} N*m load, 0.5 s on": (a["w"][loaded], a["w_dc"][loaded],
                                                                                   "rad/s"),
        "speed at the end": (a["w"][-1], a["w_dc"][-1], "rad/s"),
        "applied torque at the end": (a["tau"][-1], a["tau_dc"][-1], "N*m"),
        "winding temperature at the end": (a["T"][-1], a["T_dc"][-1], "degC"),
        "current limit derated from (no derating in dcmotor)": (t_derate, math.nan, "s"),
    }
    return Comparison(t=t, command_out=a["cmd"], speed_out={"bldc_actuator": a["w"], "dcmotor": a["w_dc"]},
                      torque_out={"bldc_actuator": a["tau"], "dcmotor": a["tau_dc"]},
                      T_winding={"bldc_actuator": a["T"], "dcmotor": a["T_dc"]}, figures=figures)


def figures_table(cmp: Comparison) -> str:
    lines = ["| figure | this model | MuJoCo dcmotor | unit |", "|---|---|---|---|"]
    for name, (ours, theirs, unit) in cmp.figures.items():
        lines.append(f"| {name} | {ours:.4g} | {theirs:.4g} | {unit} |")
    return "\n".join(lines)


def plot(cmp: Comparison, path: str | Path, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex="col")
    zoom = cmp.t <= 1.5
    for col, sel in enumerate((zoom, np.ones_like(zoom))):
        ax = axes[0, col]
        ax.plot(cmp.t[sel], cmp.command_out[sel], "k:", label="command")
        for key, style in (("bldc_actuator", "C0-"), ("dcmotor", "C3--")):
            ax.plot(cmp.t[sel], cmp.torque_out[key][sel], style, label=key)
            axes[1, col].plot(cmp.t[sel], cmp.speed_out[key][sel], style, label=key)
            axes[2, col].plot(cmp.t[sel], cmp.T_winding[key][sel], style, label=key)
        ax.set_ylabel("torque at the joint [N·m]")
        axes[1, col].set_ylabel("speed [rad/s]")
        axes[2, col].set_ylabel("winding [°C]")
        axes[2, col].set_xlabel("t [s]")
    axes[0, 0].set_title("first 1.5 s: current loop, voltage limit")
    axes[0, 1].set_title("whole run: heating, derating")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title or "this model vs MuJoCo <dcmotor>, same body and command")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- CLI --------------------------------------------------------------------------------------------------------

def register(sub) -> None:
    p = sub.add_parser("export-mujoco", help="the closest MuJoCo <dcmotor> for a parameter file, and a "
                       "side-by-side run showing where it departs",
                       description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", required=True, help="parameter file (YAML) or preset name")
    p.add_argument("--joint", default="joint", help="the MJCF joint name the actuator drives (default: joint)")
    p.add_argument("-o", "--output", help="write the MJCF fragment here (default: print it)")
    p.add_argument("--compare", action="store_true", help="run both on a flywheel and print the figures")
    p.add_argument("--duration", type=float, default=150.0, help="length of the side-by-side run [s]")
    p.add_argument("--plot", help="PNG of the side-by-side run (implies --compare)")
    p.set_defaults(func=_main)


def _main(args) -> int:
    params = load_preset(args.params)
    eq = dcmotor_equivalent(params)
    text = mjcf_fragment(eq, args.joint, source=Path(args.params).name)
    if args.output:
        Path(args.output).write_text(text)
        print(f"export-mujoco: wrote {args.output}")
    else:
        print(text)
    if args.compare or args.plot:
        if not (args.duration > 0.5 and math.isfinite(args.duration)):
            raise SystemExit(f"--duration: expected more than 0.5 s, got {args.duration}")
        cmp = compare(params, ProfileSpec(duration=args.duration))
        print(figures_table(cmp))
        if args.plot:
            plot(cmp, args.plot, title=f"{Path(args.params).name}: this model vs MuJoCo <dcmotor>")
            print(f"export-mujoco: wrote {args.plot}")
    return 0
