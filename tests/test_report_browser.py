"""report.html as a person sees it: headless Chromium at 1400 and 800 px wide. No horizontal
overflow, no console or page error, every image loaded."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from test_report import make_run
from curate.report.run_report import write_html

pytestmark = pytest.mark.slow

PROBE = """<script>
window.__errs = [];
window.addEventListener('error', e => window.__errs.push(String(e.message || \
(e.target && (e.target.src || e.target.href)))), true);
const __ce = console.error; console.error = (...a) => { window.__errs.push(a.join(' ')); __ce(...a); };
window.addEventListener('load', () => {
  const imgs = [...document.images];
  const bad = imgs.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.alt || i.src.slice(0, 40));
  const wide = [...document.body.querySelectorAll('*')].filter(e => e.getBoundingClientRect().right > \
window.innerWidth + 1
      && !e.closest('.scroll')).map(e => e.tagName + '.' + e.className);
  const row = document.querySelector('table.renders tr:nth-child(2)');
  const cols = row ? [...row.querySelectorAll('td')].map(td => {
      const im = td.querySelector('img'); \
return [td.getBoundingClientRect().width, im ? im.getBoundingClientRect().width : 0]; }) : [];
  const r = {scroll: document.documentElement.scrollWidth, inner: window.innerWidth, images: imgs.length,
             bad: bad, errors: window.__errs, wide: wide.slice(0, 5), render_cols: cols};
  document.body.setAttribute('data-check', JSON.stringify(r));
});
</script>"""


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        p = shutil.which(name)
        if p:
            return p
    pytest.skip("no Chromium on this machine (Debian: apt-get install chromium; .ci/run installs it)")


def check_page(html: Path, width: int, shot: Path | None = None) -> dict:
    page = html.read_text()
    probe = html.with_name(f"probe_{width}.html")
    probe.write_text(page.replace("<head>", "<head>" + PROBE, 1))
    args = [chromium(), "--headless=new", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
            f"--window-size={width},1200", "--virtual-time-budget=8000"]
    out = subprocess.run(args + ["--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120).stdout
    start = out.index('data-check="') + len('data-check="')
    raw = out[start:out.index('"', start)].replace("&quot;", '"').replace("&amp;", "&")
    if shot is not None:
        subprocess.run(args + [f"--screenshot={shot}", html.as_uri()], capture_output=True, timeout=120)
    return json.loads(raw)


@pytest.mark.parametrize("width", [1400, 800])
def test_report_fits_the_window_loads_every_image_and_logs_no_error(tmp_path, width):
    run = make_run(tmp_path)
    html = write_html(run)
    r = check_page(html, width, tmp_path / f"report_{width}.png")
    assert r["images"] >= 10 and r["bad"] == [], r
    assert r["errors"] == [], r
    assert r["scroll"] <= r["inner"], r        # no horizontal scrolling of the page
    assert r["wide"] == [], r                  # nothing sticks out (the renders table scrolls in its own box)
    cells = [c for c, _ in r["render_cols"]]
    imgs = [i for _, i in r["render_cols"]]
    assert len(cells) == 5, r                   # held-out photo, selection, random, FVS, all
    assert max(cells) - min(cells) <= 2 and max(imgs) - min(imgs) <= 2, r   # no column looks favoured
