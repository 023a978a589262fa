// The cantwin dashboard: renders the snapshots the simulator streams (Server-Sent Events)
// and posts the controls as JSON. The charts arrive as SVG drawn by the simulator.
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
      <div class="charts">${b.charts.join("")}</div>
    </div>`).join("");
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
    const nums = analog.map((v) => `<span class="value" data-value="${esc(v.name)}">
      <span class="name">${esc(v.name)}</span>${Number(v.value).toFixed(2)} ${esc(v.unit)}</span>`).join("");
    const bits = digital.map((v) => `<span data-value="${esc(v.name)}" data-on="${v.value ? 1 : 0}">
      <i class="lamp ${v.role === "digital-output" ? "out" : "in"} ${v.value ? "on" : ""}"></i> ${esc(v.name)}</span>`).join("");
    return `<div class="panel" data-device="${esc(d.name)}">
      <h3>${esc(d.name)} <small>(${esc(d.kind)})</small></h3>
      <div class="values">${nums}</div>
      <div class="bits">${bits}</div>
      <div class="charts">${d.charts.join("")}</div></div>`;
  }).join("");
}

function renderFrames(s) {
  $("#frames-note").textContent = s.missed ? `(${s.missed} events missed)` : "(newest first)";
  $("#frames tbody").innerHTML = s.frames.map((f) => `<tr class="${esc(f.flag)}">
    <td>${f.t_ms.toFixed(3)}</td><td>${esc(f.bus)}</td><td>${esc(f.from)}</td>
    <td>${esc(f.id)}</td><td>${esc(f.data)}</td><td>${esc(f.text)}</td></tr>`).join("");
}

function render(s) {
  last = s;
  $("#scenario").textContent = s.scenario;
  $("#time").textContent = `${(s.time_ms / 1000).toFixed(1)} s`;
  refreshSelects(s);
  renderBuses(s);
  renderNodes(s);
  renderDevices(s);
  renderFrames(s);
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
    post(path, build(formData(e.target)));
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

connect();
