// dischargelab: helpers shared by the pages (fetching JSON, formatting numbers).
"use strict";

(function (global) {
  async function api(path, options) {
    const response = await fetch(path, Object.assign({credentials: "same-origin"}, options || {}));
    let body = null;
    try { body = await response.json(); } catch (e) { body = null; }
    if (!response.ok) {
      const reason = body && body.error ? body.error : response.status + " " + response.statusText;
      const err = new Error(reason);
      err.status = response.status;
      throw err;
    }
    return body;
  }

  function postJSON(path, data) {
    return api(path, {method: "POST", headers: {"Content-Type": "application/json"},
                      body: JSON.stringify(data || {})});
  }

  // The twins of dischargelab/formatting.py: one mark for no value, toFixed's rounding (the
  // exact value, half away from zero), an unbounded end of an interval written "open".
  const MISSING = "-", OPEN = "open", SEPARATOR = " - ";

  function num(v, digits) {
    if (v === null || v === undefined || !isFinite(v)) return MISSING;
    return Number(v).toFixed(digits === undefined ? 3 : digits);
  }

  function interval(pair, digits, scale) {
    if (!pair || pair.length !== 2 || (pair[0] === null && pair[1] === null)) return MISSING;
    const k = scale === undefined ? 1 : scale;
    return pair.map(v => (v === null || v === undefined ? OPEN : num(v * k, digits))).join(SEPARATOR);
  }

  // a figure as the server wrote it (the JSON's ``text``), else written here the same way
  function text(obj, key, digits, scale) {
    if (obj && obj.text && typeof obj.text[key] === "string") return obj.text[key];
    const v = obj ? obj[key] : null;
    return (v === null || v === undefined) ? MISSING : num(v * (scale === undefined ? 1 : scale), digits);
  }

  // formatting.duration's twin: "42 s" under a minute, "69 min 29 s" under two hours, then
  // "2 h 05 min"; rounded to the last unit shown as toFixed rounds; "-" before a negative,
  // "+" before a positive one when signed
  function duration(seconds, signed) {
    if (seconds === null || seconds === undefined || typeof seconds === "boolean" ||
        !isFinite(seconds)) return MISSING;
    const v = Number(seconds), a = Math.abs(v);
    const total = Number(a.toFixed(0));
    let body;
    if (total < 60) body = total + " s";
    else if (total < 7200) body = Math.floor(total / 60) + " min " + String(total % 60).padStart(2, "0") + " s";
    else {
      const minutes = Number((a / 60).toFixed(0));
      body = Math.floor(minutes / 60) + " h " + String(minutes % 60).padStart(2, "0") + " min";
    }
    if (total === 0) return body;
    return (v < 0 ? "-" : signed ? "+" : "") + body;
  }

  // a duration as the server wrote it (the JSON's ``text``), else written here the same way
  function durationText(obj, key) {
    if (obj && obj.text && typeof obj.text[key] === "string") return obj.text[key];
    return duration(obj ? obj[key] : null);
  }

  function el(tag, attrs, children) {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === "text") node.textContent = v; else node.setAttribute(k, v);
    }
    for (const c of children || []) node.append(c);
    return node;
  }

  function showMessage(text, kind) {
    const box = document.getElementById("message");
    if (!box) return;
    box.hidden = !text;
    box.textContent = text || "";
    box.className = "message " + (kind || "error");
  }

  global.DL = {api, postJSON, num, interval, text, duration, durationText, el, showMessage,
               MISSING};
})(window);
