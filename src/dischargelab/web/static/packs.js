// dischargelab pack list: rows from /api/packs; the upload form posts to /api/upload.
"use strict";

(function () {
  const $ = id => document.getElementById(id);
  const RELOAD_MS = 2000;
  let chosen = null;
  let again = null;

  function healthCell(r) {
    const fraction = r.capacity_fraction;
    if (fraction === null || fraction === undefined || !isFinite(fraction)) return DL.el("td", {text: DL.MISSING});
    const pct = Math.round(fraction * 100);
    const fill = DL.el("span");
    fill.style.width = Math.max(0, Math.min(100, pct)) + "%";   // CSSOM: the CSP allows no inline style
    const bar = DL.el("span", {class: "bar" + (fraction < 0.8 ? " bad" : fraction < 0.9 ? " warn" : "")}, [fill]);
    return DL.el("td", {}, [DL.el("span", {class: "health", text: DL.text(r, "capacity_fraction")}), bar]);
  }

  async function load() {
    try {
      const data = await DL.api("/api/packs");
      const rows = data.rows || [];
      const body = $("packs").querySelector("tbody");
      body.replaceChildren();
      const names = $("pack-names");
      names.replaceChildren();
      for (const r of rows) {
        const link = DL.el("a", {href: "/packs/" + encodeURIComponent(r.name), text: r.name});
        const nameCell = [link];
        if (r.recomputing) nameCell.push(DL.el("span", {class: "muted", text: " recomputing …"}));
        if (r.error) nameCell.push(DL.el("span", {class: "muted", text: " " + r.error}));
        body.append(DL.el("tr", {"data-pack": r.name}, [
          DL.el("td", {}, nameCell),
          DL.el("td", {class: "num", text: String(r.events)}),
          DL.el("td", {class: "num", text: DL.text(r, "efc", 1)}),
          DL.el("td", {class: "num", text: DL.text(r, "capacity_Ah", 3)}),
          healthCell(r),
          DL.el("td", {class: "num", text: DL.text(r, "resistance_ohm", 1, 1000)}),
          DL.el("td", {class: "num", text: DL.text(r, "eol_efc", 0)}),
          DL.el("td", {class: "num", text: r.text ? r.text.eol_efc_interval95 : DL.interval(r.eol_efc_interval95, 0)}),
        ]));
        names.append(DL.el("option", {value: r.name}));
      }
      $("empty").hidden = rows.length > 0;
      $("count").textContent = rows.length + (rows.length === 1 ? " pack" : " packs");
      window.__packs = {loaded: true, rows: rows};
      // figures older than their pack's data are being recomputed by the server: look again
      clearTimeout(again);
      if (data.recompute_problem) DL.showMessage(data.recompute_problem, "error");
      else if (rows.some(r => r.recomputing)) again = setTimeout(load, RELOAD_MS);
    } catch (err) {
      DL.showMessage(err.message, "error");
      window.__packs = {loaded: true, error: err.message};
    }
  }

  function pick(file) {
    chosen = file;
    $("drop").firstChild.textContent = file ? file.name + " (" + Math.ceil(file.size / 1024) + " kB) " : "Drop a log file here, or ";
  }

  document.addEventListener("DOMContentLoaded", () => {
    const drop = $("drop");
    drop.addEventListener("dragover", e => { e.preventDefault(); drop.classList.add("over"); });
    drop.addEventListener("dragleave", () => drop.classList.remove("over"));
    drop.addEventListener("drop", e => {
      e.preventDefault();
      drop.classList.remove("over");
      if (e.dataTransfer.files.length) pick(e.dataTransfer.files[0]);
    });
    $("upload-file").addEventListener("change", e => pick(e.target.files[0] || null));
    $("upload").addEventListener("submit", async e => {
      e.preventDefault();
      const file = chosen || $("upload-file").files[0];
      if (!file) { DL.showMessage("choose or drop a log file first", "error"); return; }
      const form = new FormData();
      form.append("pack", $("upload-pack").value.trim());
      form.append("file", file, file.name);
      $("upload-button").disabled = true;
      $("upload-result").textContent = "uploading " + file.name + " …";
      try {
        const r = await DL.api("/api/upload", {method: "POST", body: form});
        const added = (r.added || []).length, skipped = (r.skipped || []).length;
        $("upload-result").textContent = added ? file.name + ": added, " + (r.events || 0) + " events"
          : skipped ? file.name + ": already in the logbook" : file.name + ": nothing added";
        DL.showMessage("");
        await load();
      } catch (err) {
        $("upload-result").textContent = "";
        DL.showMessage(err.message, "error");
      } finally {
        $("upload-button").disabled = false;
      }
    });
    load();
  });
})();
