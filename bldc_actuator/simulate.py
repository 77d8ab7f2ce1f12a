"""``bldc-actuator simulate``: run a command profile through the model offline → CSV of every signal + PNG.

Example::

    bldc-actuator simulate --preset ak80_9 --profile chirp --amplitude 5 --f0 1 --f1 100 --duration 2
    bldc-actuator simulate --params my_motor.yaml --profile csv --input commands.csv --out out/run1
    bldc-actuator simulate --preset ak80_9 --profile csv --input log_ms.csv --time-unit ms

The CSV written (PREFIX.csv) is read back by ``bldc-actuator diagnose`` without ``--map`` (input profile
``bldc_actuator_simulate``, with the ``# voltage_timing`` comment lines). The printed summary covers every
current-loop tick, whatever ``--rate``. Commands beyond the node's absurd bound (``scheduler.absurd_limits``) are
refused.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from . import profiles
from .model import Actuator, SimResult
from .params import ActuatorParams, ParameterError, load_preset, load_yaml
from .scheduler import ABSURD_FACTOR, absurd_limits
from . import drive_tuning
from .voltage_timing import csv_comment_lines, kernel_declaration

#: columns written to the CSV, in order, with units
CSV_COLUMNS = [
    ("t", "s"), ("command", "A or N*m"), ("i_q_ref", "A"), ("i_q", "A"), ("i_d", "A"), ("v_q", "V"), ("v_d", "V"),
    ("v_magnitude_q", "V"), ("v_limit_q", "V"), ("voltage_saturated", "bool"), ("omega", "rad/s"),
    ("theta", "rad"), ("position_out", "rad"), ("velocity_out", "rad/s"), ("torque_em", "N*m"),
    ("effort_out", "N*m"), ("i_phase_a", "A"), ("i_phase_b", "A"), ("i_phase_c", "A"), ("i_line_a", "A"),
    ("i_line_b", "A"), ("i_line_c", "A"), ("T_winding", "degC"), ("T_housing", "degC"),
    ("resistance_phase", "ohm"), ("joule_power", "W"), ("current_limit_effective", "A"),
    # the q-axis current command from the sample on (a torque command converted as the drive does), before limits:
    # what a drive log calls its command (i_q_ref is the drive's reference as of its last tick, one sample behind)
    ("i_q_command", "A"),
]


def positive(name):
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: expected a number, got {text!r}") from None
        if not value > 0:
            raise argparse.ArgumentTypeError(f"{name}: expected > 0, got {value!r}")
        return value
    return parse


def register(sub) -> None:
    p = sub.add_parser("simulate", help="run a command profile through the model; write CSV + PNG",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--preset", help="preset name from config/ (e.g. ak80_9); default: built-in defaults")
    src.add_argument("--params", type=Path, help="parameter YAML (node layout)")
    p.add_argument("--profile", choices=["step", "chirp", "sine", "csv"], default="step")
    p.add_argument("--kind", choices=profiles.KINDS, default="current",
                   help="command meaning: q-axis current [A] or output torque [N*m]")
    p.add_argument("--amplitude", type=float, default=5.0, help="command amplitude [A or N*m]")
    p.add_argument("--offset", type=float, default=0.0, help="sine offset [A or N*m]")
    p.add_argument("--frequency", type=positive("--frequency"), default=2.0, help="sine frequency [Hz]")
    p.add_argument("--f0", type=positive("--f0"), default=1.0, help="chirp start frequency [Hz]")
    p.add_argument("--f1", type=positive("--f1"), default=100.0, help="chirp end frequency [Hz]")
    p.add_argument("--duration", type=positive("--duration"), default=1.0, help="[s]")
    p.add_argument("--rate", type=positive("--rate"), default=1000.0,
                   help="output sample rate [Hz] of every profile (csv too: its rows are commands, held until the "
                        "next row); also the command rate of step, sine and chirp")
    p.add_argument("--input", type=Path, help="CSV of commands for --profile csv (time, current_command or "
                   "torque_command, optional load_torque)")
    p.add_argument("--time-unit", choices=list(profiles.TIME_UNITS), default=None,
                   help="unit of the --input CSV's 'time' column (default: seconds, or the unit its name gives: "
                        "time_ms, t_ms, 'time [ms]'; a unit-less column that looks like milliseconds is an error)")
    p.add_argument("--load-torque", type=float, default=None, help="constant external load at the output [N*m]")
    p.add_argument("--out", type=Path, default=Path("out/simulate"), help="output prefix (writes PREFIX.csv/.png)")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG")
    p.set_defaults(func=run)


def simulate_profile(params: ActuatorParams | str | Path, profile: profiles.Profile, *,
                     rate: float | None = 1000.0) -> SimResult:
    """Run ``profile`` through a fresh :class:`Actuator` of ``params`` (ActuatorParams, or a preset name or
    parameter file for :func:`~bldc_actuator.params.load_preset`); every signal sampled at ``rate`` [Hz]
    whatever the profile's own rows (``None``: at the profile's samples). What ``bldc-actuator simulate``
    computes."""
    read = not isinstance(params, ActuatorParams)
    if read:
        params = load_preset(params)
    if rate is not None and not (rate > 0 and np.isfinite(rate)):
        raise ValueError(f"rate: expected > 0 Hz, got {rate!r}")
    check_commands(params, profile, f"profile {profile.name}")
    # a file's warnings (the current loop's among them) were printed where it was read, with its name
    return Actuator(params, warn=not read).run(profile, record_every=None if rate is None else 1.0 / rate)


def check_commands(params: ActuatorParams, profile: profiles.Profile, source: str = "profile") -> None:
    """Refuse a profile with an absurd command, by the node's rule (:func:`~bldc_actuator.scheduler.absurd_limits`:
    more than :data:`~bldc_actuator.scheduler.ABSURD_FACTOR` x ``drive.current_limit``, in current or the output
    torque it makes); ``source`` names where the commands come from (the CSV column, ``--amplitude``). Commands
    between the limit and that are accepted and limited by the drive, as a real drive does."""
    current_max, torque_max = absurd_limits(params)
    limit, unit = (current_max, "A") if profile.kind == "current" else (torque_max, "N*m")
    bad = np.nonzero(np.abs(profile.values) > limit)[0]
    if len(bad):
        k = int(bad[0])
        raise ValueError(
            f"{source}: {profile.kind} command {profile.values[k]:g} {unit} (row {k + 1}, t = {profile.t[k]:g} s) is "
            f"absurd: |{profile.kind} command| <= {limit:g} {unit} ({ABSURD_FACTOR:g} x drive.current_limit "
            f"{params.drive.current_limit:g} A" + ("" if profile.kind == "current" else
                                                  " x motor.torque_constant_q x gear.gear_ratio") +
            f"; the drive itself limits |i_q| to drive.current_limit {params.drive.current_limit:g} A"
            + ("" if profile.kind == "current" else f", {limit / ABSURD_FACTOR:g} N*m at the output")
            + f"); {len(bad)} row(s) beyond it")


def command_source(args, profile: profiles.Profile) -> str:
    """Where a profile's commands come from (the CSV's column, the options), for error messages."""
    if args.profile == "csv":
        return f"{args.input}: column {profile.kind}_command"
    return "--amplitude/--offset" if args.profile == "sine" else "--amplitude"


def load_params(args) -> ActuatorParams:
    if args.params:
        return load_yaml(args.params)
    if args.preset:
        return load_preset(args.preset)
    return ActuatorParams()


def build_profile(args) -> profiles.Profile:
    if args.time_unit is not None and args.profile != "csv":
        raise ValueError(f"--time-unit: only for --profile csv (the --input CSV's time column), not {args.profile}")
    if args.profile == "csv":
        if not args.input:
            raise ValueError("--input: required with --profile csv (a CSV with time and a command column)")
        return profiles.from_csv(args.input, time_unit=args.time_unit)
    if args.profile == "step":
        return profiles.step(args.amplitude, args.duration, t_step=min(0.05, args.duration / 10), rate=args.rate,
                             kind=args.kind)
    if args.profile == "sine":
        return profiles.sine(args.amplitude, args.frequency, args.duration, args.rate, args.kind, args.offset)
    return profiles.chirp(args.amplitude, args.f0, args.f1, args.duration, args.rate, args.kind)


def write_csv(result: SimResult, path: Path) -> None:
    """Every signal of ``result`` at its sample rate, after ``# key: value`` comment lines that declare when the
    logged voltage acts (the kernel's held voltage: :func:`bldc_actuator.voltage_timing.kernel_declaration`) and what
    the drive's current loop was tuned with (:func:`bldc_actuator.drive_tuning.declaration`; read
    them with ``pandas.read_csv(path, comment="#")``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    t = np.asarray(result["t"], float)
    with path.open("w", newline="") as fh:
        if len(t) > 1:
            period = float(np.median(np.diff(t)))
            declared = {**kernel_declaration(result.params, period), **drive_tuning.declaration(result.params)}
            for line in csv_comment_lines(declared):
                fh.write(line + "\n")
        w = csv.writer(fh)
        w.writerow([f"{name} [{unit}]" for name, unit in CSV_COLUMNS])
        cols = [result[name] for name, _ in CSV_COLUMNS]
        for row in zip(*cols):
            w.writerow([f"{x:.9g}" for x in row])


def plot(result: SimResult, path: Path, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result["t"]
    fig, ax = plt.subplots(5, 1, figsize=(11, 12), sharex=False)
    ax[0].plot(t, result["i_q_ref"], "k--", lw=1, label="i_q ref")
    ax[0].plot(t, result["i_q"], label="i_q")
    ax[0].plot(t, result["i_d"], label="i_d")
    ax[0].set_ylabel("q-axis current [A]")
    ax[1].plot(t, result["v_magnitude_q"], label="|v_dq|")
    ax[1].plot(t, result["v_limit_q"], "r--", label="SVPWM limit")
    ax[1].plot(t, result["v_q"], lw=0.8, label="v_q")
    ax[1].set_ylabel("voltage [V]")
    ax[2].plot(t, result["velocity_out"], label="output speed")
    ax[2].set_ylabel("speed [rad/s]")
    ax[3].plot(t, result["T_winding"], label="winding")
    ax[3].plot(t, result["T_housing"], label="housing")
    ax[3].set_ylabel("temperature [°C]")
    # phase currents over the last few electrical periods (they are sinusoids at p·ω)
    n = max(10, min(len(t), 200))
    for key in ("i_phase_a", "i_phase_b", "i_phase_c"):
        ax[4].plot(t[-n:], result[key][-n:], label=key[-1].upper() if key != "i_phase_a" else "A")
    ax[4].set_ylabel("phase current [A]\n(at the output rate)")
    for a in ax:   # beside the panel: inside it the legend hid the curves it names
        a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
        a.grid(alpha=0.3)
        a.ticklabel_format(useOffset=False)
    ax[-1].set_xlabel("time [s]")
    ax[-2].set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def summary(result: SimResult) -> str:
    """The run's figures, from the simulation at every current-loop tick (:class:`profiles.RunSummary`), not from
    the trace sampled at ``--rate`` (whose peak between samples depends on the rate)."""
    s = result.summary
    return (f"duration {s.duration:.3f} s, samples {len(result['t'])} at the output rate, current-loop ticks "
            f"{s.ticks} (the figures below cover every tick)\n"
            f"peak |i_q| {s.peak_abs_i_q:.3f} A, peak output speed {s.peak_abs_velocity_out:.3f} rad/s, "
            f"voltage saturated {100 * s.saturated_fraction:.1f} % of ticks\n"
            f"winding temperature {s.T_winding_start:.2f} -> {s.T_winding_end:.2f} degC "
            f"(peak {s.T_winding_peak:.2f})")


def run(args) -> int:
    try:
        params = load_params(args)
        if args.load_torque is not None:
            params = params.replace(**{"load.load_torque": args.load_torque})
        prof = build_profile(args)
        check_commands(params, prof, command_source(args, prof))
    except (ParameterError, ValueError) as exc:
        print(f"bldc-actuator simulate: {exc}", file=sys.stderr)
        return 2
    # the parameter file's warnings (the current loop's among them) were printed where it was read, with its name
    act = Actuator(params, warn=not (args.params or args.preset))
    e0 = act.energy
    # outputs at --rate whatever the profile: a CSV of a few command rows still gives a full trace
    result = act.run(prof, record_every=1.0 / args.rate)
    csv_path = args.out.with_suffix(".csv")
    write_csv(result, csv_path)
    print(f"wrote {csv_path} ({len(CSV_COLUMNS)} columns)")
    if not args.no_plot:
        png = args.out.with_suffix(".png")
        plot(result, png, title=f"{prof.name} ({prof.kind}), {args.preset or args.params or 'defaults'}")
        print(f"wrote {png}")
    print(summary(result))
    e = act.energy
    print(f"energy: in {e.electrical_in:.6g} J = Joule {e.joule:.6g} + mechanical "
          f"{e.viscous + e.friction + e.load:.6g} + stored {e.kinetic + e.magnetic:.6g} "
          f"(residual {e.residual(e0):.2e} J)")
    return 0
