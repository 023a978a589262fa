// The cantwin dashboard: renders the snapshots the simulator streams (Server-Sent Events)
// and posts the controls as JSON. The charts are charts.js's; the frame stream keeps every
// row the snapshots bring and marks where rows are missing.
"use strict";

const $ = (sel) => document.querySelector(sel);

// This run's secret, put in the page by the server: controls send it as a header, the event
// stream (which cannot send headers) as ?token=, needed when the dashboard serves remotely.
const TOKEN = document.querySelector('meta[name="cantwin-token"]').content;

function esc(v) {
  return String(v ?? "").replace(/[&<>"']/g, (c) => ({
    "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;",
  })[c]);
}

let last = null;
let deviceKey = "";

function showMessage(ok, text) {
  const m = $("#message");
  m.className = "message " + (ok ? "ok" : "error");
  m.textContent = text;
}

function fillSelect(sel, options) {
  const keep = sel.value;
  sel.innerHTML = options.map(([v, t]) => `<option value="${esc(v)}">${esc(t)}</option>`).join("");
  if (options.some(([v]) => v === keep)) sel.value = keep;
}

function refreshSelects(s) {
  const key = JSON.stringify([s.devices.map((d) => d.name), s.buses.map((b) => b.name)]);
  if (key === deviceKey) return;
  deviceKey = key;
  const devs = s.devices.map((d) => [d.name, `${d.name} (${d.kind})`]);
  document.querySelectorAll("select.devices").forEach((e) => fillSelect(e, devs));
  document.querySelectorAll("select.devices-with-all").forEach((e) =>
    fillSelect(e, [["all", "all nodes"], ...devs]));
  document.querySelectorAll("select.devices-or-none").forEach((e) =>
    fillSelect(e, [["", "—"], ...devs]));
  document.querySelectorAll("select.buses-or-none").forEach((e) =>
    fillSelect(e, [["", "—"], ...s.buses.map((b) => [b.name, b.name])]));
  const withInputs = s.devices.filter((d) => d.values.some((v) => v.role.endsWith("-input")));
  document.querySelectorAll("select.devices-with-inputs").forEach((e) =>
    fillSelect(e, withInputs.map((d) => [d.name, `${d.name} (${d.kind})`])));
  refreshInputs();
}

function refreshInputs() {
  if (!last) return;
  const form = $("#form-input");
  const dev = last.devices.find((d) => d.name === form.device.value);
  const inputs = dev ? dev.values.filter((v) => v.role.endsWith("-input")) : [];
  const key = inputs.map((v) => v.name).join(",");
  if (form.input.dataset.key === key) return;
  form.input.dataset.key = key;
  fillSelect(form.input, inputs.map((v) => [v.name,
    v.role === "digital-input" ? `${v.name} (0/1)` : `${v.name} (${v.min}…${v.max} ${v.unit})`]));
}

function led(kind, state) {
  return `<span class="led ${kind} ${esc(state)}" title="${kind.toUpperCase()}: ${esc(state)}"></span>`;
}

function age(ms) {
  if (ms == null) return "—";
  return ms < 10000 ? `${Math.round(ms)} ms` : `${(ms / 1000).toFixed(1)} s`;
}

function renderBuses(s) {
  $("#buses").innerHTML = s.buses.map((b) => `
    <div class="card" data-bus="${esc(b.name)}">
      <h3>${esc(b.name)} · ${esc(b.bit_rate)}</h3>
      <div class="stats">
        <div class="stat"><b class="load">${b.load.toFixed(1)} %</b><span>bus load (1 s)</span></div>
        <div class="stat"><b class="fps">${b.fps.toFixed(0)}</b><span>frames/s</span></div>
        <div class="stat"><b>${b.frames}</b><span>frames</span></div>
        <div class="stat"><b>${b.error_frames}</b><span>error frames</span></div>
      </div>
    </div>`).join("");
}

