"""``report.html``: one self-contained page (PNG plots inlined as base64) with the alerts, the failures,
and per actuator one panel per tracked parameter over time (value +- 1 sigma, baseline median and the
band the trend test tolerates, alerts in red)."""

from __future__ import annotations

import base64
import datetime as dt
import html
import io
import math
from typing import Any


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _fmt(x, digits: int = 4) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return html.escape(str(x))
    return f"{x:.{digits}g}" if math.isfinite(x) else "-"


def actuator_figure(aid: str, rows: list[dict], tested: dict[str, dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    params = sorted({r["parameter"] for r in rows})
    fig, axes = plt.subplots(len(params), 1, figsize=(8, 1.9 * len(params) + 0.6), sharex=True, squeeze=False)
    for ax, par in zip(axes[:, 0], params):
        rs = sorted((r for r in rows if r["parameter"] == par), key=lambda r: r["start_time"])
        t = [dt.datetime.fromisoformat(r["start_time"]) for r in rs]
        v = [float(r["value"]) for r in rs]
        u = [float(r["uncertainty"]) if math.isfinite(float(r["uncertainty"])) else 0.0 for r in rs]
        res = tested.get(par, {})
        color = "tab:red" if res.get("alert") else "tab:blue"
        ax.errorbar(t, v, yerr=u, fmt="o", ms=3, color=color, ecolor="0.6", lw=0.8)
        if rs:
            ax.axhline(float(rs[0]["nominal"]), color="0.5", ls=":", lw=1, label="nominal")
        if res.get("tested"):
            mb = res["baseline_median"]
            half = res["z_critical"] * math.hypot(res["scatter"], res["median_uncertainty"]) * \
                math.sqrt(math.pi / 2) * math.sqrt(1 / res["n_baseline"] + 1 / res["n_recent"])
            ax.axhline(mb, color="tab:green", lw=1, label="baseline median")
            ax.axhspan(mb - half, mb + half, color="tab:green", alpha=0.12, label="no-alert band (recent median)")
        ax.set_ylabel(f"{par}\n[{rs[0]['unit'] if rs else ''}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if res.get("alert"):
            ax.set_title(f"ALERT: {par} {100 * res['relative_change']:+.1f} %, z = {res['z']:.1f}", fontsize=8,
                         color="tab:red")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle(aid, fontsize=10)
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig


def write(path, rows: list[dict], trend: dict[str, Any], failures: list[dict], summary: dict[str, Any]) -> None:
    import matplotlib.pyplot as plt

    tested: dict[str, dict[str, dict]] = {}
    for rec in trend["tested"]:
        tested.setdefault(rec["actuator_id"], {})[rec["parameter"]] = rec
    by_act: dict[str, list[dict]] = {}
    for r in rows:
        if r.get("source") == "tracked" and r.get("status") == "ok":
            by_act.setdefault(r["actuator_id"], []).append(r)
    e = html.escape
    out = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>Fleet diagnosis</title>",
           "<style>body{font-family:sans-serif;margin:1.5em;max-width:70em}table{border-collapse:collapse;"
           "font-size:0.85em}td,th{border:1px solid #ccc;padding:2px 6px}.alert{color:#b00}</style></head><body>",
           "<h1>Fleet diagnosis</h1>",
           f"<p>{summary.get('files', 0)} files, {summary.get('recordings', 0)} recording x joint, "
           f"{len({f['recording'] for f in failures})} file(s) with failures; "
           f"{summary.get('seconds', 0):.1f} s on {summary.get('workers', '?')} worker(s) "
           f"({e(str(summary.get('scheduler', '')))}). Trend test: robust z of the recent vs baseline median, "
           f"false-alarm rate {trend.get('alpha', 0.001):g} per actuator and parameter.</p>",
           f"<h2>Alerts ({len(trend['alerts'])})</h2>"]
    if trend["alerts"]:
        out.append("<table><tr><th>actuator</th><th>parameter</th><th>baseline</th><th>recent</th><th>change</th>"
                   "<th>z / critical</th><th>Theil-Sen slope per 30 d [95 %]</th><th>shape</th></tr>")
        for a in trend["alerts"]:
            out.append(f"<tr class='alert'><td>{e(a['actuator_id'])}</td><td>{e(a['parameter'])} [{e(a['unit'])}]</td>"
                       f"<td>{_fmt(a['baseline_median'])}</td><td>{_fmt(a['recent_median'])}</td>"
                       f"<td>{100 * a['relative_change']:+.1f} %</td><td>{a['z']:.1f} / {a['z_critical']:.2f}</td>"
                       f"<td>{_fmt(a.get('slope_per_30d'))} [{_fmt(a.get('slope_low_per_30d'))}, "
                       f"{_fmt(a.get('slope_high_per_30d'))}]</td><td>{e(a.get('shape', ''))}</td></tr>")
        out.append("</table>")
    else:
        out.append("<p>none</p>")
    out.append(f"<h2>Failures ({len(failures)})</h2>")
    if failures:
        out.append("<table><tr><th>recording</th><th>joint</th><th>stage</th><th>error</th></tr>")
        for f in failures:
            out.append(f"<tr><td>{e(f['recording'])}</td><td>{e(str(f.get('joint', '')))}</td><td>{e(f['stage'])}</td>"
                       f"<td>{e(f['error'][:400])}</td></tr>")
        out.append("</table>")
    else:
        out.append("<p>none</p>")
    out.append("<h2>Actuators</h2>")
    for aid in sorted(by_act):
        fig = actuator_figure(aid, by_act[aid], tested.get(aid, {}))
        out.append(f"<h3 id='{e(aid)}'>{e(aid)}</h3><img alt='{e(aid)}' src='data:image/png;base64,{_png(fig)}'>")
        plt.close(fig)
    out.append("</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(out))
