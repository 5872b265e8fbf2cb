// dischargelab: line and point plots you can zoom, pan and read, drawn by uPlot 1.6.32
// (uplot.js and uplot.css beside this file, MIT: uplot-LICENSE and NOTICE).
//
// new LinePlot(element, {xLabel, yLabel, xTime, yPad}).draw({
//   series: [{x, y, color, label, width, dash, points, hollow, radius, yFit}],
//   bands: [{x, lo, hi, color, yFit}], hlines: [{y, color, label}], vlines: [{x, color, label}],
//   xMin, yMin, empty})
// element: the <canvas class="plot"> of a page (replaced by the chart, same id and classes)
// or that chart again; a new LinePlot on it replaces the old one. A series or band with
// yFit: false does not widen the y axis. Drawing again with the same kind of series only
// swaps the data (cheap: the live page appends points several times a second) and keeps
// the reader's zoom.
// Reading: the legend shows every series' last value, and hovering its value at the cursor; drag selects a range to zoom in,
// the wheel zooms at the cursor, shift + drag pans, a double click shows everything again.
"use strict";

(function (global) {
  const TIME_STEPS = [0.1, 0.2, 0.5, 1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600,
                      7200, 10800, 21600, 43200, 86400];
  const ZOOM_STEP = 0.8;        // the wheel's zoom per notch

  function finite(v) { return v !== null && v !== undefined && isFinite(v); }

  function extent(values, acc) {
    for (let i = 0; i < values.length; i++) {
      const v = values[i];
      if (!finite(v)) continue;
      if (v < acc[0]) acc[0] = v;
      if (v > acc[1]) acc[1] = v;
    }
    return acc;
  }

  // What is known of an x array: strictly increasing? its extent. The live page only
  // appends to its arrays, so a draw scans the new samples alone.
  const SCANNED = new WeakMap();

  function scan(x) {
    let known = SCANNED.get(x);
    if (!known || known.n > x.length) known = {n: 0, increasing: true, range: [Infinity, -Infinity]};
    const range = known.range;
    for (let i = known.n; i < x.length; i++) {
      const v = x[i];
      if (!(i === 0 ? finite(v) : v > x[i - 1])) known.increasing = false;
      if (!finite(v)) continue;
      if (v < range[0]) range[0] = v;
      if (v > range[1]) range[1] = v;
    }
    known.n = x.length;
    SCANNED.set(x, known);
    return known;
  }

  function increasing(x) { return x.length > 0 && scan(x).increasing && finite(x[x.length - 1]); }

  function num(v, span) {
    if (!finite(v)) return MISSING;
    const scale = Math.abs(span || v) || 1;
    const digits = Math.max(0, Math.min(6, 3 - Math.floor(Math.log10(scale))));
    return Number(v).toFixed(digits);
  }

  const MISSING = "-";                  // formatting.py's mark for no value (DL.MISSING)
  const AXIS_FONT = "12px system-ui, sans-serif";
  const AXIS_LABEL_FONT = "bold 12px system-ui, sans-serif";
  const LABEL_PX = 12, MIN_LABEL_PX = 9;
  const X_AXIS_ROOM = 90;               // the x axis, its label and a margin [px]: not y's room

  function textWidth(text, font) {
    if (!measurer) measurer = document.createElement("canvas").getContext("2d");
    measurer.font = font;
    return measurer.measureText(String(text || "")).width;
  }

  // an axis label's font, smaller (down to MIN_LABEL_PX) when the label is longer than its room
  function labelFont(text, room) {
    const width = textWidth(text, AXIS_LABEL_FONT);
    const px = width > room ? Math.max(MIN_LABEL_PX, Math.floor(LABEL_PX * room / width)) : LABEL_PX;
    return "bold " + px + "px system-ui, sans-serif";
  }

  function lastValue(values) {
    if (!values) return null;
    for (let i = values.length - 1; i >= 0; i--) if (finite(values[i])) return values[i];
    return null;
  }

  let measurer = null;                  // a canvas context that measures text

  // the y axis as wide as its widest tick value (uPlot's fixed size cuts long ones off)
  function fitValues(u, values, axisIdx, cycleNum) {
    const axis = u.axes[axisIdx];
    if (cycleNum > 1) return axis._size;              // settled: keep the width found
    let widest = 0;
    for (const v of values || []) if (v) widest = Math.max(widest, textWidth(v, AXIS_FONT));
    return Math.ceil(widest) + (axis.ticks.size || 10) + (axis.gap || 5) + 8;
  }

  function clock(seconds, step) {
    const sign = seconds < 0 ? "-" : "";
    let s = Math.abs(seconds);
    const h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60;
    s -= 3600 * h + 60 * m;
    const sec = step < 1 ? s.toFixed(1).padStart(4, "0") : String(Math.round(s)).padStart(2, "0");
    return sign + (h ? h + ":" + String(m).padStart(2, "0") : String(m)) + ":" + sec;
  }

  class LinePlot {
    constructor(element, opts) {
      this.opts = Object.assign({xLabel: "", yLabel: "", xTime: false, yPad: 0.05}, opts || {});
      this.draws = 0;
      this.u = null;
      this.key = null;
      this.spec = {};
      this.zoomed = false;
      const old = element.__dlPlot;
      if (old) old.destroy();
      if (element.tagName === "CANVAS") {            // the page's placeholder: take its place
        const box = document.createElement("div");
        box.id = element.id;
        box.className = element.className + " plot-box";
        box.dataset.height = String(Math.round(element.getBoundingClientRect().height) || 300);
        element.replaceWith(box);
        element = box;
      }
      this.box = element;
      this.height = Number(element.dataset.height) || 300;
      element.replaceChildren();
      this.message = document.createElement("p");
      this.message.className = "plot-empty muted";
      this.message.hidden = true;
      element.append(this.message);
      element.__dlPlot = this;
      if (global.ResizeObserver) {
        this.resizer = new ResizeObserver(() => {
          if (this.u && this.box.clientWidth && this.box.clientWidth !== this.u.width) {
            this.u.setSize({width: this.box.clientWidth, height: this.height});
          }
        });
        this.resizer.observe(element);
      }
    }

    destroy() {
      if (this.resizer) this.resizer.disconnect();
      if (this.u) this.u.destroy();
      this.u = null;
    }

    // ---- data: monotonic series go to uPlot (joined on one x axis), the rest is drawn over it
    _prepare(spec) {
      const series = (spec.series || []).filter(s => s.x && s.x.length);
      const plotted = [], overlay = [];
      for (const s of series) (increasing(s.x) ? plotted : overlay).push(s);
      const xr = [Infinity, -Infinity];
      for (const s of series) extent(scan(s.x).range, xr);
      for (const b of spec.bands || []) extent(b.x, xr);
      for (const l of spec.vlines || []) if (finite(l.x)) extent([l.x], xr);
      if (spec.xMin !== undefined && isFinite(xr[0])) xr[0] = Math.min(xr[0], spec.xMin);
      if (isFinite(xr[0]) && series.some(s => s.points)) {       // keep markers off the frame
        const pad = (xr[1] - xr[0] || 1) * 0.04;
        xr[0] -= pad; xr[1] += pad;
      }
      let data;
      const dataMin = plotted.length ? Math.min(...plotted.map(s => s.x[0])) : Infinity;
      const dataMax = plotted.length ? Math.max(...plotted.map(s => s.x[s.x.length - 1])) : -Infinity;
      const extra = [xr[0], xr[1]].filter(v => isFinite(v) && (v < dataMin || v > dataMax));
      if (plotted.length === 1 && !extra.length) {
        data = [plotted[0].x, plotted[0].y];                   // the live page: no copy
      } else if (plotted.length || extra.length) {
        const tables = plotted.map(s => [s.x, s.y.map(v => (finite(v) ? v : null))]);
        if (extra.length) tables.push([extra.sort((a, b) => a - b), extra.map(() => null)]);
        data = global.uPlot.join(tables);
      } else {
        data = null;
      }
      return {plotted, overlay, data, extent: xr, hasExtent: extra.length > 0};
    }

    _structure(prep) {
      return JSON.stringify([prep.plotted.map(s => [s.label, s.color, s.width, s.dash, s.points,
                                                   s.hollow, s.radius, s.yFit]),
                             prep.hasExtent]);
    }

    // ---- the y range: the data on screen (yFit series), fitted bands, lines, yMin, padding
    _yRange(u, lo, hi) {
      const spec = this.spec;
      const yr = [finite(lo) ? lo : Infinity, finite(hi) ? hi : -Infinity];
      for (const s of this.prep.overlay) if (s.yFit !== false) extent(s.y, yr);
      for (const b of spec.bands || []) if (b.yFit !== false) { extent(b.lo, yr); extent(b.hi, yr); }
      for (const l of spec.hlines || []) if (finite(l.y)) extent([l.y], yr);
      if (spec.yMin !== undefined && isFinite(yr[0])) yr[0] = Math.min(yr[0], spec.yMin);
      if (!isFinite(yr[0])) return [0, 1];
      if (yr[1] <= yr[0]) { yr[0] -= 0.5; yr[1] += 0.5; }
      const pad = (yr[1] - yr[0]) * this.opts.yPad;
      return [yr[0] - pad, yr[1] + pad];
    }

    _options(prep) {
      const o = this.opts;
      const xAxis = {label: o.xLabel, stroke: "#374151", grid: {stroke: "#e5e7eb"},
                     ticks: {stroke: "#9ca3af"}, font: AXIS_FONT,
                     labelFont: labelFont(o.xLabel, Math.max(200, this.box.clientWidth || 600) - 80)};
      // away from the cursor the legend reads each series' last value
      const xValue = {label: o.xTime ? "time" : (o.xLabel || "x"),
                      value: (u, v, si, i) => {
                        if (i === null || i === undefined) return "last values";
                        return !finite(v) ? MISSING : o.xTime
                          ? clock(v, (u.scales.x.max - u.scales.x.min) / 200)
                          : num(v, u.scales.x.max - u.scales.x.min);
                      }};
      if (o.xTime) {
        xAxis.label = o.xLabel || "time [h:mm:ss]";
        xAxis.incrs = TIME_STEPS;
        xAxis.values = (u, splits) => {
          const step = splits.length > 1 ? splits[1] - splits[0] : 1;
          return splits.map(v => clock(v, step));
        };
      }
      const series = [xValue];
      for (const s of prep.plotted) {
        const color = s.color || "#2563eb";
        const entry = {label: s.label || "", stroke: color, width: s.width || 1.6,
                       dash: s.dash || undefined, auto: s.yFit !== false, spanGaps: false,
                       value: (u, v, si, i) => {
                         if (i === null || i === undefined) v = lastValue(u.data[si]);
                         return finite(v) ? num(v, u.scales.y.max - u.scales.y.min) : MISSING;
                       }};
        if (s.points) {
          entry.paths = () => null;
          entry.points = {show: true, size: 2 * (s.radius || 3.5), width: 1.5, stroke: color,
                          fill: s.hollow ? "#ffffff" : color};
        } else {
          entry.points = {show: false};
        }
        series.push(entry);
      }
      if (prep.hasExtent) series.push({label: "", show: false, auto: false});
      return {
        width: Math.max(200, this.box.clientWidth || 600), height: this.height,
        series,
        scales: {x: {time: false}, y: {range: (u, lo, hi) => this._yRange(u, lo, hi)}},
        axes: [xAxis, {label: o.yLabel, stroke: "#374151", grid: {stroke: "#e5e7eb"},
                       ticks: {stroke: "#9ca3af"}, size: fitValues, font: AXIS_FONT,
                       labelFont: labelFont(o.yLabel, this.height - X_AXIS_ROOM), labelSize: 20}],
        legend: {show: true, live: true},
        cursor: {drag: {x: true, y: false, setScale: true}, dataIdx: (u, si, i) => this._nearest(u, si, i)},
        hooks: {
          drawAxes: [u => this._drawUnder(u)],
          draw: [u => this._drawOver(u)],
          setScale: [(u, key) => { if (key === "x") this._noteZoom(u); }],
          ready: [u => this._wire(u)],
        },
      };
    }

    // a points series has values at few x: the cursor reads its nearest point (within 40 px)
    _nearest(u, si, i) {
      const ys = u.data[si];
      if (!ys || ys[i] !== undefined || !this.prep.plotted[si - 1] || !this.prep.plotted[si - 1].points) return i;
      const xs = u.data[0], x0 = u.valToPos(xs[i], "x");
      for (let d = 1; d < xs.length; d++) {
        for (const j of [i - d, i + d]) {
          if (j < 0 || j >= xs.length) continue;
          if (Math.abs(u.valToPos(xs[j], "x") - x0) > 40) continue;
          if (ys[j] !== undefined && ys[j] !== null) return j;
        }
        if ((i - d < 0 || Math.abs(u.valToPos(xs[i - d], "x") - x0) > 40) &&
            (i + d >= xs.length || Math.abs(u.valToPos(xs[i + d], "x") - x0) > 40)) break;
      }
      return i;
    }

    _noteZoom(u) {
      const xs = u.data[0];
      if (!xs || !xs.length) { this.zoomed = false; return; }
      const full = [xs[0], xs[xs.length - 1]], span = full[1] - full[0] || 1;
      this.zoomed = u.scales.x.min > full[0] + span * 1e-9 || u.scales.x.max < full[1] - span * 1e-9;
    }

    // wheel: zoom at the cursor; shift + drag: pan (the plain drag selects a range to zoom)
    _wire(u) {
      const over = u.over;
      over.title = "drag: zoom in · wheel: zoom · shift + drag: pan · double click: show all";
      over.addEventListener("wheel", e => {
        e.preventDefault();
        const xs = u.data[0];
        if (!xs || xs.length < 2) return;
        const lo = xs[0], hi = xs[xs.length - 1];
        const at = u.posToVal(e.offsetX, "x");
        const f = e.deltaY < 0 ? ZOOM_STEP : 1 / ZOOM_STEP;
        let min = at - (at - u.scales.x.min) * f, max = at + (u.scales.x.max - at) * f;
        if (max - min >= hi - lo) { min = lo; max = hi; }
        else if (min < lo) { max += lo - min; min = lo; }
        else if (max > hi) { min -= max - hi; max = hi; }
        u.setScale("x", {min, max});
      }, {passive: false});
      over.addEventListener("mousedown", e => {
        if (!e.shiftKey || e.button !== 0) return;
        e.stopImmediatePropagation();
        e.preventDefault();
        const x0 = e.clientX, min0 = u.scales.x.min, max0 = u.scales.x.max;
        const perPx = (max0 - min0) / u.over.clientWidth;
        const xs = u.data[0], lo = xs[0], hi = xs[xs.length - 1];
        const move = ev => {
          let shift = (x0 - ev.clientX) * perPx;
          shift = Math.max(lo - min0, Math.min(hi - max0, shift));
          u.setScale("x", {min: min0 + shift, max: max0 + shift});
        };
        const up = () => { document.removeEventListener("mousemove", move); document.removeEventListener("mouseup", up); };
        document.addEventListener("mousemove", move);
        document.addEventListener("mouseup", up);
      }, {capture: true});
      // series without a name (and the axis extent) keep out of the legend
      const rows = u.root.querySelectorAll(".u-legend .u-series");
      const named = [true, ...this.prep.plotted.map(s => Boolean(s.label)), false];
      rows.forEach((row, k) => { if (k > 0 && !named[k]) row.classList.add("dl-unnamed"); });
    }

    // ---- what uPlot does not draw: bands and reference lines under the series, the
    // non-monotonic series (interval whiskers) and the line labels over them
    _px(u) { return global.devicePixelRatio || 1; }

    _clip(u, ctx) {
      const b = u.bbox;
      ctx.save();
      ctx.beginPath(); ctx.rect(b.left, b.top, b.width, b.height); ctx.clip();
    }

    _drawUnder(u) {
      const ctx = u.ctx, spec = this.spec, r = this._px(u), b = u.bbox;
      const X = v => u.valToPos(v, "x", true), Y = v => u.valToPos(v, "y", true);
      this._clip(u, ctx);
      for (const band of spec.bands || []) {
        ctx.fillStyle = band.color || "rgba(37,99,235,0.15)";
        ctx.beginPath();
        let started = false;
        for (let i = 0; i < band.x.length; i++) {
          if (!finite(band.hi[i])) continue;
          if (!started) { ctx.moveTo(X(band.x[i]), Y(band.hi[i])); started = true; } else ctx.lineTo(X(band.x[i]), Y(band.hi[i]));
        }
        for (let i = band.x.length - 1; i >= 0; i--) if (finite(band.lo[i])) ctx.lineTo(X(band.x[i]), Y(band.lo[i]));
        ctx.closePath();
        ctx.fill();
      }
      ctx.lineWidth = r;
      for (const l of spec.hlines || []) {
        if (!finite(l.y)) continue;
        ctx.strokeStyle = l.color || "#dc2626";
        ctx.setLineDash([6 * r, 4 * r]);
        ctx.beginPath(); ctx.moveTo(b.left, Y(l.y)); ctx.lineTo(b.left + b.width, Y(l.y)); ctx.stroke();
      }
      for (const l of spec.vlines || []) {
        if (!finite(l.x)) continue;
        ctx.strokeStyle = l.color || "#6b7280";
        ctx.setLineDash([4 * r, 4 * r]);
        ctx.beginPath(); ctx.moveTo(X(l.x), b.top); ctx.lineTo(X(l.x), b.top + b.height); ctx.stroke();
      }
      ctx.setLineDash([]);
      ctx.restore();
    }

    _drawOver(u) {
      const ctx = u.ctx, spec = this.spec, r = this._px(u), b = u.bbox;
      const X = v => u.valToPos(v, "x", true), Y = v => u.valToPos(v, "y", true);
      this._clip(u, ctx);
      for (const s of this.prep.overlay) {
        ctx.strokeStyle = s.color || "#2563eb";
        ctx.fillStyle = s.color || "#2563eb";
        ctx.lineWidth = (s.width || 1.6) * r;
        ctx.setLineDash((s.dash || []).map(d => d * r));
        if (s.points) {
          for (let i = 0; i < s.x.length; i++) {
            if (!finite(s.y[i]) || !finite(s.x[i])) continue;
            ctx.beginPath(); ctx.arc(X(s.x[i]), Y(s.y[i]), (s.radius || 3.5) * r, 0, 2 * Math.PI);
            if (s.hollow) ctx.stroke(); else ctx.fill();
          }
          continue;
        }
        ctx.beginPath();
        let pen = false;
        for (let i = 0; i < s.x.length; i++) {
          if (!finite(s.y[i]) || !finite(s.x[i])) { pen = false; continue; }
          if (pen) ctx.lineTo(X(s.x[i]), Y(s.y[i])); else ctx.moveTo(X(s.x[i]), Y(s.y[i]));
          pen = true;
        }
        ctx.stroke();
      }
      ctx.setLineDash([]);
      ctx.font = `${12 * r}px system-ui, sans-serif`;
      for (const l of spec.hlines || []) {
        if (!finite(l.y) || !l.label) continue;
        ctx.fillStyle = l.color || "#dc2626"; ctx.textAlign = "right"; ctx.textBaseline = "bottom";
        ctx.fillText(l.label, b.left + b.width - 4 * r, Y(l.y) - 2 * r);
      }
      for (const l of spec.vlines || []) {
        if (!finite(l.x) || !l.label) continue;
        const x = X(l.x), room = b.left + b.width - x > ctx.measureText(l.label).width + 8 * r;
        ctx.fillStyle = l.color || "#6b7280"; ctx.textBaseline = "top";
        ctx.textAlign = room ? "left" : "right";     // beside the line, inside the plot
        ctx.fillText(l.label, room ? x + 4 * r : x - 4 * r, b.top + 2 * r);
      }
      ctx.restore();
    }

    draw(spec) {
      this.spec = spec || {};
      const prep = this._prepare(this.spec);
      this.prep = prep;
      const empty = !prep.data && !prep.overlay.length;
      this.message.hidden = !empty;
      this.message.textContent = empty ? (this.spec.empty || "no data yet") : "";
      if (empty) {
        this.destroy();
        this.key = null;
        this.draws++;
        return;
      }
      const data = prep.data || [[prep.extent[0], prep.extent[1]]];
      const key = this._structure(prep);
      if (this.u && key === this.key) {
        if (this.zoomed) {                   // keep the reader's stretch; redraw what is in it
          const {min, max} = this.u.scales.x;
          this.u.setData(data, false);
          this.u.setScale("x", {min, max});
        } else {
          this.u.setData(data);
        }
      } else {
        this.destroy();
        this.zoomed = false;
        this.key = key;
        this.u = new global.uPlot(this._options(prep), data, this.box);
      }
      this.draws++;
    }
  }

  global.LinePlot = LinePlot;
})(window);