// The signal picker lists every signal by group; refilled when the set of signals changes.
let signalKey = "";
function refreshPicker(s) {
  const key = s.signals.map((g) => g.key).join("\n");
  if (key === signalKey) return;
  signalKey = key;
  const sel = $("#signal-picker");
  const keep = sel.value;
  const groups = new Map();
  for (const g of s.signals) {
    if (!groups.has(g.group)) groups.set(g.group, []);
    groups.get(g.group).push(g);
  }
  sel.innerHTML = [...groups].map(([name, sigs]) => `<optgroup label="${esc(name)}">${sigs.map((g) =>
    `<option value="${esc(g.key)}">${esc(g.label)}${g.unit ? ` (${esc(g.unit)})` : ""}</option>`).join("")}</optgroup>`).join("");
  if (s.signals.some((g) => g.key === keep)) sel.value = keep;
}

// The first snapshot opens the charts the address names (`#charts=KEY,KEY`, kept up to
// date as charts are added and removed, so a set of charts can be bookmarked), else a load
// and a frames/s chart per bus.
let chartsOpened = false;
function openDefaultCharts(s) {
  if (chartsOpened) return;
  chartsOpened = true;
  const named = new URLSearchParams(location.hash.slice(1)).get("charts");
  const keys = named
    ? named.split(",").filter((k) => k)
    : s.buses.flatMap((b) => [`bus/${b.name}/load`, `bus/${b.name}/fps`]);
  keys.forEach((k) => cantwinCharts.addChart(k));
}

function renderNodes(s) {
  $("#nodes tbody").innerHTML = s.nodes.map((n) => {
    const state = !n.powered ? "off" : (n.nmt ?? "—");
    const emcy = n.emcy
      ? `<span title="register ${esc(n.emcy.register)}, ${age(n.emcy.age_ms)} ago">${esc(n.emcy.code)} ${esc(n.emcy.meaning)}</span>`
      : "—";
    const ctl = `${esc(n.controller)}${n.connected ? "" : " · disconnected"} <small>TEC ${n.tec} REC ${n.rec}</small>`;
    return `<tr data-device="${esc(n.device)}">
      <td><b>${esc(n.device)}</b></td><td>${esc(n.kind)}</td><td>${esc(n.bus)}</td>
      <td class="node-id">${n.node_id ?? "—"}</td>
      <td class="nmt"><span class="state ${esc(state)}">${esc(state)}</span></td>
      <td class="age">${age(n.heartbeat_age_ms)}</td>
      <td>${esc(n.error_register ?? "—")}</td><td class="emcy">${emcy}</td><td>${ctl}</td>
      <td>${led("run", n.leds.run)}${led("err", n.leds.err)}</td></tr>`;
  }).join("");
}

function renderDevices(s) {
  $("#devices").innerHTML = s.devices.filter((d) => d.values.length > 0).map((d) => {
    const analog = d.values.filter((v) => !v.role.startsWith("digital"));
    const digital = d.values.filter((v) => v.role.startsWith("digital"));
    const nums = analog.map((v) => `<span class="value" data-value="${esc(v.name)}"
      data-signal="${esc(`device/${d.name}/${v.name}`)}" title="click: chart it">
      <span class="name">${esc(v.name)}</span>${Number(v.value).toFixed(2)} ${esc(v.unit)}</span>`).join("");
    const bits = digital.map((v) => `<span data-value="${esc(v.name)}" data-on="${v.value ? 1 : 0}"
      data-signal="${esc(`device/${d.name}/${v.name}`)}" title="click: chart it">
      <i class="lamp ${v.role === "digital-output" ? "out" : "in"} ${v.value ? "on" : ""}"></i> ${esc(v.name)}</span>`).join("");
    return `<div class="panel" data-device="${esc(d.name)}">
      <h3>${esc(d.name)} <small>(${esc(d.kind)})</small></h3>
      <div class="values">${nums}</div>
      <div class="bits">${bits}</div></div>`;
  }).join("");
}

