// dischargelab pack page: health, trend against EFC, events, model curves, endurance.
// Every number comes from /api/packs/NAME (the logbook and the model, computed on the server).
"use strict";

(function () {
  const $ = id => document.getElementById(id);
  const name = decodeURIComponent(location.pathname.replace(/^\/packs\//, ""));
  const api = "/api/packs/" + encodeURIComponent(name);
  $("dl-param").href = api + "/autopilot/ardupilot.param";
  $("dl-lua").href = api + "/autopilot/ardupilot.lua";
  const COLORS = ["#2563eb", "#059669", "#d97706", "#7c3aed"];
  // marker colour of each event kind on the capacity and resistance plots
  const KIND_COLORS = {full: "#1d4ed8", partial: "#059669", flight: "#7c3aed", charge: "#0891b2"};
  const SHAPES = {line: "a straight line", early: "a fast early fade, then a line",
                  knee: "a knee", "early+knee": "a fast early fade and a knee"};

  // a number to draw (isFinite(null) is true: null would land at 0)
  const has = v => typeof v === "number" && isFinite(v);

  function fromEvents(list) {
    if (!list || !list.length) return "";
    const kinds = [...new Set(list.map(s => s.kind))].join("/");
    const names = list.map(s => s.source);
    return list.length + " " + kinds + " event" + (list.length === 1 ? "" : "s") + ": " +
      (names.length <= 3 ? names.join(", ") : names[0] + " … " + names[names.length - 1]);
  }

  function byKind(list, value, interval, scale) {
    // one marker series per event kind, its 95 % intervals as vertical segments
    const series = [];
    for (const kind of [...new Set(list.map(e => e.kind))]) {
      const color = KIND_COLORS[kind] || "#6b7280";
      for (const odd of [false, true]) {
        const sel = list.filter(e => e.kind === kind && !!e.outlier === odd);
        if (!sel.length) continue;
        for (const e of sel) if (e[interval]) series.push({x: [e.efc, e.efc], y: e[interval].map(v => v * scale), color: "#cbd5e1", width: 1});
        series.push({x: sel.map(e => e.efc), y: sel.map(e => e[value] * scale), color: odd ? "#d97706" : color, points: true,
                     hollow: odd, label: odd ? kind + " (outlier)" : kind});
      }
    }
    return series;
  }

  // the end-of-life meter without an end of life: why, and when a fade could show
  function shortEvidence(fc, efcNow) {
    const f = fc.fade || {};
    if (fc.status === "uncertain") return "fade measured, not yet enough to date an end of life (details below)";
    if (fc.status !== "no fade") return "EFC";
    const need = f.efc_needed;
    if (!has(need)) return "no fade measured yet (details below)";
    return "no fade measured yet" + (need > (efcNow || 0) ? "; a typical fade would show at about " + DL.num(need, 0) + " EFC" : "; slower than a typical fade");
  }

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
    const h = d.health || {};
    const withCap = events.filter(e => e.capacity_Ah !== null && e.capacity_Ah !== undefined && e.efc !== null);
    const refR = h.resistance_basis === "reference conditions";
    const rKey = refR ? "resistance_ref_ohm" : "resistance_ohm";
    const withR = events.filter(e => e[rKey] !== null && e[rKey] !== undefined && e.efc !== null);
    $("pack-summary").textContent = [s.events + (s.events === 1 ? " event" : " events"),
      s.chemistry, s.cells ? s.cells + (s.cells === 1 ? " cell" : " cells") + " in series" : null].filter(Boolean).join(" · ");
    $("m-capacity").textContent = DL.text(s, "capacity_Ah", 3);
    $("m-health").textContent = s.capacity_fraction === null || s.capacity_fraction === undefined ? "Ah" : "Ah (" + DL.text(s, "capacity_fraction", 0, 100) + ")";
    $("m-reference").textContent = DL.num(s.reference_capacity_Ah, 3);
    $("m-efc").textContent = DL.text(s, "efc", 1);
    $("m-resistance").textContent = DL.text(s, "resistance_ohm", 1, 1000);
    // no end of life without a measured fade: the forecast says why and when one could show
    const dated = fc && has(fc.eol_efc);
    $("m-eol").textContent = dated ? DL.num(fc.eol_efc, 0) : DL.MISSING;
    $("m-eol-iv").textContent = dated && fc.eol_efc_interval95 ? "EFC (95 %: " + DL.interval(fc.eol_efc_interval95, 0) + ")"
      : fc ? shortEvidence(fc, h.efc_now) : "no fade measured yet (no capacity estimate yet)";
    const civ = h.capacity_now_interval95;
    $("m-capacity-iv").textContent = civ ? "95 %: " + DL.interval(civ, 3) : "";
    const lines = [];
    if (h.capacity_now_Ah !== null && h.capacity_now_Ah !== undefined) lines.push("Capacity today from " + fromEvents(h.capacity_from) + ".");
    if (h.resistance_now_ohm !== null && h.resistance_now_ohm !== undefined) lines.push("Resistance today (" + h.resistance_basis + ") from " + fromEvents(h.resistance_from) + ".");
    if (fc && fc.message) lines.push("End of life: " + fc.message + ".");
    if (dated) lines.push("Trend: " + (SHAPES[fc.shape] || fc.shape) + " (odds of a bend against a straight line " + Number(fc.bend_odds).toPrecision(3) + "); " +
                       (has(fc.knee_efc) ? "knee at " + DL.num(fc.knee_efc, 0) + " EFC." : "no knee in the data yet (the forecast allows one ahead)."));
    $("health-note").textContent = lines.join(" ");

    const bands = [], series = [], vlines = [], hlines = [];
    const band = fc && fc.band;
    if (band && band.efc) {
      // the band's far end can fall steeply: it is clipped to the measured capacities' range
      bands.push({x: band.efc, lo: band.lo, hi: band.hi, color: "rgba(37,99,235,0.13)", yFit: false});
      series.push({x: band.efc, y: band.capacity_Ah, color: "#2563eb", width: 1.2, dash: [5, 3], label: "trend and 95 % band", yFit: false});
    }
    series.push(...byKind(withCap, "capacity_Ah", "capacity_interval95", 1));
    if (civ && has(h.efc_now)) {
      series.push({x: [h.efc_now, h.efc_now], y: civ, color: "#111827", width: 2});
      series.push({x: [h.efc_now], y: [h.capacity_now_Ah], color: "#111827", points: true, label: "today"});
    }
    if (fc && has(fc.knee_efc)) vlines.push({x: fc.knee_efc, color: "#7c3aed", label: "knee " + DL.num(fc.knee_efc, 0)});
    if (fc && has(fc.threshold_Ah)) hlines.push({y: fc.threshold_Ah, color: "#dc2626", label: "end of life " + DL.num(fc.threshold_Ah, 2) + " Ah"});
    if (fc && has(fc.eol_efc)) {
      vlines.push({x: fc.eol_efc, color: "#dc2626", label: "EOL " + DL.num(fc.eol_efc, 0) + " EFC"});
      if (fc.eol_efc_interval95) {
        const [a, b] = fc.eol_efc_interval95;
        if (has(a) && has(b) && fc.threshold_Ah) bands.push({x: [a, b], lo: [fc.threshold_Ah * 0.98, fc.threshold_Ah * 0.98], hi: [fc.threshold_Ah * 1.02, fc.threshold_Ah * 1.02], color: "rgba(220,38,38,0.18)"});
      }
    }
    new LinePlot($("plot-capacity"), {xLabel: "equivalent full cycles [EFC]", yLabel: "capacity [Ah]"})
      .draw({series, bands, hlines, vlines, xMin: 0, empty: "no capacity measured yet"});
    const rt = h.trend && h.trend.resistance;
    const rBands = rt && rt.efc.length > 1 ? [{x: rt.efc, lo: rt.lo.map(v => v * 1000), hi: rt.hi.map(v => v * 1000), color: "rgba(5,150,105,0.13)"}] : [];
    const rSeries = rt && rt.efc.length > 1 ? [{x: rt.efc, y: rt.value.map(v => v * 1000), color: "#059669", width: 1.2, label: "trend and 95 % band"}] : [];
    $("resistance-basis").textContent = refR ? "(at reference conditions)" : "";
    new LinePlot($("plot-resistance"), {xLabel: "equivalent full cycles [EFC]", yLabel: "resistance [mΩ]"})
      .draw({series: rSeries.concat(byKind(withR, rKey, refR ? "resistance_ref_interval95" : "resistance_interval95", 1000)), bands: rBands,
             xMin: 0, empty: "no load steps to measure resistance yet"});

    const cells = events.filter(e => e.cells && e.efc !== null);
    $("cells-card").hidden = !cells.length;
    if (cells.length) {
      const spread = e => [e.cells.rest_spread_V, e.cells.spread_V].find(v => v !== null && v !== undefined);
      const withSpread = cells.filter(e => spread(e) !== undefined);
      new LinePlot($("plot-cells"), {xLabel: "equivalent full cycles [EFC]", yLabel: "rest-voltage spread [mV]"})
        .draw({series: [{x: withSpread.map(e => e.efc), y: withSpread.map(e => spread(e) * 1000), color: "#7c3aed", points: true, label: "cell spread"}],
               xMin: 0, empty: "no rest voltages per cell yet"});
      const drifting = cells.filter(e => e.cells.drift);
      $("cells-note").textContent = drifting.length ? "A cell drifts away from the others in " + drifting.length + " event(s), latest " + drifting[drifting.length - 1].source + "." : "No cell drifts away from the others.";
    }

    const m = d.model;
    if (m && m.curves) {
      $("model-name").textContent = "(" + [m.name, m.family].filter(Boolean).join(", ") + ")";
      new LinePlot($("plot-model"), {xLabel: "discharged charge [Ah]", yLabel: "pack voltage [V]"})
        .draw({series: m.curves.map((c, k) => ({x: c.charge_Ah, y: c.voltage_V, color: COLORS[k % COLORS.length],
                                                  label: DL.num(c.c_rate, 1) + "C (" + DL.num(c.current_A, 1) + " A)"}))});
      $("model-note").textContent = [m.statement, m.note].filter(Boolean).join(" ");
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
        DL.el("td", {class: "num", text: DL.interval(e.capacity_interval95, 3)}),
        DL.el("td", {class: "num", text: DL.text(e, "resistance_ohm", 1, 1000)}),
        DL.el("td", {class: "num", text: DL.num(e.efc, 1)}), DL.el("td", {text: e.outlier ? "outlier" : (e.capacity_note || "")}),
        DL.el("td", {class: "num", text: DL.text(e, "resistance_ref_ohm", 1, 1000)}),
      ]));
    }
  }

  function showEndurance(r) {
    const t = $("endurance-result");
    t.replaceChildren();
    const cannot = r.cannot_deliver ? r.cannot_deliver.message : null;
    const rows = [["Mission", r.mission],
                  ["Pack as flown", r.cells_series + "S" + r.strings_parallel + "P" + (r.chemistry ? " " + r.chemistry : "") +
                   ", cutoff " + DL.num(r.cutoff_cell_V, 2) + " V/cell"]];
    if (cannot) rows.push(["Cannot fly", cannot]);
    const unc = r.uncertainty;
    rows.push(["Model", (r.model_family ? r.model_family + " (" + r.model + ")" : r.model) || DL.MISSING],
              ["Interval", unc && unc.available ? unc.method : "none (no parameter draws flown)"]);
    rows.push(["Completed", r.completed ? "yes" : "no (" + r.ended_by + ")"],
              ["Flight time", DL.durationText(r, "flight_time_s")],
              ["Endurance to cutoff", DL.durationText(r, "endurance_s")],
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
