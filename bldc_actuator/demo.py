"""``bldc-actuator demo``: the ROS 2 node on a motor preset, driven by a built-in command profile from an
in-process "controller" node in the same executor, recording an MCAP, then a summary and a plot.

What runs: :class:`~bldc_actuator.node.ActuatorNode` (lock-step by default: one 1 ms control period per
command, so command timing is exact and the run is reproducible) and :class:`ProfilePlayer`, which answers
every ``joint_states`` message with the profile's command for that simulation time — exactly how an
external controller connects. ``--time-factor F`` runs the node free instead (F x real time, 0 = as fast
as possible) with the player publishing on command changes.

Profile (output side; torques scaled to the motor's current limit): torque step to +tau_a (the rotor
runs up to the voltage-limited speed), reversal to -tau_a, coast, a chirp, +tau_a again, then a load
step of tau_a/2 at the output. Outputs: ``out/demo.mcap``, ``out/demo.png``, a printed summary.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

from . import effects, frames
from .params import ActuatorParams, ParameterError, load_preset
from .profiles import Profile

DURATION = 4.0          #: simulated seconds
RATE = 1000.0           #: profile samples per second = node publish rate
#: (start, end) of the windows where the steady speed is measured [s]
STEADY_NO_LOAD = (0.70, 0.95)
STEADY_LOAD = (3.75, 3.98)


def demo_profile(params: ActuatorParams, duration: float = DURATION, rate: float = RATE) -> Profile:
    """Torque steps + chirp + load step at the OUTPUT [N*m], scaled to the drive's current limit."""
    from scipy.signal import chirp

    tau_max = params.drive.current_limit * params.motor.torque_constant_q * params.gear.gear_ratio
    tau_a = 0.25 * tau_max
    t = np.arange(int(round(duration * rate)) + 1) / rate
    cmd = np.zeros_like(t)
    cmd[(t >= 0.05) & (t < 1.0)] = tau_a
    cmd[(t >= 1.0) & (t < 1.6)] = -tau_a
    ch = (t >= 1.8) & (t < 2.8)
    cmd[ch] = tau_a * chirp(t[ch] - 1.8, 2.0, 1.0, 40.0, method="linear", phi=-90)
    cmd[t >= 2.8] = tau_a
    load = np.where(t >= 3.4, 0.5 * tau_a, 0.0)
    return Profile(t, cmd, "torque", load, name="demo: torque steps, chirp 2-40 Hz, load step",
                   meta={"tau_a": tau_a, "load": 0.5 * tau_a})