// The scrolling trace: every row of every snapshot, newest first, the last TABLE_MAX kept.
// Rows carry the simulator's numbers: a jump in them is marked, never silent.
const TABLE_MAX = 2000;
const stream = { expected: null, paused: false, held: [], heldLost: 0, rows: 0, gaps: 0 };

function frameRow(f) {
  return `<tr class="${esc(f.flag)}" data-seq="${f.seq}"><td>${f.seq}</td>
    <td>${f.t_ms.toFixed(3)}</td><td>${esc(f.bus)}</td><td>${esc(f.from)}</td>
    <td>${esc(f.id)}</td><td>${esc(f.data)}</td><td>${esc(f.text)}</td></tr>`;
}

function gapRow(n, why) {
  stream.gaps += 1;
  return `<tr class="gap" data-dropped="${n}"><td colspan="7">⋯ dropped ${n} ${n === 1 ? "row" : "rows"}: ${esc(why)}</td></tr>`;
}

/** The rows (oldest first) of one snapshot, with markers where rows are missing. */
function streamItems(s) {
  const items = [];
  const first = s.frames.length ? s.frames[0].seq : s.next_seq;
  if (stream.expected != null && first > stream.expected) {
    items.push({ gap: first - stream.expected,
      why: "more than 2048 rows between two snapshots, or this page missed a snapshot" });
  }
  if (s.missed > 0) {
    items.push({ gap: s.missed, why: "the bus tap was full (more than 8192 events between two snapshots); they have no number" });
  }
  for (const f of s.frames) items.push({ f });
  stream.expected = s.next_seq;
  return items;
}

function showItems(items) {
  if (!items.length) return;
  const html = items.slice().reverse().map((i) => (i.f ? frameRow(i.f) : gapRow(i.gap, i.why))).join("");
  const body = $("#frames tbody");
  body.insertAdjacentHTML("afterbegin", html);
  while (body.rows.length > TABLE_MAX) body.deleteRow(body.rows.length - 1);
  stream.rows = body.rows.length;
}

function renderFrames(s) {
  const items = streamItems(s);
  if (stream.paused) {
    stream.held.push(...items);
    if (stream.held.length > TABLE_MAX) {
      const lost = stream.held.splice(0, stream.held.length - TABLE_MAX);
      stream.heldLost += lost.reduce((n, i) => n + (i.f ? 1 : 0), 0);
    }
  } else {
    showItems(items);
  }
  $("#frames-note").textContent = `(every frame, newest first; the last ${TABLE_MAX} rows are kept, gaps are marked)`;
  $("#frames-count").textContent = stream.paused
    ? `paused · ${stream.held.length} rows waiting`
    : `${stream.rows} rows · ${s.missed_total} events missed by the tap since the start`;
}

function resumeFrames() {
  stream.paused = false;
  const items = stream.held;
  if (stream.heldLost) {
    items.unshift({ gap: stream.heldLost, why: `more than ${TABLE_MAX} rows arrived while paused` });
  }
  stream.held = [];
  stream.heldLost = 0;
  showItems(items);
}

$("#frames-pause").addEventListener("click", () => {
  if (stream.paused) resumeFrames(); else stream.paused = true;
  $("#frames-pause").textContent = stream.paused ? "Resume" : "Pause";
});

// The fixed trace: one row per identifier, overwritten in place.
function renderFixed(s) {
  if ($("#fixed-view").classList.contains("hidden")) return;
  const ms = (v) => (v == null ? "—" : v.toFixed(3));
  $("#fixed tbody").innerHTML = s.fixed.map((r) => {
    const bytes = r.data.split(" ").map((b, i) => (r.changed >> i & 1 ? `<b class="chg">${esc(b)}</b>` : esc(b))).join(" ");
    return `<tr data-id="${esc(r.id)}" data-bus="${esc(r.bus)}"><td>${esc(r.bus)}</td><td>${esc(r.id)}</td>
      <td class="count">${r.count}</td><td class="cycle">${ms(r.cycle_ms)}</td><td>${ms(r.min_ms)}</td><td>${ms(r.max_ms)}</td>
      <td>${ms(r.age_ms)}</td><td>${bytes}</td><td>${esc(r.text)}</td></tr>`;
  }).join("") + (s.fixed_overflow
    ? `<tr class="gap"><td colspan="9">${s.fixed_overflow} frames of further identifiers not kept (bounded)</td></tr>` : "");
}

