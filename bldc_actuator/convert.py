"""``bldc-actuator convert``: datasheet values (with their frames) -> q-axis model parameters, each step explained.

Example::

    bldc-actuator convert --winding delta --kv 100 --terminal-resistance 0.186 --terminal-inductance 1.2e-4 \\
        --pole-pairs 21 --bus-voltage 24 --yaml motor.yaml --verify

The q-axis frame is the power-invariant d-q transform of the *winding* quantities (see
:mod:`bldc_actuator.frames`). ``--verify`` rebuilds a three-phase circuit (:mod:`bldc_actuator.abc_model`) from
the converted parameters and measures the datasheet quantities on it again.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from typing import Optional, TextIO

from . import frames
from .params import yaml_scalar

PAPER_DOC = "docs/paper-discrepancies.md"

# factor names used to explain a Kt / Kv disagreement
_NAMED_FACTORS = [
    ("sqrt(3/2)", math.sqrt(1.5)), ("sqrt(2/3)", math.sqrt(2.0 / 3.0)), ("sqrt(2)", math.sqrt(2.0)),
    ("1/sqrt(2)", 1.0 / math.sqrt(2.0)), ("sqrt(3)", math.sqrt(3.0)), ("1/sqrt(3)", 1.0 / math.sqrt(3.0)),
    ("3/2", 1.5), ("2/3", 2.0 / 3.0), ("2", 2.0), ("1/2", 0.5), ("3", 3.0), ("1/3", 1.0 / 3.0),
    ("sqrt(3)/2", math.sqrt(3.0) / 2.0), ("2/sqrt(3)", 2.0 / math.sqrt(3.0)),
    ("3/sqrt(2)", 3.0 / math.sqrt(2.0)), ("sqrt(2)/3", math.sqrt(2.0) / 3.0),
]
#: Kv-derived and Kt-derived K_t^q closer than this are "in agreement" (the paper reports real back-EMF
#: 5-10 % above the Kv number)
AGREE_TOL = 0.10
#: a ratio is attributed to a named frame factor when within this
FACTOR_TOL = 0.03

_KB_UNITS = {"V*s/rad": 1.0, "V/krpm": 60.0 / (2.0 * math.pi * 1000.0), "V/rpm": 60.0 / (2.0 * math.pi)}


class _UsageError(Exception):
    def __init__(self, argument: str, message: str):
        super().__init__(f"argument {argument}: {message}")


def _number(argument: str, unit: str, *, lo: float = 0.0, lo_open: bool = True, hi: float = math.inf):
    """argparse type: a finite float in the range, error names the argument, range and unit."""
    rng = f"{'>' if lo_open else '>='} {lo:g}" + (f" and <= {hi:g}" if math.isfinite(hi) else "")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number {rng} [{unit}], got {text!r}") from None
        ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and value <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"expected a number {rng} [{unit}], got {text!r}")
        return value
    parse.__name__ = argument  # shown by argparse in "invalid <name> value"
    return parse


def _pole_pairs(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1 [pole pairs], got {text!r}") from None
    if not 1 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"expected an integer in 1..1000 [pole pairs], got {text!r}")
    return value


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``convert`` subcommand (called by :mod:`bldc_actuator.cli`)."""
    p = subparsers.add_parser(
        "convert",
        help="datasheet values -> q-axis model parameters, each conversion step explained",
        description=(
            "Convert motor datasheet values, each given with its reference frame, to the q-axis model "
            "(power-invariant d-q transform of the winding quantities): phase resistance R^phi [ohm], q-axis "
            "inductance L^q [H], torque constant K_t^q = back-EMF constant K_b^q [N*m/A = V*s/rad, per "
            "mechanical rad/s]. Every step prints its formula, numbers and the source equation of Lee et al. "
            f"(shared/reference/seed-paper.tex); where the paper is wrong the physics is used ({PAPER_DOC})."),
        epilog=(
            "examples:\n"
            "  bldc-actuator convert --winding delta --kv 100 --terminal-resistance 0.186 "
            "--terminal-inductance 1.2e-4\n"
            "  bldc-actuator convert --winding unknown --kv 100 --kt 0.14 --kt-frame phase_peak\n"
            "  bldc-actuator convert --winding wye --kv 270 --pole-pairs 7 --bus-voltage 48 --yaml motor.yaml "
            "--verify"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--winding", choices=("wye", "delta", "unknown"), default="unknown",
                   help="winding connection; 'unknown' (default) prints both answers")
    p.add_argument("--terminal-resistance", type=_number("--terminal-resistance", "ohm"), metavar="OHM",
                   help="resistance between two leads, third lead floating [ohm]")
    p.add_argument("--terminal-inductance", type=_number("--terminal-inductance", "H"), metavar="H",
                   help="inductance between two leads, third lead floating [H]")
    p.add_argument("--kv", type=_number("--kv", "rpm/V"), metavar="RPM_PER_V",
                   help="velocity constant: no-load rpm per volt [rpm/V]")
    p.add_argument("--kv-frame", choices=frames.KV_FRAMES, default=None,
                   help="which volt the Kv number divides (default: ll_peak, assumed with a warning)")
    p.add_argument("--kt", type=_number("--kt", "N*m/A"), metavar="NM_PER_A",
                   help="torque constant: motor torque per ampere of the current named by --kt-frame [N*m/A]")
    p.add_argument("--kt-frame", choices=frames.TORQUE_CONSTANT_FRAMES, default=None,
                   help="current the --kt value is per (required with --kt). per_phase_amplitude is the paper's "
                        "per-winding constant amplitude; phase_peak is total torque per phase-current amplitude; "
                        "q_amplitude_invariant / q_power_invariant transform the WINDING currents; "
                        "drive_amplitude_invariant / drive_power_invariant are what a FOC drive (ODrive, VESC) "
                        "reports: it transforms the LINE currents (differs from q_* on a delta motor by sqrt(3))")
    p.add_argument("--kb", type=_number("--kb", "V*s/rad (or --kb-unit)"), metavar="KB",
                   help="back-EMF constant in the voltage frame --kb-frame, per mechanical speed")
    p.add_argument("--kb-frame", choices=frames.BACK_EMF_FRAMES, default=None,
                   help="voltage frame of --kb (default: ll_peak, assumed with a warning)")
    p.add_argument("--kb-unit", choices=tuple(_KB_UNITS), default="V*s/rad",
                   help="unit of --kb (default V*s/rad)")
    p.add_argument("--pole-pairs", type=_pole_pairs, metavar="P", help="magnet pole pairs p (theta_e = p theta)")
    p.add_argument("--bus-voltage", type=_number("--bus-voltage", "V"), metavar="V",
                   help="DC bus voltage [V]: prints the SVPWM voltage limit and the no-load speed")
    p.add_argument("--yaml", metavar="OUT", help="write a ROS parameter snippet (motor.* keys) to OUT")
    p.add_argument("--verify", action="store_true",
                   help="rebuild a three-phase circuit from the result and measure the datasheet values on it")
    p.set_defaults(func=run)
    return p


# ------------------------------------------------------------------------------------------------
# Conversion
# ------------------------------------------------------------------------------------------------

@dataclass
class _Section:
    title: str
    lines: list[str] = field(default_factory=list)


@dataclass
class WindingResult:
    """All converted values for one winding assumption."""

    winding: str
    r_phase: Optional[float] = None
    l_q: Optional[float] = None
    k_q: Optional[float] = None
    k_q_source: str = ""
    k_candidates: dict = field(default_factory=dict)  # source -> Conversion
    sections: list = field(default_factory=list)
    warnings: list = field(default_factory=list)


def _g(x: float) -> str:
    return f"{x:.6g}"


def _name_factor(ratio: float) -> Optional[str]:
    best = min(_NAMED_FACTORS, key=lambda nf: abs(math.log(ratio / nf[1])))
    return best[0] if abs(ratio / best[1] - 1.0) <= FACTOR_TOL else None


def _convert_winding(w: str, a: argparse.Namespace, kv_frame: str, kb_frame: str) -> WindingResult:
    res = WindingResult(w)
    if a.terminal_resistance is not None:
        f = 0.5 if w == "wye" else 1.5
        res.r_phase = frames.phase_resistance_from_terminal(a.terminal_resistance, w)
        why = "R^ll = 2 R^phi (two windings in series)" if w == "wye" else \
            "R^ll = R^phi || 2 R^phi = 2/3 R^phi (one winding parallel to two in series)"
        res.sections.append(_Section("phase resistance R^phi (= q-axis resistance, P = R^phi I_q^2, eq. power_quad)", [
            f"R^phi = {'1/2' if w == 'wye' else '3/2'} * R^ll = {f:g} x {_g(a.terminal_resistance)} ohm = "
            f"{_g(res.r_phase)} ohm   [eq. resistance_{w}; {why}]"]))
    if a.terminal_inductance is not None:
        res.l_q = frames.q_inductance_from_terminal(a.terminal_inductance, w)
        f = 0.5 if w == "wye" else 1.5
        paper_f = 1.5 if w == "wye" else 0.5
        paper = paper_f * a.terminal_inductance
        why = ("L^ll = 2 (L_s - M): two windings in series" if w == "wye" else
               "L^ll = 2/3 (L_s - M): KVL gives i_bc = i_ca = -i_ab/2, the same split as for R")
        res.sections.append(_Section("q-axis inductance L^q = L_d = L_s - M (eq. effective_induct)", [
            f"L^q = {'1/2' if w == 'wye' else '3/2'} * L^ll = {f:g} x {_g(a.terminal_inductance)} H = "
            f"{_g(res.l_q)} H   [physics: {why}; same factor as R, so L^q/R^phi = L^ll/R^ll]",
            f"note: the paper's eq. inductance_{w} / table tab:q-conversion give L^q = {'3/2' if w == 'wye' else '1/2'}"
            f" L^ll = {_g(paper)} H, {_g(paper / res.l_q)}x the circuit value; not used (see {PAPER_DOC})"]))

    # torque / back-EMF constant candidates, in priority order kt > kb > kv
    if a.kt is not None:
        c = frames.torque_constant_q_from(a.kt, a.kt_frame, w)
        res.k_candidates[f"--kt ({a.kt_frame})"] = c
    if a.kb is not None:
        kb_si = a.kb * _KB_UNITS[a.kb_unit]
        c = frames.back_emf_constant_q_from(kb_si, kb_frame, w)
        if a.kb_unit != "V*s/rad":
            c.steps.insert(0, f"K_b({kb_frame}) = {_g(a.kb)} {a.kb_unit} x {_g(_KB_UNITS[a.kb_unit])} = "
                              f"{_g(kb_si)} V*s/rad   [unit conversion, per mechanical rad/s]")
        res.k_candidates[f"--kb ({kb_frame})"] = c
    if a.kv is not None:
        c = frames.back_emf_constant_q_from_kv(a.kv, w, kv_frame)
        res.k_candidates[f"--kv ({kv_frame})"] = c
    if res.k_candidates:
        src, chosen = next(iter(res.k_candidates.items()))
        res.k_q, res.k_q_source = float(chosen), src
        lines = []
        for s, c in res.k_candidates.items():
            lines.append(f"from {s}:")
            lines += [f"  {step}" for step in c.steps]
            res.warnings += [f"{s}: {wn}" for wn in c.warnings]
        lines.append(f"K_t^q = K_b^q = {_g(res.k_q)} N*m/A (= V*s/rad)   [from {src}; K_t = K_b in SI units, "
                     "appendix Motor Physics; eq. q_axis_torque: tau = K_t^q I^q]")
        for s, c in list(res.k_candidates.items())[1:]:
            ratio = float(c) / res.k_q
            if abs(ratio - 1.0) <= AGREE_TOL:
                lines.append(f"{s} gives {_g(float(c))} N*m/A: agrees within {abs(ratio - 1) * 100:.1f} % "
                             f"(tolerance {AGREE_TOL * 100:.0f} %: real back-EMF is often 5-10 % off the Kv number)")
                continue
            name = _name_factor(ratio)
            msg = (f"{s} gives K_t^q = {_g(float(c))} N*m/A, {_g(ratio)}x the value from {src}"
                   + (f" -- a frame factor of {name}" if name else ""))
            hints = _reconcile(w, a, src, float(c), kv_frame, kb_frame)
            if hints:
                msg += "; it would agree if " + " or ".join(hints)
            lines.append("DISAGREE: " + msg)
            res.warnings.append(msg)
        res.sections.append(_Section("torque constant K_t^q = back-EMF constant K_b^q (per mechanical rad/s)",
                                     lines))
    return res


def _reconcile(w: str, a: argparse.Namespace, src: str, other: float, kv_frame: str, kb_frame: str) -> list[str]:
    """Frame interpretations of the chosen constant that would make it agree with ``other``."""
    hints = []
    if src.startswith("--kt"):
        for fr in frames.TORQUE_CONSTANT_FRAMES:
            if fr != a.kt_frame and abs(float(frames.torque_constant_q_from(a.kt, fr, w)) / other - 1) <= FACTOR_TOL:
                hints.append(f"--kt-frame were {fr}")
    elif src.startswith("--kb"):
        kb_si = a.kb * _KB_UNITS[a.kb_unit]
        for fr in frames.BACK_EMF_FRAMES:
            if fr != kb_frame and abs(float(frames.back_emf_constant_q_from(kb_si, fr, w)) / other - 1) <= FACTOR_TOL:
                hints.append(f"--kb-frame were {fr}")
    other_w = "delta" if w == "wye" else "wye"
    return hints + ([f"the winding were {other_w}"] if _agrees_for(other_w, a, kv_frame, kb_frame) else [])


def _agrees_for(w: str, a: argparse.Namespace, kv_frame: str, kb_frame: str) -> bool:
    vals = []
    if a.kt is not None:
        vals.append(float(frames.torque_constant_q_from(a.kt, a.kt_frame, w)))
    if a.kb is not None:
        vals.append(float(frames.back_emf_constant_q_from(a.kb * _KB_UNITS[a.kb_unit], kb_frame, w)))
    if a.kv is not None:
        vals.append(float(frames.back_emf_constant_q_from_kv(a.kv, w, kv_frame)))
    return len(vals) > 1 and max(vals) / min(vals) - 1 <= AGREE_TOL


def _speed_section(w: str, k_q: float, v_bus: float, pole_pairs: Optional[int]) -> _Section:
    v_lim = frames.voltage_limit_q(v_bus, w)
    w_max = frames.no_load_speed_max(v_bus, k_q, w)
    lines = [
        f"SVPWM: line-to-line peak <= V_bus = {_g(v_bus)} V  =>  |v_dq| <= "
        f"{'V_bus/sqrt(2)' if w == 'wye' else 'sqrt(3/2) V_bus'} = {_g(v_lim)} V   [eq. voltage_{w}]",
        f"no load (i = 0): v_q = K_b^q omega  =>  omega_max = {_g(v_lim)} V / {_g(k_q)} V*s/rad = {_g(w_max)} rad/s"
        f" = {_g(frames.rad_per_s_to_rpm(w_max))} rpm   [paper's max-speed eq. ({w}); = V_bus / Kbar_b^ll]",
        "under load the drop R^phi i_q and v_d = -omega_e L^q i_q lower this (|v_dq| counts, not v_q)",
    ]
    if pole_pairs:
        lines.append(f"electrical frequency at omega_max: {_g(pole_pairs * w_max / (2 * math.pi))} Hz "
                     f"(p = {pole_pairs})")
    return _Section(f"voltage limit and no-load speed at V_bus = {_g(v_bus)} V", lines)


def _extra_section(res: WindingResult, pole_pairs: Optional[int]) -> Optional[_Section]:
    if res.k_q is None:
        return None
    w, k = res.winding, res.k_q
    lines = [
        f"Kbar_b^ll = {_g(frames.back_emf_constant_from_q(k, 'll_peak', w))} V*s/rad -> Kv = "
        f"{_g(frames.kv_from_back_emf_constant_q(k, w))} rpm/V (ll peak); torque = sqrt(3)/2 Kbar_b^ll Ibar^l "
        "for either winding [eq. kb_ll_torque]",
        f"K_t per phase-current amplitude (Maxon/TQ datasheet style) = "
        f"{_g(frames.torque_constant_from_q(k, 'phase_peak', w))} N*m/A;  per line A rms = "
        f"{_g(frames.torque_constant_from_q(k, 'line_rms', w))} N*m/A",
        f"K_t as an amplitude-invariant drive reports it (ODrive, VESC: torque per its i_q, the amplitude of the "
        f"LINE currents it measures; --kt-frame drive_amplitude_invariant) = "
        f"{_g(frames.torque_constant_from_q(k, 'drive_amplitude_invariant', w))} N*m/A"
        + ("" if w == "wye" else " (delta: sqrt(3) below the per-phase-amplitude value; entering it as "
                                 "q_amplitude_invariant would make K_t^q sqrt(3) too small)"),
    ]
    if pole_pairs:
        psi_d = frames.flux_linkage_d_from_back_emf_constant_q(k, pole_pairs)
        lines.append(f"magnet flux linkage: psi_d = K_b^q/p = {_g(psi_d)}"
                     f" Wb (power-invariant d-axis); per winding peak psi_PM = "
                     f"{_g(psi_d * math.sqrt(2 / 3))} Wb "
                     "(amplitude-invariant drives' 'flux linkage')")
    return _Section("equivalent values in other frames (for drives and other datasheets)", lines)


# ------------------------------------------------------------------------------------------------
# Output
# ------------------------------------------------------------------------------------------------

def _param_lines(res: WindingResult, pole_pairs: Optional[int]) -> list[str]:
    out = [f"motor.winding           = {res.winding}"]
    if pole_pairs is not None:
        out.append(f"motor.pole_pairs        = {pole_pairs}")
    if res.r_phase is not None:
        out.append(f"motor.phase_resistance  = {_g(res.r_phase)} ohm")
    if res.l_q is not None:
        out.append(f"motor.q_inductance      = {_g(res.l_q)} H")
    if res.k_q is not None:
        out.append(f"motor.torque_constant_q = {_g(res.k_q)} N*m/A")
    return out


def yaml_snippet(res: WindingResult, pole_pairs: Optional[int], command: str = "") -> str:
    """ROS 2 parameter-file snippet with the motor.* q-axis parameters."""
    lines = []
    if command:
        lines.append(f"# generated by: {command}")
    lines += ["# q-axis model (power-invariant d-q of the winding quantities); units: ohm, H, N*m/A",
              "/**/bldc_actuator:", "  ros__parameters:", "    motor:", f"      winding: {res.winding}"]
    if pole_pairs is not None:
        lines.append(f"      pole_pairs: {int(pole_pairs)}")
    if res.r_phase is not None:
        lines.append(f"      phase_resistance: {yaml_scalar(float(res.r_phase))}")
    if res.l_q is not None:
        lines.append(f"      q_inductance: {yaml_scalar(float(res.l_q))}")
    if res.k_q is not None:
        lines.append(f"      torque_constant_q: {yaml_scalar(float(res.k_q))}")
    return "\n".join(lines) + "\n"


def _print_section(sec: _Section, out: TextIO) -> None:
    print(sec.title, file=out)
    for line in sec.lines:
        print(f"  {line}", file=out)


# ------------------------------------------------------------------------------------------------
# Verification on the abc circuit model
# ------------------------------------------------------------------------------------------------

def verify(res: WindingResult, a: argparse.Namespace, kv_frame: str, kb_frame: str,
           out: TextIO) -> bool:
    """Build an abc circuit from the q-axis result, measure the datasheet values on it, print the agreement.

    The circuit does not use the frames conversions: L_s = 3/4 L^q, M = -1/4 L^q (any split with
    L_s - M = L^q gives the same terminal behaviour), and the winding back-EMF amplitude is scaled until the
    circuit's torque per q-axis ampere (root of the sum of squared winding currents) equals K_t^q.
    Returns True if every quantity that was used agrees to 1e-6.
    """
    import numpy as np

    from . import abc_model as am

    w = res.winding
    p = a.pole_pairs or 1
    r = res.r_phase if res.r_phase is not None else 1.0
    lq = res.l_q if res.l_q is not None else 1e-4
    k = res.k_q if res.k_q is not None else 0.1
    th = np.linspace(0.0, 2 * np.pi, 96, endpoint=False)

    def amp(x):  # fundamental amplitude of samples over one electrical period
        return 2.0 * abs(np.sum(x * np.exp(-1j * th))) / len(th)

    def motor(k_phase):
        return am.AbcMotor(w, r, 0.75 * lq, -0.25 * lq, k_phase, p)

    def torque_per_q_ampere(m):
        ss = am.steady_state_winding_currents(m, 1.0, th, 0.0)
        return float(np.mean(ss.torque / np.sqrt(np.sum(ss.i_w ** 2, axis=0))))

    m = motor(k / torque_per_q_ampere(motor(1.0)))  # torque is linear in the back-EMF amplitude

    # measurements on the circuit
    k_ll, oc = am.measure_back_emf_ll(m, samples=len(th))
    omega_oc = float(oc.omega[0])
    kb_in = {"ll_peak": amp(oc.v_ll[0]), "phase_peak": amp(oc.v_w[0]),
             "q_power_invariant": float(np.mean(np.sqrt(np.sum(oc.v_w ** 2, axis=0))))}
    kb_in.update(ll_rms=kb_in["ll_peak"] / math.sqrt(2), phase_rms=kb_in["phase_peak"] / math.sqrt(2),
                 q_amplitude_invariant=kb_in["phase_peak"], bus=kb_in["ll_peak"])
    kb_in = {f: v / omega_oc for f, v in kb_in.items()}
    ss = am.steady_state_winding_currents(m, 1.0, th, 0.0)
    tau = float(np.mean(ss.torque))
    cur = {"phase_peak": amp(ss.i_w[0]), "line_peak": amp(ss.i_line[0]),
           "q_power_invariant": float(np.mean(np.sqrt(np.sum(ss.i_w ** 2, axis=0))))}
    cur.update(phase_rms=cur["phase_peak"] / math.sqrt(2), line_rms=cur["line_peak"] / math.sqrt(2),
               q_amplitude_invariant=cur["phase_peak"])

    rows = []  # (name, datasheet, circuit, unit, used)
    if a.terminal_resistance is not None:
        rows.append(("terminal resistance [DC, third lead open]", a.terminal_resistance,
                     am.measure_terminal_resistance(m), "ohm", True))
    if a.terminal_inductance is not None:
        rows.append(("terminal inductance [1 kHz, third lead open]", a.terminal_inductance,
                     am.measure_terminal_inductance(m), "H", True))
    for src in res.k_candidates:
        used = src == res.k_q_source
        if src.startswith("--kv"):
            rows.append((f"Kv ({kv_frame}) [open circuit]", a.kv,
                         60.0 / (2 * math.pi * kb_in[kv_frame]), "rpm/V", used))
        elif src.startswith("--kb"):
            rows.append((f"K_b ({kb_frame}) [open circuit]", a.kb, kb_in[kb_frame] / _KB_UNITS[a.kb_unit],
                         a.kb_unit, used))
        else:
            if a.kt_frame == "bus":
                kt = _kt_bus(m, th)
            elif a.kt_frame == "per_phase_amplitude":
                kt = float(np.max(np.abs(m.torque_coefficients(th)[0])))
            else:
                kt = tau / cur[a.kt_frame]
            rows.append((f"K_t ({a.kt_frame}) [torque / current]", a.kt, kt, "N*m/A", used))
    if a.bus_voltage is not None and res.k_q is not None:
        w_max = frames.no_load_speed_max(a.bus_voltage, res.k_q, w)
        duty = am.svpwm_duties(oc.u_terminals * (w_max / omega_oc), a.bus_voltage)
        rows.append((f"open-circuit V_ll peak at omega_max = {_g(w_max)} rad/s", a.bus_voltage,
                     kb_in["ll_peak"] * w_max, "V", True))
        rows.append(("SVPWM duty span at omega_max (1 = full)", 1.0, float(np.max(duty) - np.min(duty)), "", True))

    print(f"verify ({w}): abc circuit with R = {_g(r)} ohm, L_s = {_g(0.75 * lq)} H, M = {_g(-0.25 * lq)} H, "
          f"Kbar_b^phi = {_g(m.k_b_phase)} V*s/rad, p = {p}; measured on the circuit:", file=out)
    print(f"  {'quantity':52s} {'datasheet':>11s} {'circuit':>11s}  rel.err  unit", file=out)
    ok = True
    for name, ds, meas, unit, used in rows:
        err = abs(meas / ds - 1.0)
        flag = "" if used else ("  (not used: disagrees)" if err > AGREE_TOL else "  (not used)")
        if used and err > 1e-6:
            ok = False
            flag = "  MISMATCH"
        print(f"  {name:52s} {_g(ds):>11s} {_g(meas):>11s}  {err:.1e}  {unit}{flag}", file=out)
    print(f"  verdict: {'OK, the q-axis parameters reproduce the datasheet values' if ok else 'MISMATCH'}",
          file=out)
    return ok


def _kt_bus(m, th) -> float:
    """Torque per DC bus ampere of the circuit at full SVPWM modulation and (nearly) no load, lossless inverter."""
    import numpy as np

    from . import abc_model as am
    omega = 10.0
    ss = am.steady_state_winding_currents(m, 1e-9, th, omega)  # tiny current: no-load voltage, no losses
    v_bus = float(np.max(np.abs(ss.v_ll)))                     # full modulation: ll peak = V_bus
    i_bus = float(np.mean(am.bus_current(am.svpwm_duties(ss.u_terminals, v_bus), ss.i_line)))
    return float(np.mean(ss.torque)) / i_bus


# ------------------------------------------------------------------------------------------------
# Entry point
# ------------------------------------------------------------------------------------------------

def _check(a: argparse.Namespace) -> None:
    if a.kt is not None and a.kt_frame is None:
        raise _UsageError("--kt-frame", "required with --kt: the current the torque constant is per, one of "
                          + ", ".join(frames.TORQUE_CONSTANT_FRAMES))
    if a.kt_frame is not None and a.kt is None:
        raise _UsageError("--kt-frame", "given without --kt")
    if a.kb_frame is not None and a.kb is None:
        raise _UsageError("--kb-frame", "given without --kb")
    if a.kv_frame is not None and a.kv is None:
        raise _UsageError("--kv-frame", "given without --kv")
    if all(v is None for v in (a.terminal_resistance, a.terminal_inductance, a.kv, a.kt, a.kb)):
        raise _UsageError("--terminal-resistance/--terminal-inductance/--kv/--kt/--kb",
                          "nothing to convert: give at least one datasheet value")
    if a.yaml and a.winding == "unknown":
        raise _UsageError("--yaml", "needs --winding wye or delta (the parameters depend on it)")


def _command_line(a: argparse.Namespace) -> str:
    """The equivalent command line (for the YAML header)."""
    parts = ["bldc-actuator convert", f"--winding {a.winding}"]
    for opt in ("terminal_resistance", "terminal_inductance", "kv", "kv_frame", "kt", "kt_frame", "kb", "kb_frame",
                "pole_pairs", "bus_voltage"):
        v = getattr(a, opt)
        if v is not None:
            flag = "--" + opt.replace("_", "-")
            parts.append(f"{flag} {v:g}" if isinstance(v, float) else f"{flag} {v}")
    if a.kb is not None and a.kb_unit != "V*s/rad":
        parts.append(f"--kb-unit '{a.kb_unit}'")
    return " ".join(parts)


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run the conversion; returns the exit code (2 for bad input)."""
    out = out or sys.stdout
    try:
        _check(args)
    except _UsageError as exc:
        print(f"bldc-actuator convert: error: {exc}", file=sys.stderr)
        return 2
    kv_frame = args.kv_frame or "ll_peak"
    kb_frame = args.kb_frame or "ll_peak"
    general = []
    if args.kv is not None and args.kv_frame is None:
        general.append("--kv-frame not given: Kv read as no-load rpm per volt of line-to-line PEAK back-EMF "
                       "(the paper's reading, 1/Kbar_b^ll); if it is per volt rms use --kv-frame ll_rms "
                       "(K_t^q smaller by sqrt(2))")
    if args.kb is not None and args.kb_frame is None:
        general.append("--kb-frame not given: K_b read as line-to-line peak volts per rad/s; V/krpm datasheets "
                       "often mean ll rms (then use --kb-frame ll_rms)")
    windings = ("wye", "delta") if args.winding == "unknown" else (args.winding,)
    if args.winding == "unknown":
        general.append("winding unknown: both answers printed; R^phi, L^q differ by 3x and K_t^q from Kv/K_b^ll by "
                       "sqrt(3) between wye and delta. Identify it (paper appendix Winding Type identification: "
                       "ask the manufacturer, look for the neutral, or drive two leads with DC and use a thermal "
                       "camera: delta heats one winding 4x more than the other two)")

    print("bldc-actuator convert: datasheet -> q-axis model (power-invariant d-q of the winding quantities)",
          file=out)
    results = []
    for w in windings:
        res = _convert_winding(w, args, kv_frame, kb_frame)
        if args.bus_voltage is not None and res.k_q is not None:
            res.sections.append(_speed_section(w, res.k_q, args.bus_voltage, args.pole_pairs))
        extra = _extra_section(res, args.pole_pairs)
        if extra:
            res.sections.append(extra)
        results.append(res)
        print(f"\n== winding: {w} ==", file=out)
        for sec in res.sections:
            _print_section(sec, out)
        print(f"q-axis model parameters ({w}):", file=out)
        for line in _param_lines(res, args.pole_pairs):
            print(f"  {line}", file=out)

    if args.winding == "unknown":
        print("\nwinding-agnostic: tau = sqrt(3)/2 Kbar_b^ll Ibar^l (eq. kb_ll_torque) and omega_max = "
              "V_bus/Kbar_b^ll hold for both windings; terminal-frame products do not need the winding.", file=out)
    warnings = general + [w for res in results for w in res.warnings]
    if warnings:
        print("\nwarnings:", file=out)
        for wn in dict.fromkeys(warnings):
            print(f"  - {wn}", file=out)

    if args.yaml:
        text = yaml_snippet(results[0], args.pole_pairs, _command_line(args))
        try:
            with open(args.yaml, "w", encoding="utf-8") as fh:
                fh.write(text)
        except OSError as exc:
            print(f"bldc-actuator convert: error: argument --yaml: cannot write {args.yaml!r}: {exc}", file=sys.stderr)
            return 2
        print(f"\nwrote {args.yaml}", file=out)

    if args.verify:
        print("", file=out)
        ok = all([verify(res, args, kv_frame, kb_frame, out) for res in results])
        return 0 if ok else 1
    return 0
