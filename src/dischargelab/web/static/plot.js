// dischargelab: a small line plot on a <canvas> (no dependencies).
// LinePlot(canvas, {xLabel, yLabel}) ; plot.draw({series: [{x, y, color, label, width, dash}],
// bands: [{x, lo, hi, color}], hlines: [{y, color, label}], vlines: [{x, color, label}]}).
// Long series are thinned per pixel column (min and max kept), so drawing stays fast.
"use strict";

(function (global) {
  function niceStep(span, target) {
    const raw = span / Math.max(1, target);
    const mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const norm = raw / mag;
    const step = norm < 1.5 ? 1 : norm < 3 ? 2 : norm < 7 ? 5 : 10;
    return step * mag;
  }

  function ticks(lo, hi, target) {
    if (!(hi > lo)) return [lo];
    const step = niceStep(hi - lo, target);
    const out = [];
    for (let v = Math.ceil(lo / step) * step, k = 0; v <= hi + step * 1e-9 && k < 50; v += step, k++) {
      out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    }
    return out;
  }

  function fmt(v, step) {
    const digits = Math.max(0, Math.min(6, -Math.floor(Math.log10(step) + 1e-9)));
    return v.toFixed(digits);
  }

  function extent(values, acc) {
    for (let i = 0; i < values.length; i++) {
      const v = values[i];
      if (v === null || v === undefined || !isFinite(v)) continue;
      if (v < acc[0]) acc[0] = v;
      if (v > acc[1]) acc[1] = v;
    }
    return acc;
  }

  class LinePlot {
    constructor(canvas, opts) {
      this.canvas = canvas;
      this.opts = Object.assign({xLabel: "", yLabel: "", xTime: false, yPad: 0.05}, opts || {});
      this.draws = 0;
    }

    _size() {
      const ratio = global.devicePixelRatio || 1;
      const rect = this.canvas.getBoundingClientRect();
      const w = Math.max(200, Math.round(rect.width));
      const h = Math.max(120, Math.round(rect.height));
      if (this.canvas.width !== Math.round(w * ratio) || this.canvas.height !== Math.round(h * ratio)) {
        this.canvas.width = Math.round(w * ratio);
        this.canvas.height = Math.round(h * ratio);
      }
      return {w, h, ratio};
    }

    draw(spec) {
      const {w, h, ratio} = this._size();
      const ctx = this.canvas.getContext("2d");
      ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
      ctx.clearRect(0, 0, w, h);
      const series = (spec.series || []).filter(s => s.x && s.x.length);
      const bands = spec.bands || [];
      const hlines = spec.hlines || [];
      const vlines = spec.vlines || [];
      let xr = [Infinity, -Infinity], yr = [Infinity, -Infinity];
      for (const s of series) { extent(s.x, xr); extent(s.y, yr); }
      for (const b of bands) { extent(b.x, xr); extent(b.lo, yr); extent(b.hi, yr); }
      for (const l of hlines) if (isFinite(l.y)) extent([l.y], yr);
      for (const l of vlines) if (isFinite(l.x)) extent([l.x], xr);
      if (spec.xMin !== undefined) xr[0] = Math.min(xr[0], spec.xMin);
      if (spec.yMin !== undefined) yr[0] = Math.min(yr[0], spec.yMin);
      const m = {l: 58, r: 14, t: 24, b: 38};
      const pw = w - m.l - m.r, ph = h - m.t - m.b;
      ctx.font = "12px system-ui, sans-serif";
      ctx.fillStyle = "#6b7280";
      if (!isFinite(xr[0]) || !isFinite(yr[0])) {
        ctx.textAlign = "center";
        ctx.fillText(spec.empty || "no data yet", m.l + pw / 2, m.t + ph / 2);
        this.draws++;
        return;
      }
      if (xr[1] <= xr[0]) xr = [xr[0] - 1, xr[0] + 1];
      if (series.some(s => s.points)) {                  // keep markers off the frame
        const px = (xr[1] - xr[0]) * 0.04;
        xr = [xr[0] - px, xr[1] + px];
      }
      if (yr[1] <= yr[0]) yr = [yr[0] - 0.5, yr[0] + 0.5];
      const pad = (yr[1] - yr[0]) * this.opts.yPad;
      yr = [yr[0] - pad, yr[1] + pad];
      const X = v => m.l + (v - xr[0]) / (xr[1] - xr[0]) * pw;
      const Y = v => m.t + ph - (v - yr[0]) / (yr[1] - yr[0]) * ph;

      // grid and ticks
      ctx.strokeStyle = "#e5e7eb";
      ctx.lineWidth = 1;
      ctx.textAlign = "right";
      ctx.textBaseline = "middle";
      const yt = ticks(yr[0], yr[1], Math.max(3, Math.floor(ph / 45)));
      const ystep = yt.length > 1 ? yt[1] - yt[0] : 1;
      for (const v of yt) {
        const y = Math.round(Y(v)) + 0.5;
        ctx.beginPath(); ctx.moveTo(m.l, y); ctx.lineTo(m.l + pw, y); ctx.stroke();
        ctx.fillText(fmt(v, ystep), m.l - 6, y);
      }
      let xScale = 1, xUnit = this.opts.xLabel;
      if (this.opts.xTime) {
        const span = xr[1] - xr[0];
        if (xr[1] > 7200 && span > 3600) { xScale = 3600; xUnit = "time [h]"; }
        else if (xr[1] > 300 && span > 120) { xScale = 60; xUnit = "time [min]"; }
        else { xUnit = "time [s]"; }
      }
      ctx.textAlign = "center";
      ctx.textBaseline = "top";
      const xt = ticks(xr[0] / xScale, xr[1] / xScale, Math.max(3, Math.floor(pw / 90)));
      const xstep = xt.length > 1 ? xt[1] - xt[0] : 1;
      for (const v of xt) {
        const x = Math.round(X(v * xScale)) + 0.5;
        ctx.beginPath(); ctx.moveTo(x, m.t); ctx.lineTo(x, m.t + ph); ctx.stroke();
        ctx.fillText(fmt(v, xstep), x, m.t + ph + 6);
      }
      ctx.fillStyle = "#374151";
      ctx.fillText(xUnit, m.l + pw / 2, h - 16);
      ctx.save();
      ctx.translate(14, m.t + ph / 2);
      ctx.rotate(-Math.PI / 2);
      ctx.textBaseline = "middle";
      ctx.fillText(this.opts.yLabel, 0, 0);
      ctx.restore();

      ctx.save();
      ctx.beginPath(); ctx.rect(m.l, m.t, pw, ph); ctx.clip();
      for (const b of bands) {
        ctx.fillStyle = b.color || "rgba(37,99,235,0.15)";
        ctx.beginPath();
        let started = false;
        for (let i = 0; i < b.x.length; i++) {
          if (!isFinite(b.hi[i])) continue;
          if (!started) { ctx.moveTo(X(b.x[i]), Y(b.hi[i])); started = true; }
          else ctx.lineTo(X(b.x[i]), Y(b.hi[i]));
        }
        for (let i = b.x.length - 1; i >= 0; i--) if (isFinite(b.lo[i])) ctx.lineTo(X(b.x[i]), Y(b.lo[i]));
        ctx.closePath();
        ctx.fill();
      }
      for (const l of hlines) {
        if (!isFinite(l.y)) continue;
        ctx.strokeStyle = l.color || "#dc2626";
        ctx.setLineDash([6, 4]);
        ctx.beginPath(); ctx.moveTo(m.l, Y(l.y)); ctx.lineTo(m.l + pw, Y(l.y)); ctx.stroke();
        ctx.setLineDash([]);
        if (l.label) { ctx.fillStyle = l.color || "#dc2626"; ctx.textAlign = "right"; ctx.textBaseline = "bottom"; ctx.fillText(l.label, m.l + pw - 4, Y(l.y) - 2); }
      }
      for (const l of vlines) {
        if (!isFinite(l.x)) continue;
        ctx.strokeStyle = l.color || "#6b7280";
        ctx.setLineDash([4, 4]);
        ctx.beginPath(); ctx.moveTo(X(l.x), m.t); ctx.lineTo(X(l.x), m.t + ph); ctx.stroke();
        ctx.setLineDash([]);
        if (l.label) { ctx.fillStyle = l.color || "#6b7280"; ctx.textAlign = "left"; ctx.textBaseline = "top"; ctx.fillText(l.label, X(l.x) + 4, m.t + 2); }
      }
      for (const s of series) {
        ctx.strokeStyle = s.color || "#2563eb";
        ctx.lineWidth = s.width || 1.6;
        ctx.setLineDash(s.dash || []);
        if (s.points) {
          ctx.fillStyle = s.color || "#2563eb";
          for (let i = 0; i < s.x.length; i++) {
            if (!isFinite(s.y[i]) || s.y[i] === null) continue;
            ctx.beginPath(); ctx.arc(X(s.x[i]), Y(s.y[i]), s.radius || 3.5, 0, 2 * Math.PI);
            if (s.hollow) ctx.stroke(); else ctx.fill();
          }
          continue;
        }
        ctx.beginPath();
        let pen = false, col = -1, lo = 0, hi = 0;
        const n = s.x.length;
        for (let i = 0; i < n; i++) {
          const yv = s.y[i];
          if (yv === null || !isFinite(yv)) { pen = false; continue; }
          const px = X(s.x[i]), py = Y(yv), c = Math.floor(px);
          if (n > 2 * pw && pen && c === col) {          // same pixel column: keep min and max
            if (py < lo) { lo = py; ctx.lineTo(px, py); }
            else if (py > hi) { hi = py; ctx.lineTo(px, py); }
            continue;
          }
          if (pen) ctx.lineTo(px, py); else ctx.moveTo(px, py);
          pen = true; col = c; lo = hi = py;
        }
        ctx.stroke();
        ctx.setLineDash([]);
      }
      ctx.restore();
      // legend
      const named = series.filter(s => s.label);
      ctx.textAlign = "left";
      ctx.textBaseline = "middle";
      let lx = m.l;
      for (const s of named) {
        ctx.fillStyle = s.color || "#2563eb";
        ctx.fillRect(lx, 9, 14, 3);
        ctx.fillStyle = "#374151";
        ctx.fillText(s.label, lx + 18, 11);
        lx += 28 + ctx.measureText(s.label).width;
      }
      ctx.strokeStyle = "#9ca3af";
      ctx.strokeRect(m.l + 0.5, m.t + 0.5, pw, ph);
      this.draws++;
    }
  }

  global.LinePlot = LinePlot;
})(window);