function showView(fixed) {
  $("#fixed-view").classList.toggle("hidden", !fixed);
  $("#scroll-view").classList.toggle("hidden", fixed);
  $("#view-fixed").classList.toggle("active", fixed);
  $("#view-scroll").classList.toggle("active", !fixed);
  $("#view-fixed").setAttribute("aria-selected", String(fixed));
  $("#view-scroll").setAttribute("aria-selected", String(!fixed));
  if (fixed && last) renderFixed(last);
}
$("#view-scroll").addEventListener("click", () => showView(false));
$("#view-fixed").addEventListener("click", () => showView(true));

function render(s) {
  last = s;
  $("#scenario").textContent = s.scenario;
  $("#time").textContent = `${(s.time_ms / 1000).toFixed(1)} s`;
  refreshSelects(s);
  refreshPicker(s);
  renderBuses(s);
  renderNodes(s);
  renderDevices(s);
  cantwinCharts.chartSnapshot(s);
  openDefaultCharts(s);
  renderFrames(s);
  renderFixed(s);
}

// The window so far, drawn before the snapshots' samples (a page opened late sees the past).
async function loadHistory() {
  try {
    const r = await fetch("/api/history", { headers: { "X-Cantwin-Token": TOKEN } });
    if (!r.ok) return;
    const h = await r.json();
    cantwinCharts.storeHistory(h.series || {});
    cantwinCharts.charts.forEach((c) => c.update());
  } catch (err) {
    showMessage(false, `the charts' history could not be read: ${err}`);
  }
}

function connect() {
  const es = new EventSource(`/events?token=${encodeURIComponent(TOKEN)}`);
  es.addEventListener("snapshot", (e) => {
    $("#link").className = "link up";
    $("#link").textContent = "live";
    render(JSON.parse(e.data));
  });
  es.onerror = () => {
    $("#link").className = "link down";
    $("#link").textContent = "disconnected";
  };
}

async function post(path, body) {
  try {
    const r = await fetch(path, {
      method: "POST",
      headers: { "Content-Type": "application/json", "X-Cantwin-Token": TOKEN },
      body: JSON.stringify(body),
    });
    const a = await r.json().catch(() => ({ ok: false, message: `HTTP ${r.status}` }));
    showMessage(r.ok && a.ok, a.message || `HTTP ${r.status}`);
  } catch (err) {
    showMessage(false, `request failed: ${err}`);
  }
}

function formData(form) {
  const o = {};
  new FormData(form).forEach((v, k) => { o[k] = v; });
  return o;
}

function control(id, path, build) {
  $(id).addEventListener("submit", (e) => {
    e.preventDefault();
    const o = formData(e.target);
    // The button pressed (Read or Write) names the operation.
    if (e.submitter && e.submitter.name) o[e.submitter.name] = e.submitter.value;
    post(path, build(o));
  });
}

control("#form-nmt", "/api/nmt", (o) => o);
control("#form-input", "/api/input", (o) => o);
control("#form-sdo", "/api/sdo", (o) => o);
control("#form-power", "/api/power", (o) => o);
control("#form-fault", "/api/fault", (o) => {
  if (o.count) o.count = Number(o.count);
  return o;
});
$("#form-input").device.addEventListener("change", refreshInputs);
$("#form-chart").addEventListener("submit", (e) => {
  e.preventDefault();
  const key = $("#signal-picker").value;
  if (key) cantwinCharts.addChart(key);
});
$("#devices").addEventListener("click", (e) => {
  const el = e.target.closest("[data-signal]");
  if (el) cantwinCharts.addChart(el.dataset.signal);
});

loadHistory();
connect();
