// dischargelab pack page: health, trend against EFC, events, model curves, endurance.
// Every number comes from /api/packs/NAME (the logbook and the model, computed on the server).
"use strict";

(function () {
  const $ = id => document.getElementById(id);
  const name = decodeURIComponent(location.pathname.replace(/^\/packs\//, ""));
  const api = "/api/packs/" + encodeURIComponent(name);
  const COLORS = ["#2563eb", "#059669", "#d97706", "#7c3aed"];

  const RELOAD_MS = 2000;
  let again = null;

  function show(d) {
    window.__pack = {loaded: true, data: d};
    // figures older than the pack's data are being recomputed by the server: look again
    clearTimeout(again);
    if (d.recompute_problem) DL.showMessage(d.recompute_problem, "error");
    else if (d.error) DL.showMessage(d.error, "error");
    else if (d.recomputing) {
      DL.showMessage("the figures of this pack are being recomputed with its latest data …", "info");
      again = setTimeout(async () => { try { show(await DL.api(api)); } catch (err) { DL.showMessage(err.message, "error"); } }, RELOAD_MS);
    } else DL.showMessage("");
    document.title = d.name + " · dischargelab";
    $("pack-name").textContent = d.name;
    const s = d.summary || {};
    const events = (d.health && d.health.events) || [];
    const fc = d.health && d.health.forecast;
    const withCap = events.filter(e => e.capacity_Ah !== null && e.capacity_Ah !== undefined);
    const withR = events.filter(e => e.resistance_ohm !== null && e.resistance_ohm !== undefined);
    $("pack-summary").textContent = [s.events + (s.events === 1 ? " event" : " events"),
      s.chemistry, s.cells ? s.cells + (s.cells === 1 ? " cell" : " cells") + " in series" : null].filter(Boolean).join(" · ");
    $("m-capacity").textContent = DL.num(s.capacity_Ah, 3);
    $("m-health").textContent = s.capacity_fraction === null || s.capacity_fraction === undefined ? "Ah" : "Ah (" + DL.num(s.capacity_fraction * 100, 0) + " %)";
    $("m-reference").textContent = DL.num(s.reference_capacity_Ah, 3);
    $("m-efc").textContent = DL.num(s.efc, 1);
    $("m-resistance").textContent = s.resistance_ohm === null || s.resistance_ohm === undefined ? "–" : DL.num(s.resistance_ohm * 1000, 1);
    $("m-eol").textContent = fc ? DL.num(fc.eol_efc, 0) : "–";
    $("m-eol-iv").textContent = fc && fc.eol_efc_interval95 ? "EFC (95 %: " + DL.num(fc.eol_efc_interval95[0], 0) + "–" + DL.num(fc.eol_efc_interval95[1], 0) + ")" : "EFC";

    const normal = withCap.filter(e => !e.outlier), odd = withCap.filter(e => e.outlier);
    const bands = [], series = [], vlines = [], hlines = [];
    const band = fc && fc.band;
    if (band && band.efc) {
      // the band's far end can fall steeply: it is clipped to the measured capacities' range
      bands.push({x: band.efc, lo: band.lo, hi: band.hi, color: "rgba(37,99,235,0.13)", yFit: false});
      series.push({x: band.efc, y: band.capacity_Ah, color: "#2563eb", width: 1.2, dash: [5, 3], label: "trend and 95 % band", yFit: false});
    }
    const ivs = withCap.filter(e => e.capacity_interval95);
    for (const e of ivs) series.push({x: [e.efc, e.efc], y: e.capacity_interval95, color: "#93c5fd", width: 1});
    series.push({x: normal.map(e => e.efc), y: normal.map(e => e.capacity_Ah), color: "#1d4ed8", points: true, label: "capacity"});
    if (odd.length) series.push({x: odd.map(e => e.efc), y: odd.map(e => e.capacity_Ah), color: "#d97706", points: true, hollow: true, label: "outlier"});
    if (fc && isFinite(fc.threshold_Ah)) hlines.push({y: fc.threshold_Ah, color: "#dc2626", label: "end of life " + DL.num(fc.threshold_Ah, 2) + " Ah"});
    if (fc && isFinite(fc.eol_efc)) {
      vlines.push({x: fc.eol_efc, color: "#dc2626", label: "EOL " + DL.num(fc.eol_efc, 0) + " EFC"});
      if (fc.eol_efc_interval95) {
        const [a, b] = fc.eol_efc_interval95;
        if (isFinite(a) && isFinite(b) && fc.threshold_Ah) bands.push({x: [a, b], lo: [fc.threshold_Ah * 0.98, fc.threshold_Ah * 0.98], hi: [fc.threshold_Ah * 1.02, fc.threshold_Ah * 1.02], color: "rgba(220,38,38,0.18)"});
      }
    }
    new LinePlot($("plot-capacity"), {xLabel: "equivalent full cycles [EFC]", yLabel: "capacity [Ah]"})
      .draw({series, bands, hlines, vlines, xMin: 0, empty: "no capacity measured yet"});
    new LinePlot($("plot-resistance"), {xLabel: "equivalent full cycles [EFC]", yLabel: "resistance [mΩ]"})
      .draw({series: [{x: withR.map(e => e.efc), y: withR.map(e => e.resistance_ohm * 1000), color: "#059669", points: true, label: "resistance"}],
             xMin: 0, empty: "no load steps to measure resistance yet"});

    const m = d.model;
    if (m && m.curves) {
      $("model-name").textContent = "(" + [m.name, m.family].filter(Boolean).join(", ") + ")";
      new LinePlot($("plot-model"), {xLabel: "discharged charge [Ah]", yLabel: "pack voltage [V]"})
        .draw({series: m.curves.map((c, k) => ({x: c.charge_Ah, y: c.voltage_V, color: COLORS[k % COLORS.length],
                                                  label: DL.num(c.c_rate, 1) + "C (" + DL.num(c.current_A, 1) + " A)"}))});
      $("model-note").textContent = m.note || "";
    } else {
      $("model-name").textContent = "";
      new LinePlot($("plot-model"), {}).draw({series: [], empty: d.model_note || "no model fitted yet — Refit"});
      $("model-note").textContent = "Refit fits the pack's model to its latest full discharge and stores it; the curves and the endurance use it, scaled to the pack's health today.";
    }
    $("fly").disabled = !m;
    $("fly").title = m ? "" : "no model fitted yet: Refit first";

    const body = $("events").querySelector("tbody");
    body.replaceChildren();
    for (const e of events.slice().reverse()) {
      body.append(DL.el("tr", {class: e.outlier ? "outlier" : ""}, [
        DL.el("td", {text: e.source || ""}), DL.el("td", {text: (e.start || "").replace("T", " ").slice(0, 19)}),
        DL.el("td", {text: e.kind || ""}), DL.el("td", {class: "num", text: DL.num(e.discharged_Ah, 3)}),
        DL.el("td", {class: "num", text: DL.num(e.capacity_Ah, 3)}),
        DL.el("td", {class: "num", text: e.capacity_interval95 ? DL.num(e.capacity_interval95[0], 3) + " – " + DL.num(e.capacity_interval95[1], 3) : "–"}),
        DL.el("td", {class: "num", text: e.resistance_ohm === null || e.resistance_ohm === undefined ? "–" : DL.num(e.resistance_ohm * 1000, 1)}),
        DL.el("td", {class: "num", text: DL.num(e.efc, 1)}), DL.el("td", {text: e.outlier ? "outlier" : ""}),
      ]));
    }
  }

  function showEndurance(r) {
    const t = $("endurance-result");
    t.replaceChildren();
    const cannot = r.cannot_deliver ? r.cannot_deliver.message : null;
    const rows = [["Mission", r.mission]];
    if (cannot) rows.push(["Cannot fly", cannot]);
    rows.push(["Completed", r.completed ? "yes" : "no (" + r.ended_by + ")"],
              ["Flight time", DL.clock(r.flight_time_s)], ["Endurance to cutoff", DL.clock(r.endurance_s)],
              ["Charge used", DL.num(r.charge_used_Ah, 3) + " Ah"], ["State of charge at the end", DL.num(r.soc_end_pct, 1) + " %"],
              ["Minimum voltage", DL.num(r.min_voltage_V, 2) + " V"]);
    for (const w of r.warnings || []) if (w !== cannot) rows.push(["Warning", w]);
    for (const [k, v] of rows) {
      t.append(DL.el("tr", k === "Cannot fly" ? {class: "cannot"} : {},
                     [DL.el("th", {text: k}), DL.el("td", {text: String(v)})]));
    }
    window.__endurance = r;
  }

  document.addEventListener("DOMContentLoaded", async () => {
    try {
      const missions = await DL.api("/api/missions");
      for (const m of missions.missions) $("mission").append(DL.el("option", {value: m, text: m}));
      if (missions.missions.includes("paper-table5")) $("mission").value = "paper-table5";
      show(await DL.api(api));
    } catch (err) {
      DL.showMessage(err.message, "error");
      window.__pack = {loaded: true, error: err.message, status: err.status};
    }
    $("endurance").addEventListener("submit", async e => {
      e.preventDefault();
      $("fly").disabled = true;
      try { showEndurance(await DL.postJSON(api + "/endurance", {mission: $("mission").value})); DL.showMessage(""); }
      catch (err) { DL.showMessage(err.message, "error"); }
      finally { $("fly").disabled = false; }
    });
    $("refit").addEventListener("click", async () => {
      $("refit").disabled = true;
      $("fit-result").textContent = "fitting …";
      try { await DL.postJSON(api + "/fit", {}); $("fit-result").textContent = "model refitted"; show(await DL.api(api)); }
      catch (err) { $("fit-result").textContent = ""; DL.showMessage(err.message, "error"); }
      finally { $("refit").disabled = false; }
    });
  });
})();