def steady_speed_analytic(params: ActuatorParams, T_winding: float, T_housing: float,
                          tau_load_out: float = 0.0, i_q_ref: float | None = None) -> tuple[float, float]:
    """Voltage-limited steady state of the model equations: ``(output speed [rad/s], i_d [A])``.

    Motor side, constant speed w and constant d/q currents (L di/dt = 0)::

        v_d = R i_d - p w L i_q,   v_q = R i_q + p w L i_d + K w,   |v| = V_max (SVPWM limit)
        K i_q = b w + tau_f(w) + tau_load/N                                  (torque balance)
        (0 - i_d, i_q_ref - i_q) parallel to (v_d, v_q)                       (saturated PI at rest:
                                                the anti-windup keeps the error along the voltage)

    R at the winding temperature, K at the housing (magnet) temperature. For a given w the last line is a
    quadratic in i_d (small root); |v(w)| = V_max is solved for w by bracketing. ``i_q_ref`` defaults to the
    current limit (a command the drive cannot meet: the speed is voltage-limited). The parallel condition is the
    proportional limiter's (``drive.voltage_limit_mode: proportional``, every preset's); the other modes' steady
    states are solved in test/test_voltage_limit.py, and asking for one here is an error naming the field.
    """
    from scipy.optimize import brentq

    if params.drive.voltage_limit_mode != "proportional":
        raise ValueError(f"drive.voltage_limit_mode: steady_speed_analytic solves the proportional limiter only, "
                         f"got {params.drive.voltage_limit_mode!r}")

    m, e = params.motor, params.effects
    R = effects.resistance_at(m.phase_resistance, T_winding, m.reference_temperature,
                              m.copper_temperature_coefficient, m.resistance_temperature_enabled)
    K = m.torque_constant_q * effects.flux_factor(T_housing, m.reference_temperature,
                                                  m.magnet_temperature_coefficient, m.magnet_temperature_enabled)
    V = frames.voltage_limit_q(params.drive.bus_voltage, m.winding)
    N, L, p, b = params.gear.gear_ratio, m.q_inductance, m.pole_pairs, m.viscous_damping
    i_ref = params.drive.current_limit if i_q_ref is None else i_q_ref

    def residual(w):
        tau_f = effects.friction_magnitude(1.0, w, e.coulomb_friction, e.friction_asymmetry,
                                           e.stribeck_friction, e.stribeck_velocity)
        i_q = (b * w + tau_f + tau_load_out / N) / K
        err = i_ref - i_q
        a2, a1, a0 = -p * w * L, -(R * i_q + K * w + err * R), err * p * w * L * i_q
        if a2 == 0.0:
            i_d = -a0 / a1
        else:
            disc = math.sqrt(a1 * a1 - 4.0 * a2 * a0)
            i_d = min(((-a1 + disc) / (2 * a2), (-a1 - disc) / (2 * a2)), key=abs)
        v_d, v_q = R * i_d - p * w * L * i_q, R * i_q + p * w * L * i_d + K * w
        return math.hypot(v_d, v_q) - V, i_d

    w = brentq(lambda w: residual(w)[0], 1e-9, 1.01 * V / K, xtol=1e-13, rtol=1e-14)
    return w / N, residual(w)[1]


# -------------------------------------------------------------------------------------------- ROS part

def _executor(context):
    """EventsExecutor when this rclpy has it (about 4x faster lock-step round trips), else single-threaded."""
    try:
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    except Exception:  # noqa: BLE001 - older rclpy
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)


def make_player(profile: Profile, actuator_prefix: str, joint_states: str, *, every_state: bool, context=None):
    """A node that plays ``profile`` into the actuator: on each ``joint_states`` (simulation time t) it
    publishes the command for t (every state in lock-step, else on change) and the load torque on change.
    ``player.done`` completes when t reaches the end of the profile."""
    from rclpy.clock import Clock, ClockType
    from rclpy.node import Node
    from rclpy.task import Future
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    class ProfilePlayer(Node):
        def __init__(self):
            super().__init__("demo_profile_player", context=context)
            self.t_ns = np.round(profile.t * 1e9).astype(np.int64)
            self.end_ns = int(self.t_ns[-1])
            self.pub_cmd = self.create_publisher(Float64, f"{actuator_prefix}/{profile.kind}_command", 100)
            self.pub_load = self.create_publisher(Float64, f"{actuator_prefix}/load_torque", 100)
            self.sub = self.create_subscription(JointState, joint_states, self.on_state, 100)
            self.done = Future()
            self.last_t = -1
            self.last_cmd = None
            self.last_load = None
            self.sent = 0
            self._progress = (time.monotonic(), -1)
            self.create_timer(0.5, self._watch, clock=Clock(clock_type=ClockType.STEADY_TIME))

        def ready(self, actuator_node) -> bool:
            return (self.pub_cmd.get_subscription_count() > 0 and self.pub_load.get_subscription_count() > 0
                    and actuator_node.pub_joint.get_subscription_count() > 0)

        def start(self) -> None:
            self.last_t = 0                 # the state at t = 0 is answered here, not again in on_state
            self.send(0)

        def send(self, t: int) -> None:
            k = int(np.searchsorted(self.t_ns, t, side="right") - 1)
            if profile.load_torque is not None:
                load = float(profile.load_torque[k])
                if load != self.last_load:
                    self.pub_load.publish(Float64(data=load))
                    self.last_load = load
            cmd = float(profile.values[k])
            if every_state or cmd != self.last_cmd:
                self.pub_cmd.publish(Float64(data=cmd))
                self.last_cmd = cmd
                self.sent += 1

        def on_state(self, msg: JointState) -> None:
            t = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if t <= self.last_t or self.done.done():
                return                      # stale (free-running bursts) or finished
            self.last_t = t
            if t >= self.end_ns:
                self.done.set_result(t)
                return
            self.send(t)

        def _watch(self) -> None:           # lock-step safety net: a lost message must not stall the loop
            now = time.monotonic()
            stalled = self.last_t == self._progress[1] and now - self._progress[0] > 1.0
            if stalled and every_state and not self.done.done():
                self.get_logger().warning("no joint_states for 1 s: re-sending the command")
                self.send(max(self.last_t, 0))
                self._progress = (now, self.last_t)
            elif self.last_t != self._progress[1]:
                self._progress = (now, self.last_t)

    return ProfilePlayer()


