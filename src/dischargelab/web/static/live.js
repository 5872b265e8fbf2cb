// dischargelab live bench: history on connect, then every sample as it is logged.
// Each sample carries n (0, 1, 2 ... in the run); a jump in n is counted as missing samples,
// so the page shows whether it has everything. window.__live exposes the state to tests.
"use strict";

(function () {
  const F = {n: 0, t: 1, v: 2, cell: 3, i: 4, p: 5, ah: 6, wh: 7, temp: 8, seq: 9};
  const L = window.__live = {
    run: null, n: [], t: [], v: [], i: [], p: [], temp: [], seq: [], ah: [], wh: [],
    lastN: -1, firstN: 0, missing: 0, gaps: 0, snapshots: 0, updates: [], last: null,
    status: null, events: [], connected: false,
  };
  const $ = id => document.getElementById(id);
  const ETA_HOW = {
    model: "The pack's battery model run from the charge taken out so far to the cutoff, at the mean current of the last two minutes",
    trend: "The voltage's present rate of fall extended to the cutoff (no battery model given): an upper estimate that shrinks as the knee of the curve comes",
  };
  let voltagePlot, currentPlot, drawPending = false;

  function reset(firstN) {
    for (const k of ["n", "t", "v", "i", "p", "temp", "seq", "ah", "wh"]) L[k] = [];
    L.lastN = firstN - 1;
    L.firstN = firstN;
    L.last = null;
  }

  function add(rows) {
    for (const r of rows) {
      const n = r[F.n];
      if (n !== L.lastN + 1) { L.gaps += 1; L.missing += Math.max(0, n - L.lastN - 1); }
      L.lastN = n;
      L.n.push(n); L.t.push(r[F.t]); L.v.push(r[F.v]); L.i.push(r[F.i]); L.p.push(r[F.p]);
      L.temp.push(r[F.temp]); L.seq.push(r[F.seq]); L.ah.push(r[F.ah]); L.wh.push(r[F.wh]);
      L.last = r;
    }
  }

  function addEvents(events) {
    const list = $("events");
    for (const e of events) {
      L.events.push(e);
      const text = e.message || e.reason || (e.kind === "gap" ? DL.duration(e.duration_s) + " without data" : "");
      const item = DL.el("li", {class: "ev-" + e.kind}, [DL.el("b", {text: e.kind}), " " + text]);
      list.prepend(item);
    }
    while (list.children.length > 30) list.lastChild.remove();
  }

  function render() {
    drawPending = false;
    const r = L.last, s = L.status || {};
    $("m-voltage").textContent = r ? DL.num(r[F.v], 3) : DL.MISSING;
    $("m-cell").textContent = r ? DL.num(r[F.cell], 3) : DL.MISSING;
    $("m-current").textContent = r ? DL.num(r[F.i], 2) : DL.MISSING;
    $("m-power").textContent = r ? DL.num(r[F.p], 1) : DL.MISSING;
    $("m-charge").textContent = r ? DL.num(r[F.ah], 4) : DL.MISSING;
    $("m-energy").textContent = r ? DL.num(r[F.wh], 3) : DL.MISSING;
    $("m-temp").textContent = r ? DL.num(r[F.temp], 1) : DL.MISSING;
    $("m-elapsed").textContent = r ? DL.duration(r[F.t]) : DL.MISSING;
    const limits = (s.info || {}).limits || {};
    const cutoff = limits.cutoff_pack_V;
    voltagePlot.draw({
      series: [{x: L.t, y: L.v, color: "#2563eb", label: "pack voltage"}],
      hlines: cutoff ? [{y: cutoff, color: "#dc2626", label: "cutoff " + DL.num(cutoff, 2) + " V"}] : [],
      empty: "waiting for samples",
    });
    currentPlot.draw({
      series: [{x: L.t, y: L.i, color: "#059669", label: "current"}],
      empty: "no current measured", yMin: 0,
    });
    $("s-samples").textContent = L.n.length + (L.firstN > 0 ? " (history from sample " + L.firstN + ")" : "");
    $("s-gaps").textContent = L.missing === 0 ? "none" : L.missing + " in " + L.gaps + " gaps";
    const now = performance.now();
    L.updates.push(now);
    if (L.updates.length > 20000) L.updates.splice(0, 10000);
  }

  function schedule() {
    if (drawPending) return;
    drawPending = true;
    // draw now unless a draw happened in the last 40 ms (a burst of messages draws once)
    const last = L.updates.length ? L.updates[L.updates.length - 1] : -1e9;
    const wait = Math.max(0, 40 - (performance.now() - last));
    setTimeout(render, wait);
  }

  function showStatus(s) {
    L.status = s;
    const badge = $("state");
    let text = "idle", cls = "idle";
    if (s.active) { text = "running"; cls = "running"; }
    else if (s.ended_by) { text = "ended: " + s.ended_by; cls = s.ended_by === "cutoff" || s.ended_by === "user" || s.ended_by === "duration" ? "ended" : "alarm"; }
    if (s.safety && s.active) { text += " · " + s.safety; cls = "alarm"; }
    badge.textContent = text;
    badge.className = "badge " + cls;
    const info = s.info || {};
    $("where").textContent = info.port ? (info.demo ? "virtual logger (" + (info.battery || "") + ", time ×" + DL.num(info.speed, 0) + ")" : info.port) + " → " + (info.out || "") : "";
    $("s-link").textContent = s.link || DL.MISSING;
    $("s-rate").textContent = s.rate_Hz === null || s.rate_Hz === undefined ? DL.MISSING : DL.num(s.rate_Hz, 1) + " samples/s";
    $("s-lost").textContent = (s.frames_lost ?? DL.MISSING) + " / " + (s.frames_corrupt ?? DL.MISSING);
    $("s-safety").textContent = s.safety || (s.active ? "within limits" : DL.MISSING);
    $("s-min").textContent = s.min_voltage_V === null || s.min_voltage_V === undefined ? DL.MISSING : DL.num(s.min_voltage_V, 3) + " V";
    $("m-eta").textContent = s.time_to_cutoff_s === null || s.time_to_cutoff_s === undefined ? DL.MISSING : DL.duration(s.time_to_cutoff_s);
    $("m-eta-method").textContent = s.time_to_cutoff_method ? "(" + s.time_to_cutoff_method + ")" : "";
    $("eta-meter").title = ETA_HOW[s.time_to_cutoff_method] || "";
    $("start").disabled = !s.can_start;
    $("stop").disabled = !s.can_stop;
    $("start-form").classList.toggle("locked", !s.can_start);
    const limits = info.limits;
    const table = $("limits");
    table.replaceChildren();
    if (limits) {
      const rows = [["Cells", limits.cells_series + " in series (" + (limits.chemistry || "") + ")"],
                    ["Cutoff", DL.num(limits.cutoff_cell_V, 2) + " V/cell = " + DL.num(limits.cutoff_pack_V, 2) + " V"],
                    ["Max temperature", limits.max_temperature_C === null ? "not checked" : DL.num(limits.max_temperature_C, 0) + " °C"],
                    ["Debounce", limits.debounce_samples + " samples"],
                    ["Rate", DL.num(info.rate_Hz, 2) + " Hz"]];
      for (const [k, v] of rows) table.append(DL.el("tr", {}, [DL.el("th", {text: k}), DL.el("td", {text: v})]));
    }
    $("start-note").textContent = s.mode === "demo"
      ? "Demo: Start runs a virtual logger (simulated pack on a pseudo-terminal) through the real acquisition; the log file is written on the server."
      : "This page watches a test started on the command line (dischargelab acquire ... --serve); Stop ends it cleanly, as Ctrl-C would.";
    if (s.ended_by && !s.active && s.end_message) DL.showMessage(s.end_message, s.ended_by === "cutoff" || s.ended_by === "user" || s.ended_by === "duration" ? "info" : "error");
  }

  function connect() {
    const source = new EventSource("/api/live/stream");
    source.addEventListener("open", () => { L.connected = true; });
    source.addEventListener("error", () => { L.connected = false; $("state").textContent = "reconnecting"; $("state").className = "badge alarm"; });
    source.addEventListener("snapshot", e => {
      const d = JSON.parse(e.data);
      L.snapshots += 1;
      if (d.run !== L.run) { $("events").replaceChildren(); L.events = []; DL.showMessage(""); }
      L.run = d.run;
      reset(d.first_n);
      add(d.samples);
      $("events").replaceChildren();
      L.events = [];
      addEvents(d.events);
      showStatus(d.status);
      schedule();
    });
    source.addEventListener("samples", e => {
      const d = JSON.parse(e.data);
      if (d.run !== L.run) return;            // a snapshot of the new run follows
      add(d.samples);
      addEvents(d.events);
      schedule();
    });
    source.addEventListener("status", e => { showStatus(JSON.parse(e.data)); });
  }

  function formSettings(form) {
    const out = {};
    for (const input of form.querySelectorAll("input, select")) {
      const v = input.value.trim();
      if (v === "") continue;
      out[input.name] = input.type === "number" ? Number(v) : v;
    }
    return out;
  }

  document.addEventListener("DOMContentLoaded", () => {
    voltagePlot = new LinePlot($("plot-voltage"), {xTime: true, yLabel: "pack voltage [V]"});
    currentPlot = new LinePlot($("plot-current"), {xTime: true, yLabel: "current [A]"});
    $("start-form").addEventListener("submit", async ev => {
      ev.preventDefault();
      $("start").disabled = true;
      try {
        const r = await DL.postJSON("/api/live/start", formSettings(ev.target));
        DL.showMessage("started: logging to " + r.out, "info");
      } catch (err) {
        DL.showMessage(err.message, "error");
        $("start").disabled = false;
      }
    });
    $("stop").addEventListener("click", async () => {
      try { await DL.postJSON("/api/live/stop", {}); } catch (err) { DL.showMessage(err.message, "error"); }
    });
    window.addEventListener("resize", schedule);
    connect();
    schedule();
  });
})();
