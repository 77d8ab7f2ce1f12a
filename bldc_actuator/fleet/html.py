"""``report.html``: one self-contained page (PNG plots inlined as base64) a maintenance engineer reads at a
glance: the alert list on top (actuator, parameter, what happened, the evidence, the projected limit date),
then failures and recordings with data issues, then per actuator one row of small multiples -- each tracked
parameter over time with its +-1 sigma bars, the nominal (reference) line and its tolerance band, the limit
when given, recordings with a data issue drawn hollow, and alerts in red."""

from __future__ import annotations

import base64
import datetime as dt
import html
import io
import math
from typing import Any

from .alerts import USABLE_STATUS

KIND_LABEL = {"off_nominal": "off nominal", "drifting": "drifting", "shifted": "shifted"}


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _fmt(x, digits: int = 4) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return html.escape(str(x)) if x is not None else "-"
    return f"{x:.{digits}g}" if math.isfinite(x) else "-"


def _f(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def actuator_figure(aid: str, rows: list[dict], series: dict[str, dict]):
    """Small multiples: one panel per tracked parameter of one actuator, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = sorted({r["parameter"] for r in rows})
    ncol = min(3, len(params))
    nrow = int(math.ceil(len(params) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.0 * nrow + 0.6), squeeze=False)
    for ax in axes.flat[len(params):]:
        ax.set_visible(False)
    for ax, par in zip(axes.flat, params):
        rs = sorted((r for r in rows if r["parameter"] == par), key=lambda r: r["start_time"])
        t = [dt.datetime.fromisoformat(r["start_time"]) for r in rs]
        v = [_f(r["value"]) for r in rs]
        u = [_f(r["uncertainty"]) if math.isfinite(_f(r["uncertainty"])) else 0.0 for r in rs]
        rec = series.get(par, {})
        alert = bool(rec.get("alert"))
        color = "tab:red" if alert else "tab:blue"
        ref = _f(rec.get("reference", rs[0].get("nominal") if rs else float("nan")))
        if math.isfinite(ref):
            tol = _f(rec.get("tolerance", float("nan")))
            ax.axhline(ref, color="0.3", ls="--", lw=1, label=rec.get("reference_kind", "nominal"))
            if math.isfinite(tol) and tol > 0:
                ax.axhspan(ref - tol * abs(ref), ref + tol * abs(ref), color="0.5", alpha=0.12, label="tolerance")
        lim = (rec.get("limit") or {}).get("limit")
        if lim is not None:
            ax.axhline(lim, color="tab:red", ls=":", lw=1.2, label="limit")
        off = set((rec.get("off_nominal") or {}).get("recordings_off", []))
        for ti, vi, ui, r in zip(t, v, u, rs):
            hollow = r.get("status") == "warning"
            c = "tab:red" if r["start_time"] in off else color
            ax.errorbar([ti], [vi], yerr=[ui], fmt="o", ms=4, color=c, mfc="white" if hollow else c,
                        ecolor="0.35", lw=1.0, capsize=2)
        line = (rec.get("drift") or {}).get("line")
        if line:
            ax.plot([dt.datetime.fromisoformat(x) for x, _ in line], [y for _, y in line], color=color, lw=0.8,
                    alpha=0.6)
        unit = rs[0].get("unit", "") if rs else ""
        title = par.replace("_", " ")
        if alert:
            title = "ALERT " + ", ".join(KIND_LABEL.get(k, k) for k in rec.get("kinds", [])) + "\n" + title
        ax.set_title(title, fontsize=10, color="tab:red" if alert else "black")
        ax.set_ylabel(unit, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.ticklabel_format(axis="y", useOffset=False)
        ax.grid(alpha=0.3)
        for lab in ax.get_xticklabels():
            lab.set_rotation(30)
            lab.set_ha("right")
    first = axes.flat[0]
    if first.get_legend_handles_labels()[0]:
        first.legend(fontsize=8, loc="best")
    fig.suptitle(aid, fontsize=12)
    fig.tight_layout()
    return fig


def verdicts(rows: list[dict]) -> dict[str, dict[str, int]]:
    """parameter -> {diagnose's verdict (accepted, rejected, suspected, not identifiable, ...): recordings}."""
    out: dict[str, dict[str, int]] = {}
    for r in rows:
        d = str(r.get("diagnosis") or "")
        if d:
            head = d.split(":", 1)[0].strip()
            c = out.setdefault(r["parameter"], {})
            c[head] = c.get(head, 0) + 1
    return out


def _alert_rows(alerts: list[dict]) -> list[str]:
    e = html.escape
    out = ["<table><tr><th>actuator</th><th>parameter</th><th>alert</th><th>first</th><th>last</th>"
           "<th>reference</th><th>rate / day</th><th>limit</th><th>recordings</th><th>evidence</th></tr>"]
    for a in alerts:
        f, l_ = a["first"], a["last"]
        lim = a.get("limit") or {}
        if lim.get("reached"):
            lim_s = f"{_fmt(lim['limit'])}: reached {e(lim['reached_at'][:10])}"
        elif lim.get("projected_date"):
            lim_s = (f"{_fmt(lim['limit'])}: {e(lim['projected_date'][:10])} "
                     f"({e((lim.get('projected_date_early') or '-')[:10])} .. "
                     f"{e((lim.get('projected_date_late') or 'never')[:10])})")
        else:
            lim_s = _fmt(lim.get("limit")) if lim else ""
        recs = "<br>".join(e(p.rsplit("/", 2)[-1] if "/" in p else p) for p in a["recordings"])
        out.append(
            f"<tr class='alert'><td>{e(a['actuator_id'])}{(' [' + e(a['joint']) + ']') if a['joint'] else ''}</td>"
            f"<td>{e(a['parameter'])} [{e(a['unit'])}]</td>"
            f"<td><b>{e(', '.join(KIND_LABEL.get(k, k) for k in a['kinds']))}</b></td>"
            f"<td>{_fmt(f['value'])} ± {_fmt(f['sd'], 2)}<br><small>{e(f['start_time'][:16])}</small></td>"
            f"<td>{_fmt(l_['value'])} ± {_fmt(l_['sd'], 2)}<br><small>{e(l_['start_time'][:16])}</small></td>"
            f"<td>{_fmt(a['reference'])} ({e(a['reference_kind'])})</td>"
            f"<td>{_fmt(a.get('rate_per_day'), 3)} ± {_fmt(a.get('rate_se_per_day'), 2)}</td>"
            f"<td>{lim_s}</td><td class='recs'><small>{recs}</small></td><td><small>{e(a['message'])}</small></td></tr>")
    out.append("</table>")
    return out


def write(path, rows: list[dict], ev: dict[str, Any], failures: list[dict], summary: dict[str, Any]) -> None:
    import matplotlib.pyplot as plt

    series: dict[str, dict[str, dict]] = {}
    for rec in ev["series"]:
        series.setdefault(rec["actuator_id"], {})[rec["parameter"]] = rec
    by_act: dict[str, list[dict]] = {}
    for r in rows:
        if r.get("source") == "tracked" and r.get("status") in USABLE_STATUS:
            by_act.setdefault(r["actuator_id"], []).append(r)
    opt = ev.get("options", {})
    e = html.escape
    alerts = ev["alerts"]
    out = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>Fleet diagnosis</title>",
           "<style>body{font-family:sans-serif;margin:1.5em;max-width:80em}table{border-collapse:collapse;"
           "font-size:0.85em}td,th{border:1px solid #ccc;padding:2px 6px;vertical-align:top}.alert{color:#b00}"
           ".ok{color:#070}td.recs{white-space:nowrap}img{max-width:100%}</style></head><body>",
           "<h1>Fleet diagnosis</h1>",
           f"<h2 class='{'alert' if alerts else 'ok'}'>Alerts: {len(alerts)}</h2>"]
    out += _alert_rows(alerts) if alerts else ["<p class='ok'>No actuator needs attention.</p>"]
    out.append(
        f"<p><small>{summary.get('files', 0)} files, {summary.get('recordings', 0)} recording x joint, "
        f"{len({f['recording'] for f in failures})} file(s) failed, {summary.get('recordings_with_data_issues', 0)} "
        f"with data issues; {summary.get('seconds', 0):.1f} s on {summary.get('workers', '?')} worker(s) "
        f"({e(str(summary.get('scheduler', '')))}). Off nominal: the latest value more than the tolerance "
        f"({100 * opt.get('default_tolerance', 0.1):.0f} % unless set per parameter) and more than "
        f"{opt.get('k_sigma', 5):g} combined sd from the {e(opt.get('reference', 'nominal'))}; drifting: weighted "
        f"straight line through the recordings' values and their sd, false-alarm rate {opt.get('alpha', 1e-3):g} "
        f"per actuator and parameter; shifted: baseline vs recent median (>= 8 recordings).</small></p>")
    out.append(f"<h2>Failures ({len(failures)})</h2>")
    if failures:
        out.append("<table><tr><th>recording</th><th>joint</th><th>stage</th><th>error</th></tr>")
        for f in failures:
            out.append(f"<tr><td>{e(f['recording'])}</td><td>{e(str(f.get('joint', '')))}</td><td>{e(f['stage'])}</td>"
                       f"<td>{e(f['error'][:400])}</td></tr>")
        out.append("</table>")
    else:
        out.append("<p>none</p>")
    issues: dict[tuple[str, str], tuple[str, bool]] = {}
    for r in rows:
        if r.get("data_issues"):
            k = (r["recording"], str(r.get("joint") or ""))
            issues[k] = (r["data_issues"], issues.get(k, ("", False))[1] or r.get("status") == "warning")
    warned = sorted(k for k, (_, w) in issues.items() if w)
    other = [k for k in sorted(issues) if not issues[k][1]]
    out.append(f"<h2>Data issues ({len(warned)} recording(s) with a warning, {len(other)} with remarks only)</h2>")
    if warned:
        out.append("<table><tr><th>recording</th><th>joint</th><th>issues (values kept, status warning)</th></tr>")
        for k in warned:
            out.append(f"<tr><td>{e(k[0])}</td><td>{e(k[1])}</td><td>{e(issues[k][0][:600])}</td></tr>")
        out.append("</table>")
    else:
        out.append("<p>no recording with a warning</p>")
    if other:
        kinds: dict[str, int] = {}
        for k in other:
            for part in issues[k][0].split(" | "):
                head = part.split(":", 1)[0]
                kinds[head] = kinds.get(head, 0) + 1
        out.append("<p><small>remarks (no effect on the values): " +
                   ", ".join(f"{e(h)} in {n} recording(s)" for h, n in sorted(kinds.items())) +
                   "; every one in the table's data_issues column</small></p>")
    out.append("<h2>Actuators</h2><p><small>value ± 1 sd per recording; dashed: reference, grey band: tolerance, "
               "dotted red: limit; hollow: a recording with a data issue; red: alert.</small></p>")
    alerted = {a["actuator_id"] for a in alerts}
    for aid in sorted(by_act, key=lambda a: (a not in alerted, a)):
        fig = actuator_figure(aid, by_act[aid], series.get(aid, {}))
        out.append(f"<h3 id='{e(aid)}' class='{'alert' if aid in alerted else ''}'>{e(aid)}</h3>"
                   f"<img alt='{e(aid)}' src='data:image/png;base64,{_png(fig)}'>")
        plt.close(fig)
        said = verdicts(by_act[aid])
        if said:
            out.append("<p><small>what diagnose said: " + "; ".join(
                f"{e(par)}: " + ", ".join(f"{e(v)} in {n}" for v, n in sorted(c.items()))
                for par, c in sorted(said.items())) + f" (of {len({r['recording'] for r in by_act[aid]})} "
                "recordings)</small></p>")
    out.append("</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(out))
