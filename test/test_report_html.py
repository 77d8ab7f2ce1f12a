"""The fleet's report.html in a real headless browser (Debian's ``chromium``): it loads without console errors
or JavaScript exceptions, and the content a maintenance engineer reads rendered (the alert table's rows, one
figure per actuator, decoded by the browser at its drawn size). Skips, saying why, where chromium is absent
(``.ci/run`` installs it in CI)."""

from __future__ import annotations

import datetime as dt
import re
import shutil
import subprocess
from html.parser import HTMLParser

import pytest

pytest.importorskip("matplotlib")

from bldc_actuator.fleet import alerts as A  # noqa: E402
from bldc_actuator.fleet import html as H  # noqa: E402

CHROMIUM = next((p for p in (shutil.which(n) for n in ("chromium", "chromium-browser")) if p), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium; "
                                                          ".ci/run installs it when CI=true)")

T0 = dt.datetime(2026, 1, 1, 8, tzinfo=dt.timezone.utc)
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-extensions", "--allow-file-access-from-files"]


def _rows(aid, parameter, unit, values, nominal, sd):
    return [{"recording": f"/logs/{aid}/2026-01-0{d + 1}.mcap", "joint": "", "actuator_id": aid,
             "start_time": (T0 + dt.timedelta(days=d)).isoformat(), "source": "tracked", "effect": parameter,
             "parameter": parameter, "value": v, "uncertainty": sd, "unit": unit, "nominal": nominal,
             "status": "warning" if (aid, d) == ("robot2/hip", 1) else "ok", "params_file": "p.yaml",
             "diagnosis": "accepted: coulomb_friction" if parameter == "coulomb_friction" else "",
             "data_issues": "outlier: 3 samples" if (aid, d) == ("robot2/hip", 1) else ""}
            for d, v in enumerate(values)]


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A small fleet: one actuator whose friction creeps (alerted), one stable, three parameters each."""
    rows = (_rows("robot1/knee", "coulomb_friction", "N*m", [0.030, 0.034, 0.039, 0.044, 0.049], 0.03, 0.0008)
            + _rows("robot1/knee", "torque_constant_q", "N*m/A", [0.0743, 0.0744, 0.0742, 0.0743, 0.0743], 0.0743,
                    2e-4)
            + _rows("robot1/knee", "phase_resistance", "ohm", [227.34075, 227.34076, 227.34074, 227.34075,
                                                               227.34075], 227.34075, 1e-5)
            + _rows("robot2/hip", "coulomb_friction", "N*m", [0.0301, 0.0299, 0.0300, 0.0302, 0.0300], 0.03, 0.0008)
            + _rows("robot2/hip", "torque_constant_q", "N*m/A", [0.0743, 0.0742, 0.0744, 0.0743, 0.0743], 0.0743,
                    2e-4))
    ev = A.evaluate(rows, A.Options(limits={"coulomb_friction": 0.06}))
    out = tmp_path_factory.mktemp("fleet_html")
    path = out / "report.html"
    H.write(path, rows, ev, [{"recording": "/logs/robot3/broken.mcap", "joint": "", "stage": "load",
                              "error": "not an MCAP file"}],
            {"files": 11, "recordings": 10, "recordings_with_data_issues": 1, "seconds": 12.5, "workers": 1,
             "scheduler": "local"})
    return path, ev


def _chromium(tmp_path, *args, timeout=180):
    profile = tmp_path / "chromium-profile"
    cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


class _Dom(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows, self.alert_rows, self.images, self.h3 = 0, 0, [], []
        self._in_h3 = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "tr":
            self.rows += 1
            self.alert_rows += a.get("class") == "alert"
        elif tag == "img":
            self.images.append(a)
        elif tag == "h3":
            self._in_h3 = True

    def handle_endtag(self, tag):
        self._in_h3 = self._in_h3 and tag != "h3"

    def handle_data(self, data):
        if self._in_h3 and data.strip():
            self.h3.append(data.strip())


#: a page script's own result, written into the DOM after load: every <img> decoded at a non-zero size
PROBE = ("<script>addEventListener('load',()=>{const i=[...document.images];document.body.setAttribute("
         "'data-probe',i.length+':'+i.filter(x=>x.complete&&x.naturalWidth>200&&x.naturalHeight>100)"
         ".length)})</script>")


def test_report_html_renders_in_chromium_without_console_errors(report, tmp_path):
    path, ev = report
    probed = tmp_path / "probed.html"
    probed.write_text(path.read_text().replace("</body>", PROBE + "</body>"))
    res = _chromium(tmp_path, "--enable-logging=stderr", "--v=0", "--virtual-time-budget=5000", "--dump-dom",
                    probed.as_uri())
    assert res.returncode == 0, res.stderr[-2000:]
    # console messages and uncaught exceptions reach stderr as "CONSOLE(...)" / ":CONSOLE:" lines
    console = [ln for ln in res.stderr.splitlines() if "CONSOLE" in ln]
    assert not console, console
    assert "Uncaught" not in res.stderr
    dom = _Dom()
    dom.feed(res.stdout)
    assert dom.alert_rows == len(ev["alerts"]) >= 1                 # the friction creep, and only it
    assert dom.h3 == ["robot1/knee", "robot2/hip"]                   # alerted actuator first
    assert len(dom.images) == 2
    m = re.search(r'data-probe="(\d+):(\d+)"', res.stdout)
    assert m and m.group(1) == m.group(2) == "2", m and m.group(0)  # both figures decoded at their size


def test_report_html_screenshot(report, tmp_path):
    """The page drawn: a PNG of a plausible size (looked at by a person when the page changes)."""
    path, _ = report
    shot = tmp_path / "report.png"
    res = _chromium(tmp_path, "--window-size=1280,2000", "--hide-scrollbars", f"--screenshot={shot}",
                    path.as_uri())
    assert res.returncode == 0, res.stderr[-2000:]
    assert shot.exists() and shot.stat().st_size > 20_000
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_console_check_sees_a_page_error(tmp_path):
    """The check above can fail: a page that logs an error and throws shows both on chromium's stderr."""
    bad = tmp_path / "bad.html"
    bad.write_text("<html><body><script>console.error('boom'); throw new Error('bad')</script></body></html>")
    res = _chromium(tmp_path, "--enable-logging=stderr", "--v=0", "--virtual-time-budget=2000", "--dump-dom",
                    bad.as_uri())
    console = [ln for ln in res.stderr.splitlines() if "CONSOLE" in ln]
    assert any("boom" in ln for ln in console) and "Uncaught" in res.stderr, res.stderr[-2000:]