@contextlib.contextmanager
def _ctrl_c_outside_callbacks():
    """Ctrl-C sets a flag the spin loop polls (a KeyboardInterrupt inside a callback would be logged as a
    crash by the executor); on leaving, KeyboardInterrupt is raised if it was pressed."""
    hit = [False]
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return

    def handler(signum, frame):
        if hit[0]:
            raise KeyboardInterrupt     # second Ctrl-C: at once
        hit[0] = True

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: hit[0]
    finally:
        signal.signal(signal.SIGINT, previous)
    if hit[0]:
        raise KeyboardInterrupt


def run_demo(params_preset: str | None, out_dir: Path, *, time_factor: float | None = None,
             plot: bool = True, duration: float = DURATION, quiet: bool = False,
             domain_id: int | None = None) -> dict:
    """Run the demo; return the summary dict (also printed unless ``quiet``). ``duration`` below 4 s
    cuts the profile (the load-step window then has no data)."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from .node import ActuatorNode

    base = load_preset(params_preset) if params_preset else ActuatorParams()
    profile = demo_profile(base, duration)
    out_dir.mkdir(parents=True, exist_ok=True)
    mcap_path = out_dir / "demo.mcap"
    lock_step = time_factor is None
    overrides = [Parameter("node.record", value=str(mcap_path)), Parameter("node.lock_step", value=lock_step),
                 Parameter("node.publish_rate", value=RATE), Parameter("node.watchdog_timeout", value=0.0),
                 Parameter("node.joint_name", value="demo_joint")]
    if params_preset:
        overrides.append(Parameter("preset", value=str(params_preset)))
    if not lock_step:
        overrides.append(Parameter("node.time_factor", value=float(time_factor)))
        overrides.append(Parameter("node.max_sim_time", value=duration + 0.01))
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = player = None
    executor = _executor(context)
    wall0 = time.perf_counter()
    try:
        node = ActuatorNode(context=context, parameter_overrides=overrides, start=False)
        player = make_player(profile, "/bldc_actuator", node.pub_joint.topic_name, every_state=lock_step,
                             context=context)
        executor.add_node(node)
        executor.add_node(player)
        deadline = time.monotonic() + 20.0
        while not player.ready(node):
            executor.spin_once(timeout_sec=0.01)
            if time.monotonic() > deadline:
                raise RuntimeError("demo: the profile player and the node did not discover each other in 20 s")
        wall0 = time.perf_counter()
        node.start()                     # publishes the state at t = 0 (and starts the timer unless lock-step)
        player.start()                   # the first command; in lock-step it starts the loop
        with _ctrl_c_outside_callbacks() as interrupted:
            deadline = time.monotonic() + 120.0
            while not player.done.done() and not interrupted() and time.monotonic() < deadline:
                executor.spin_until_future_complete(player.done, timeout_sec=0.2)
        if not player.done.done():
            raise RuntimeError("demo: the profile did not finish within 120 s wall")
    finally:
        wall = time.perf_counter() - wall0
        if node is not None:
            node.close()
        for n in (player, node):
            if n is not None:
                executor.remove_node(n)
                n.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=context)
    from .recording import read_recording

    rec = read_recording(mcap_path)
    summary = summarize_demo(rec, profile, wall, lock_step, time_factor, params_preset)
    if plot:
        summary["plot"] = str(plot_demo(rec, profile, summary, out_dir / "demo.png"))
    if not quiet:
        print_summary(summary)
    return summary


# ------------------------------------------------------------------------------------- summary / plot

def _series(rec):
    """Arrays from the recording: t [s] and the signals the summary and plot use."""
    from .node import Q_AXIS_FIELDS

    ns = "/bldc_actuator/"
    js = rec.topics["/joint_states"]
    q = rec.topics[ns + "q_axis_state"]
    qi = {k: i for i, k in enumerate(Q_AXIS_FIELDS)}
    s = {
        "t": np.array([t for t, _ in js]) * 1e-9,
        "position": np.array([m.position[0] for _, m in js]),
        "velocity": np.array([m.velocity[0] for _, m in js]),
        "effort": np.array([m.effort[0] for _, m in js]),
        "t_q": np.array([t for t, _ in q]) * 1e-9,
        "T_w": np.array([m.temperature for _, m in rec.topics[ns + "winding_temperature"]]),
        "T_h": np.array([m.temperature for _, m in rec.topics[ns + "housing_temperature"]]),
    }
    for k in Q_AXIS_FIELDS:
        s[k] = np.array([m.data[qi[k]] for _, m in q])
    return s


def summarize_demo(rec, profile: Profile, wall: float, lock_step: bool, time_factor, preset) -> dict:
    """Summary of a demo recording (a :class:`bldc_actuator.recording.Recording`)."""
    from .recording import as_level, summarize
    from .replay import resimulate

    path = rec.path
    info = summarize(path)
    params = rec.params()
    s = _series(rec)
    t = s["t"]
    tau_load = profile.meta["load"]

    def window(w):
        m = (t >= w[0]) & (t <= w[1])
        return float(s["velocity"][m][-1]), float(np.ptp(s["velocity"][m])), m

    v0, ripple0, m0 = window(STEADY_NO_LOAD)
    v1, ripple1, m1 = window(STEADY_LOAD)
    i_ref = profile.meta["tau_a"] / (params.motor.torque_constant_q * params.gear.gear_ratio)
    est0 = est1 = float("nan")     # the analytic check solves the proportional limiter (every preset's)
    if params.drive.voltage_limit_mode == "proportional":
        est0, _ = steady_speed_analytic(params, float(s["T_w"][m0][-1]), float(s["T_h"][m0][-1]), 0.0, i_ref)
        est1, _ = steady_speed_analytic(params, float(s["T_w"][m1][-1]), float(s["T_h"][m1][-1]), tau_load, i_ref)
    dt = float(np.median(np.diff(s["t_q"]))) if len(s["t_q"]) > 1 else 0.0

    def saturated(w):
        return float(np.mean(s["voltage_saturated"][(s["t_q"] >= w[0]) & (s["t_q"] <= w[1])]))

    replayed = resimulate(rec)
    dv = max(abs(o["velocity_out"] - m.velocity[0]) for (_, o), (_, m) in zip(replayed, rec.topics["/joint_states"]))
    levels = [as_level(st.level) for _, a in rec.topics["/diagnostics"] for st in a.status]
    sim = float(t[-1] - t[0])
    return {
        "preset": preset or "built-in defaults",
        "mode": "lock-step (1 period per command)" if lock_step else
                f"free-running, time_factor {time_factor:g}" + (" (as fast as possible)" if not time_factor or
                                                                math.isinf(time_factor) else ""),
        "sim_s": sim, "wall_s": wall, "real_time_factor": sim / wall if wall > 0 else math.inf,
        "recording": str(path), "file_size": info["file_size"], "finalized": info["finalized"],
        "message_count": info["message_count"],
        "topics": {k: (v["type"], v["count"], v["rate_hz"]) for k, v in info["topics"].items()},
        "gear_ratio": params.gear.gear_ratio, "tau_a": profile.meta["tau_a"], "tau_load": tau_load,
        "steady_no_load": (v0, est0, ripple0, saturated(STEADY_NO_LOAD)),
        "steady_load": (v1, est1, ripple1, saturated(STEADY_LOAD)),
        "peak_T_winding": float(np.max(s["T_w"])), "peak_T_housing": float(np.max(s["T_h"])),
        "start_T_winding": float(s["T_w"][0]),
        "saturation_s": float(np.sum(s["voltage_saturated"][1:]) * dt),
        "peak_i_q": float(np.max(np.abs(s["i_q"]))),
        "current_limit": params.drive.current_limit,
        "diagnostics_levels": {lv: levels.count(lv) for lv in sorted(set(levels))},
        "replay_max_dv": dv, "replay_states": len(replayed),
    }


def print_summary(s: dict) -> None:
    out = sys.stdout.write
    out(f"bldc-actuator demo: {s['preset']}, {s['mode']}\n")
    out(f"  simulated {s['sim_s']:.3f} s in {s['wall_s']:.2f} s wall ({s['real_time_factor']:.1f}x real time)\n")
    out(f"  recording {s['recording']}: {s['file_size'] / 1e6:.2f} MB, {s['message_count']} messages, "
        f"{'finalized' if s['finalized'] else 'NOT finalized'}\n")
    out("  topics:\n")
    for topic, (typ, count, rate) in s["topics"].items():
        out(f"    {topic:<40} {typ:<34} {count:>6}" + (f"  {rate:8.1f} Hz\n" if rate else "\n"))
    v0, e0, r0, sat0 = s["steady_no_load"]
    v1, e1, r1, sat1 = s["steady_load"]
    out("  physics (output side):\n")
    out(f"    torque steps +-{s['tau_a']:.3f} N*m (25 % of the current limit), "
        f"load step {s['tau_load']:.3f} N*m at 3.4 s\n")
    out(f"    steady speed, no load (at {STEADY_NO_LOAD[1]} s): {v0:.6f} rad/s; analytic voltage-limited steady "
        f"state {e0:.6f} rad/s ({(v0 / e0 - 1) * 100:+.2g} %; window ripple {r0:.2g} rad/s, saturated {sat0:.0%})\n")
    out(f"    steady speed, load {s['tau_load']:.3f} N*m (at {STEADY_LOAD[1]} s): {v1:.6f} rad/s; analytic "
        f"{e1:.6f} rad/s ({(v1 / e1 - 1) * 100:+.2g} %; ripple {r1:.2g} rad/s, saturated {sat1:.0%})\n")
    out(f"    peak winding temperature {s['peak_T_winding']:.2f} degC (start {s['start_T_winding']:.2f}); "
        f"housing {s['peak_T_housing']:.2f} degC\n")
    out(f"    voltage saturation {s['saturation_s']:.3f} s of {s['sim_s']:.3f} s "
        f"({s['saturation_s'] / s['sim_s']:.0%}); peak |i_q| {s['peak_i_q']:.2f} A (limit {s['current_limit']:g} A)\n")
    names = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
    out("    diagnostics: " + ", ".join(f"{names.get(k, k)} x{v}" for k, v in s["diagnostics_levels"].items()) + "\n")
    out(f"  re-simulated from the MCAP alone: max |velocity difference| {s['replay_max_dv']:.3g} rad/s over "
        f"{s['replay_states']} states\n")
    if "plot" in s:
        out(f"  plot: {s['plot']}\n")


def plot_demo(rec, profile: Profile, summary: dict, png: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = _series(rec)
    fig, ax = plt.subplots(5, 1, figsize=(10, 11), sharex=True, constrained_layout=True)
    ax[0].step(profile.t, profile.values, where="post", label="torque command", color="0.5")
    ax[0].plot(s["t"], s["effort"], label="effort (K i_q N)", lw=0.8)
    ax[0].step(profile.t, profile.load_torque, where="post", label="load torque", color="C3")
    ax[0].set_ylabel("output torque [N*m]")
    ax[1].plot(s["t"], s["velocity"], label="velocity", lw=0.8)
    for (w, (_, est, _, _)) in ((STEADY_NO_LOAD, summary["steady_no_load"]), (STEADY_LOAD, summary["steady_load"])):
        ax[1].hlines(est, *w, colors="k", linestyles="--",
                     label="analytic steady speed" if w == STEADY_NO_LOAD else None)
    ax[1].set_ylabel("output speed [rad/s]")
    ax[2].plot(s["t_q"], s["i_q"], label="i_q", lw=0.8)
    ax[2].plot(s["t_q"], s["i_q_ref"], label="i_q_ref", lw=0.8, ls="--")
    ax[2].plot(s["t_q"], s["i_d"], label="i_d", lw=0.8)
    ax[2].set_ylabel("q-axis current [A]")
    ax[3].plot(s["t_q"], s["v_magnitude_q"], label="|v_dq|", lw=0.8)
    ax[3].plot(s["t_q"], s["v_limit_q"], label="SVPWM limit", color="k", ls="--")
    sat = s["voltage_saturated"] > 0.5
    ax[3].fill_between(s["t_q"], 0, s["v_limit_q"], where=sat, color="C3", alpha=0.15, label="saturated")
    ax[3].set_ylabel("voltage [V]")
    ax[4].plot(s["t"], s["T_w"], label="winding")
    ax[4].plot(s["t"], s["T_h"], label="housing")
    ax[4].set_ylabel("temperature [degC]")
    ax[4].set_xlabel("simulation time [s]")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(loc="best", fontsize=8)
    fig.suptitle(f"bldc-actuator demo: {summary['preset']} ({summary['mode']})")
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return png


# ------------------------------------------------------------------------------------------ command line

def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="run the ROS 2 node with a built-in command profile, record out/demo.mcap, plot",
        description="Runs actuator_node in-process, driven by a built-in profile (torque steps, chirp, load "
                    "step; about 4 s of simulation) from a second in-process node, records an MCAP, prints a "
                    "summary (topics, steady speed vs the analytic value, temperatures, saturation) and writes "
                    "a plot. Needs rclpy (pip install .[wheels]).")
    p.add_argument("--preset", default=None, help="motor preset name (e.g. ak80_9) or parameter file; "
                   "default: the built-in defaults")
    p.add_argument("--out", type=Path, default=Path("out"), help="output directory (default: out)")
    p.add_argument("--time-factor", type=float, default=None, metavar="F",
                   help="run the node free at F x real time (0 = as fast as possible) instead of lock-step")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG")
    p.set_defaults(func=run)


def run(args) -> int:
    try:
        summary = run_demo(args.preset, args.out, time_factor=args.time_factor, plot=not args.no_plot)
    except ParameterError as exc:
        print(f"bldc-actuator demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bldc-actuator demo: interrupted", file=sys.stderr)
        return 130
    except ModuleNotFoundError as exc:
        print(f"bldc-actuator demo: {exc.name} is not installed (pip install .[wheels])", file=sys.stderr)
        return 1
    return 0 if summary["finalized"] else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="bldc-actuator")
    register(parser.add_subparsers())
    return run(parser.parse_args(["demo", *(argv or [])]))
