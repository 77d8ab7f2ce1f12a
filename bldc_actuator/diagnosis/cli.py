"""``bldc-actuator diagnose``: the command-line face of :func:`.pipeline.diagnose`.

    bldc-actuator diagnose RECORDING --params PARAMS.yaml [--profile NAME|FILE] [--joint NAME]
                           [--map CANONICAL=EXPR ...] [--map-file F]
                           --json REPORT.json --report DIR [--updated-params OUT.yaml]
                           [--effects a,b] [--holdout FRACTION | --holdout-file F]
                           [--mujoco-model ROBOT.xml [--joint-map REC=MJCF,...]]

``--mujoco-model``: a multi-joint file diagnosed as one robot (:mod:`.body.robot`): the body's torque on every
joint from the MJCF's inverse dynamics is each joint's known load, the body's mass errors are findings, and the
report has a section per joint (``--json``: one JSON; ``--report``: report.md plus a directory per joint).

Exit status: 0 when the diagnosis ran (whatever it found), 2 on bad input (the message names the file,
field or option).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "locate where a recording and the model differ, name the missing physics, fit it, show the improvement"


def register(subparsers) -> None:
    from .frame.candidates import EFFECT_NAMES

    p = subparsers.add_parser("diagnose", help=HELP, description=HELP + ". See docs and issue 4.",
                              formatter_class=argparse.RawDescriptionHelpFormatter,
                              epilog="effects: " + ", ".join(EFFECT_NAMES))
    p.add_argument("recording", metavar="RECORDING", help="CSV or MCAP recording")
    p.add_argument("--params", required=True, metavar="PARAMS.yaml",
                   help="nominal parameters: a parameter file (the node's YAML), a preset name, 'defaults' "
                        "(the built-in defaults) or 'recording' (the parameters stored in this MCAP recording)")
    p.add_argument("--joint", metavar="NAME", help="the joint to diagnose in a file of several actuators (an "
                                                   "actuator_node recording of several joints, a wide CSV)")
    p.add_argument("--profile", metavar="NAME|FILE",
                   help="input profile (YAML) saying how the log's columns become canonical channels; default: "
                        "auto-detected from the header (the chosen one is printed); see docs/realdata.md")
    p.add_argument("--map", action="append", default=[], metavar="CANONICAL=EXPR",
                   help="rename/scale a column, e.g. velocity=speed*9 (repeatable)")
    p.add_argument("--map-file", metavar="F", help="YAML mapping {canonical: expression}")
    p.add_argument("--json", metavar="REPORT.json", help="write the JSON report here")
    p.add_argument("--report", metavar="DIR", help="write report.md and PNG plots into DIR")
    p.add_argument("--updated-params", metavar="OUT.yaml",
                   help="write the parameter file with the accepted effects fitted (with --mujoco-model: one per "
                        "joint, OUT.<joint>.yaml)")
    p.add_argument("--effects", metavar="a,b", help="test only these candidate effects (comma-separated)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--holdout", type=float, default=0.3, metavar="FRACTION",
                   help="fraction of the recording held out, in interleaved time blocks (default 0.3)")
    g.add_argument("--holdout-file", metavar="F", help="a second recording used as held-out data")
    p.add_argument("--tolerance", type=float, default=0.05, metavar="FRACTION",
                   help="a parameter-change finding (K_t, J, R, L, thermal network) must move its parameter by more "
                        "than this fraction of nominal, else 'consistent with nominal' (default 0.05)")
    p.add_argument("--max-uncertainty", type=float, default=0.5, metavar="FRACTION",
                   help="every accepted value must have a relative uncertainty below this, else 'suspected, not "
                        "identifiable' (default 0.5)")
    p.add_argument("--simulation-gate", dest="simulation_gate", action="store_true", default=True,
                   help="(default) accept only findings that make the simulated actuator reproduce held-out data "
                        "better: leave-one-out replay from recorded states beyond the window-to-window noise floor, "
                        "and for thermal-network findings the full-length thermal simulation; no other simulated "
                        "channel may get worse by more than --tolerance")
    p.add_argument("--no-simulation-gate", dest="simulation_gate", action="store_false",
                   help="accept in equation-error space only (the simulated verdict is still reported per finding)")
    p.add_argument("--cutoff", type=float, metavar="HZ", help="parallel low-pass cut-off (default min(fs/10, 100 Hz))")
    p.add_argument("--voltage-timing", choices=("auto", "applied", "command", "sample"), default="auto",
                   help="how the logged voltage is timed where the log shows no frame delay on its d axis (one "
                        "it shows always places the voltage): 'applied' = the voltage held at the sample (this "
                        "project's node, simulate CSV and kernel: held over the loop period the sample ends, it acts "
                        "half a loop period BEFORE the sample, + drive.current_loop_delay); 'command' = the voltage "
                        "the drive computed from the current sample it is logged with (acts drive.current_loop_delay "
                        "+ half a loop period later); 'sample' = the voltage acting at its sample; 'auto' (default) = "
                        "what the recording declares (this project's MCAP and CSV files do), else 'command' where the "
                        "log shows that pairing's noise signature, else 'sample'")
    p.add_argument("--window", type=float, default=0.1, metavar="S", help="replay window length (default 0.1 s)")
    p.add_argument("--mujoco-model", metavar="ROBOT.xml",
                   help="diagnose every joint of a multi-joint file as one robot against this MJCF model: the body's "
                        "torque on each joint (mujoco.mj_inverse over the recorded motion) is its known load, and a "
                        "body's mass error (a link, a payload) is a finding (fixed-base robots)")
    p.add_argument("--joint-map", action="append", default=[], metavar="REC=MJCF,...",
                   help="with --mujoco-model: the MJCF joint of a recorded joint whose name differs, e.g. "
                        "joint1=shoulder_yaw,joint2=elbow (repeatable)")
    p.add_argument("--no-plots", action="store_true", help="Markdown report without PNGs")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run)


def _fail(msg: str) -> int:
    print(f"bldc-actuator diagnose: error: {msg}", file=sys.stderr)
    return 2


def _load(path: str, mapping, params, joint=None, profile=None, progress=False):
    from .io import cleaning, loaders

    raw = loaders.load(path, mapping=mapping, params=params, joint=joint, profile=profile)
    if progress and raw.meta.get("profile"):
        print(f"[diagnose] input profile: {raw.meta['profile']} ({raw.meta.get('profile_how', '')}; "
              f"{raw.meta.get('profile_path', '')})", file=sys.stderr, flush=True)
    if params is None:   # --params recording
        params = raw.meta.get("params_from_recording")
        if params is None:
            raise ValueError(f"--params recording: {path} stores no (readable) model parameters; give a "
                             "parameter file, a preset or 'defaults'")
    return cleaning.clean(raw, params=params), params


def run(args) -> int:
    from ..params import ParameterError, load_preset
    from .pipeline import DiagnoseOptions, diagnose

    from ..params import ActuatorParams

    try:
        params = (None if args.params == "recording" else ActuatorParams() if args.params == "defaults"
                  else load_preset(args.params))
    except (ParameterError, FileNotFoundError) as exc:
        return _fail(f"--params {args.params}: {exc}")
    try:
        from .io.loaders import Mapping

        mapping = Mapping.from_yaml(args.map_file) if args.map_file else Mapping()
        extra = Mapping.parse(args.map)
        mapping.update(extra)
        if not mapping.has_columns:
            mapping = None
    except ValueError as exc:
        return _fail(str(exc))
    effects = [e.strip() for e in args.effects.split(",") if e.strip()] if args.effects else None
    try:
        DiagnoseOptions(effects=effects).validated_effects()
    except ValueError as exc:
        return _fail(f"--{exc}")
    if args.holdout_file is None and not (0.0 < args.holdout < 1.0):
        return _fail(f"--holdout: expected a fraction 0 < f < 1, got {args.holdout!r}")
    for name in ("recording", "holdout_file"):
        path = getattr(args, name)
        if path is not None and not Path(path).exists():
            return _fail(f"{path}: no such file")
    progress = not args.quiet
    if args.mujoco_model:
        return _run_robot(args, params, mapping, effects, progress)
    if args.joint_map:
        return _fail("--joint-map: applies with --mujoco-model only")
    try:
        if progress:
            print(f"[diagnose] loading {args.recording}", file=sys.stderr, flush=True)
        signals, params = _load(args.recording, mapping, params, args.joint, args.profile, progress)
        holdout_signals = (_load(args.holdout_file, mapping, params, args.joint, args.profile)[0]
                           if args.holdout_file else None)
    except (ValueError, OSError) as exc:    # LoadError is a ValueError
        return _fail(str(exc))
    if not (0.0 <= args.tolerance < 1.0):
        return _fail(f"--tolerance: expected a fraction 0 <= f < 1, got {args.tolerance!r}")
    if not (args.max_uncertainty > 0.0):
        return _fail(f"--max-uncertainty: expected a fraction > 0, got {args.max_uncertainty!r}")
    options = DiagnoseOptions(effects=effects, holdout=args.holdout, holdout_signals=holdout_signals,
                              cutoff_hz=args.cutoff, window_s=args.window, progress=progress,
                              tolerance=args.tolerance, max_relative_uncertainty=args.max_uncertainty,
                              simulation_gate=args.simulation_gate, voltage_timing=args.voltage_timing)
    try:
        report = diagnose(signals, params, options=options)
    except ValueError as exc:
        return _fail(str(exc))
    if args.json:
        report.write_json(args.json)
    if args.report:
        report.write_markdown(args.report, plots=not args.no_plots)
    if args.updated_params and report.updated_params is not None:
        report.write_params(args.updated_params)
    _print_summary(report, args)
    return 0


def _run_robot(args, params, mapping, effects, progress) -> int:
    from .body.joints import parse_joint_map
    from .body.robot import diagnose_robot_file
    from .pipeline import DiagnoseOptions

    if params is None:
        return _fail("--params recording: not with --mujoco-model yet; give a parameter file or a preset")
    if args.joint is not None:
        return _fail("--joint: not with --mujoco-model (the robot is diagnosed whole)")
    if args.holdout_file:
        return _fail("--holdout-file: not with --mujoco-model yet; use --holdout")
    if not Path(args.mujoco_model).exists():
        return _fail(f"--mujoco-model {args.mujoco_model}: no such file")
    try:
        joint_map = parse_joint_map(args.joint_map)
        options = DiagnoseOptions(effects=effects, holdout=args.holdout, cutoff_hz=args.cutoff, window_s=args.window,
                                  progress=progress, tolerance=args.tolerance,
                                  max_relative_uncertainty=args.max_uncertainty, simulation_gate=args.simulation_gate,
                                  voltage_timing=args.voltage_timing)
        if progress:
            print(f"[diagnose] robot: {args.recording} against {args.mujoco_model}", file=sys.stderr, flush=True)
        report = diagnose_robot_file(args.recording, params, args.mujoco_model, joint_map=joint_map,
                                     profile=args.profile, mapping=mapping, options=options)
    except (ValueError, OSError) as exc:
        return _fail(str(exc))
    if args.json:
        report.write_json(args.json)
    if args.report:
        report.write_markdown(args.report, plots=not args.no_plots)
    written = []
    if args.updated_params:        # one parameter file per joint: OUT.yaml -> OUT.<joint>.yaml
        out = Path(args.updated_params)
        for j, r in report.joints.items():
            if r.updated_params is not None:
                path = out.with_name(f"{out.stem}.{j}{out.suffix or '.yaml'}")
                r.write_params(path)
                written.append(str(path))
    for f in report.body.findings:
        print(f"body: {f.sentence()}")
    if not report.body.findings:
        print("body: nothing missing in the mass properties")
    for f in report.body.rejected:
        print(f"  body, not accepted: {f.body} {f.delta_mass:+.3g} kg: {f.reason}")
    for j, r in report.joints.items():
        print(f"{j}: {r.verdict}")
    for name, path in (("json", args.json), ("report", args.report and str(Path(args.report) / "report.md"))):
        if path:
            print(f"  wrote {name}: {path}")
    for path in written:
        print(f"  wrote updated params: {path}")
    return 0


def _print_summary(report, args) -> None:
    print(report.verdict)
    if report.method != "equation error + simulation":
        print(f"  route: {report.method}")
    for u in report.verdict_record.undecidable:
        if u.remedy:
            print(f"  {'not decidable' if report.verdict_kind == 'not decidable' else 'caveat'}: {u.code}: "
                  f"what to do: {u.remedy}")
    for f in report.findings:
        unc = f["uncertainty"]
        pars = ", ".join(f"{k}={_fmt(v)}" + ("" if unc.get(k) is None else f"±{_fmt(unc[k])}")
                         for k, v in f["parameters"].items() if not isinstance(v, str))
        tag = ("" if f.get("simulated", True) else " [not yet simulated]") + \
            (" [not checkable in simulation]" if f.get("not_checkable_in_simulation") else "")
        ho = f.get("held_out") or {}
        line = f"  {f['effect']}{tag}: {pars}"
        if f.get("frame_factor"):
            line += f"; frame factor {f['frame_factor']}"
        if ho:
            line += f"; held-out {ho.get('metric', '')}: {_fmt(ho['before'])} -> {_fmt(ho['after'])} {ho.get('unit', '')}"
        sim = f.get("simulation")
        if sim and sim.get("channel"):
            unit = {"velocity": "rad/s", "current": "A", "voltage": "V", "temperature": "K"}[sim["channel"]]
            line += (f"; simulated held-out {sim['channel']} error without/with it {_fmt(sim['without'])} -> "
                     f"{_fmt(sim['with'])} {unit}: {sim['verdict']}")
        print(line)
    for a in report.aliases:
        print(f"  alias: {a['message']}; experiment: {a['experiment']}")
    for x in report.rejected:
        if x.get("form") == "torque balance":
            print(f"  not accepted: {x['effect']}: {x['reason']}")
    for x in report.not_checkable:
        print(f"  not checkable: {x['effect']}: {x['reason']}")
    shown = [d for d in report.data_issues if d.get("kind") in ("unit_suspect", "clipped", "sign_convention",
                                                                  "missing_channel")]
    if report.data_issues:
        print(f"  data issues: {len(report.data_issues)}" + (" (all in the report)" if report.data_issues else ""))
        for d in shown[:8]:
            print(f"    [{d.get('kind')}] {d.get('detail')} -> {d.get('action')}")
    for name, path in (("json", args.json), ("report", args.report and str(Path(args.report) / "report.md")),
                       ("updated params", args.updated_params)):
        if path:
            print(f"  wrote {name}: {path}")


def _fmt(x) -> str:
    if isinstance(x, bool):         # a drive option (drive.decoupling_enabled): as the parameter file spells it
        return str(x).lower()
    try:
        return f"{float(x):.4g}"
    except (TypeError, ValueError):
        return str(x)
