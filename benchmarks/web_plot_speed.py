"""How long the web pages' plot takes to draw as a live test grows, in headless Chromium.

The live page appends every new sample to its arrays and redraws at most every 40 ms, so
each draw must stay short however long the test has run. This loads the shipped ``plot.js``
and ``uplot.js`` into a blank page, grows a voltage series like a 10 Hz test (with the
cutoff line, as the live page draws it) and times ``LinePlot.draw`` at each length: the
first draw (the chart is built) and the median of the following ones (the data swapped),
also while zoomed into the first tenth. Needs Debian's chromium and chromium-driver and
selenium (``make browser``; the `test` extra).

Usage: python benchmarks/web_plot_speed.py [--points 10000,100000,500000] [--repeats 15]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE))

from _machine import machine_line  # noqa: E402

STATIC = HERE.parent / "src" / "dischargelab" / "web" / "static"

PAGE = """<!DOCTYPE html><html><head><meta charset="utf-8">
<link rel="stylesheet" href="{static}/uplot.css"><link rel="stylesheet" href="{static}/app.css">
<script src="{static}/uplot.js"></script><script src="{static}/plot.js"></script></head>
<body><main><div class="card"><canvas id="plot" class="plot"></canvas></div></main></body></html>
"""

MEASURE = """
const n = arguments[0], repeats = arguments[1], zoom = arguments[2];
const done = arguments[arguments.length - 1];
(async () => {
const t = new Array(n), v = new Array(n);
for (let i = 0; i < n; i++) { t[i] = i / 10; v[i] = 8.4 - 2.2 * Math.pow(i / n, 3) - 0.3 * i / n; }
const plot = new LinePlot(document.getElementById("plot"),
                          {xTime: true, yLabel: "pack voltage [V]"});
const spec = () => ({series: [{x: t, y: v, color: "#2563eb", label: "pack voltage"}],
                     hlines: [{y: 6.0, color: "#dc2626", label: "cutoff 6.00 V"}]});
let t0 = performance.now();
plot.draw(spec());
await Promise.resolve();                      // uPlot draws in a microtask after the call
const first = performance.now() - t0;
if (zoom) plot.u.setScale("x", {min: 0, max: t[Math.floor(n / 10)]});
await new Promise(resolve => setTimeout(resolve, 50));         // uPlot commits the zoom
const times = [];
for (let k = 0; k < repeats; k++) {
  t.push(t[t.length - 1] + 0.1); v.push(v[v.length - 1] - 1e-5);
  t0 = performance.now();
  plot.draw(spec());
  await Promise.resolve();
  times.push(performance.now() - t0);
}
times.sort((a, b) => a - b);
done({first: first, median: times[Math.floor(times.length / 2)], max: times[times.length - 1],
      zoomed: plot.zoomed});
})();
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", default="10000,100000,500000",
                        help="series lengths to time (comma list)")
    parser.add_argument("--repeats", type=int, default=15, help="draws timed per length")
    args = parser.parse_args()
    lengths = [int(x) for x in args.points.split(",")]

    from web_helpers import Browser

    browser = Browser()
    version = browser.driver.capabilities.get("browserVersion", "?")
    rows = []
    try:
        with tempfile.TemporaryDirectory() as folder:
            page = Path(folder) / "plot.html"
            page.write_text(PAGE.format(static=STATIC.as_uri()), encoding="utf-8")
            for n in lengths:
                for zoom in (False, True):
                    browser.get(page.as_uri())
                    browser.wait_for("!!(window.LinePlot && window.uPlot)", what="the scripts")
                    browser.driver.set_script_timeout(120)
                    got = browser.driver.execute_async_script(MEASURE, n, args.repeats, zoom)
                    assert got["zoomed"] == zoom
                    rows.append((n, "zoomed into the first tenth" if zoom else "whole run",
                                 got["first"], got["median"], got["max"]))
    finally:
        browser.quit()

    print("LinePlot.draw in headless Chromium (uPlot), a voltage series growing one sample "
          "per draw\n")
    print("| samples | view | first draw (chart built) [ms] | next draws, median [ms] "
          "| next draws, max [ms] |")
    print("|---:|---|---:|---:|---:|")
    for n, view, first, median, worst in rows:
        print(f"| {n:,} | {view} | {first:.1f} | {median:.1f} | {worst:.1f} |")
    print("\nBudget: a draw well under the live page's 40 ms between draws (10 Hz test: "
          "36,000 samples an hour).")
    print(f"Machine: {machine_line()}; Chromium {version}; load average "
          f"{os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
