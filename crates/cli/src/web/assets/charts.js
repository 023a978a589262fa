// The dashboard's charts: every signal the simulator samples (bus load and frames/s, each
// device's live values, each decoded PDO value) is kept here over the model's window, and any
// of them can be charted with uPlot (vendored, served by the dashboard itself).
//
// A chart follows the newest samples until it is zoomed (drag across it, or the mouse
// wheel) or panned (shift-drag); a double-click or "Live" follows again. A click places the
// armed cursor (A, then B): the readout gives both samples and their Δt and Δvalue. "Pause"
// freezes the picture while samples keep being kept; "CSV" saves the samples in view.
// Everything is drawn on canvases or placed through the CSS object model, as the page's
// Content-Security-Policy requires (no inline style attributes, no eval).
"use strict";

/** Seconds of samples kept per signal: the simulator's window (dashboard::WINDOW_S). */
const HISTORY_S = 300;
/** Hard bound on the samples a signal keeps (4 a second over the window, with room). */
const HISTORY_MAX = 2000;
const COLORS = ["#1f5fa8", "#c5221f", "#1e8e3e", "#e37400", "#8e24aa", "#00838f"];

/** Samples by signal key: { t: [seconds since start], v: [values], sig: last description }. */
const store = new Map();

function storeSample(sig, t, v) {
  let s = store.get(sig.key);
  if (!s) {
    s = { t: [], v: [], sig };
    store.set(sig.key, s);
  }
  s.sig = sig;
  if (s.t.length && t <= s.t[s.t.length - 1]) return;
  s.t.push(t);
  s.v.push(v);
  let drop = 0;
  while (drop < s.t.length && (t - s.t[drop] > HISTORY_S || s.t.length - drop > HISTORY_MAX)) drop++;
  if (drop) {
    s.t.splice(0, drop);
    s.v.splice(0, drop);
  }
}

/** Puts `/api/history` (the window so far) before the samples the snapshots bring. */
function storeHistory(series) {
  for (const [key, points] of Object.entries(series)) {
    const s = store.get(key);
    const first = s && s.t.length ? s.t[0] : Infinity;
    const older = points.filter(([t]) => t < first);
    if (!older.length) continue;
    if (s) {
      s.t.unshift(...older.map((p) => p[0]));
      s.v.unshift(...older.map((p) => p[1]));
    } else {
      store.set(key, { t: older.map((p) => p[0]), v: older.map((p) => p[1]), sig: null });
    }
  }
}

function fmt(v) {
  if (v == null || !Number.isFinite(v)) return "—";
  const a = Math.abs(v);
  if (a !== 0 && (a < 0.01 || a >= 1e6)) return v.toExponential(3);
  return String(Math.round(v * 1000) / 1000);
}

/** The y range: from zero for quantities that cannot be negative (or whose samples in view
 * are all zero or more), never empty, with a little room above. */
function yRange(nonNegative, min, max) {
  if (min == null || max == null || !Number.isFinite(min) || !Number.isFinite(max)) return [0, 1];
  if (nonNegative || min >= 0) {
    const top = max > 0 ? uPlot.rangeNum(0, max, 0.1, true)[1] : 1;
    return [0, top];
  }
  if (min === max) {
    const pad = Math.abs(min) * 0.1 || 1;
    return [min - pad, max + pad];
  }
  return uPlot.rangeNum(min, max, 0.1, true);
}

/** The index of the sample of `ts` nearest to `t` (ts ascending, not empty). */
function nearest(ts, t) {
  let lo = 0;
  let hi = ts.length - 1;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (ts[mid] < t) lo = mid; else hi = mid;
  }
  return Math.abs(ts[lo] - t) <= Math.abs(ts[hi] - t) ? lo : hi;
}

function csvField(text) {
  return /[",\n]/.test(text) ? `"${text.replace(/"/g, '""')}"` : text;
}

let nextColor = 0;

class Chart {
  constructor(host, key, onRemove) {
    this.key = key;
    this.color = COLORS[nextColor++ % COLORS.length];
    this.paused = false;
    this.zoomed = false;
    this.cursors = { A: null, B: null };
    this.armed = "A";
    this.lastCsv = "";
    this.el = document.createElement("div");
    this.el.className = "chart-card";
    this.el.dataset.signal = key;
    this.el.innerHTML = `
      <div class="chart-head">
        <b class="chart-title"></b>
        <span class="chart-state"></span>
        <span class="chart-tools">
          <button type="button" class="tool pause" title="Freeze the picture; samples are still kept">Pause</button>
          <button type="button" class="tool live" title="Follow the newest samples (or double-click the chart)">Live</button>
          <button type="button" class="tool arm-a" title="The next click on the chart places cursor A">A</button>
          <button type="button" class="tool arm-b" title="The next click on the chart places cursor B">B</button>
          <button type="button" class="tool clear" title="Remove both cursors">Clear</button>
          <button type="button" class="tool csv" title="Save the samples in view as CSV">CSV</button>
          <button type="button" class="tool remove" title="Remove this chart">×</button>
        </span>
      </div>
      <div class="chart-plot"></div>
      <div class="chart-readout">drag to zoom · wheel zooms · shift-drag pans · click places a cursor</div>`;
    host.appendChild(this.el);
    const q = (sel) => this.el.querySelector(sel);
    q(".pause").addEventListener("click", () => this.setPaused(!this.paused));
    q(".live").addEventListener("click", () => this.follow());
    q(".arm-a").addEventListener("click", () => this.arm("A"));
    q(".arm-b").addEventListener("click", () => this.arm("B"));
    q(".clear").addEventListener("click", () => {
      this.cursors = { A: null, B: null };
      this.arm("A");
      this.redraw();
    });
    q(".csv").addEventListener("click", () => this.exportCsv());
    q(".remove").addEventListener("click", () => {
      this.u.destroy();
      this.el.remove();
      onRemove(this);
    });
    this.build();
    this.arm("A");
    this.update();
  }

  sig() {
    const s = store.get(this.key);
    return (s && s.sig) || { key: this.key, label: this.key, unit: "", non_negative: false };
  }

  data() {
    const s = store.get(this.key);
    return s ? [s.t.slice(), s.v.slice()] : [[], []];
  }

  build() {
    const sig = this.sig();
    const plot = this.el.querySelector(".chart-plot");
    const chart = this;
    const opts = {
      width: Math.max(plot.clientWidth, 320),
      height: 190,
      legend: { show: false },
      scales: {
        // The samples' own time span, a second around a single one.
        x: { time: false, range: (u, min, max) => (min === max ? [min - 1, max + 1] : [min, max]) },
        y: { range: (u, min, max) => yRange(chart.sig().non_negative, min, max) },
      },
      axes: [
        { label: "s since the dashboard started", labelSize: 18, size: 34 },
        { label: sig.unit || "", labelSize: 18, size: 56 },
      ],
      series: [{ label: "t" }, { label: sig.label, stroke: this.color, width: 1.5, points: { show: false } }],
      cursor: {
        drag: { x: true, y: false, setScale: true },
        bind: {
          mousedown: (u, targ, handler) => (e) => {
            chart.downX = e.clientX;
            if (e.shiftKey) {
              chart.startPan(e);
              return null;
            }
            // A drag across the plot is a zoom (uPlot sets the x range at its end): from
            // then on the chart keeps that range rather than following the samples.
            const up = (m) => {
              document.removeEventListener("mouseup", up);
              if (Math.abs(m.clientX - e.clientX) > 3) chart.setZoomed(true);
            };
            document.addEventListener("mouseup", up);
            return handler(e);
          },
          dblclick: () => () => null,
        },
      },
      hooks: {
        draw: [(u) => chart.drawCursors(u)],
      },
    };
    this.u = new uPlot(opts, this.data(), plot);
    const over = this.u.over;
    over.addEventListener("click", (e) => {
      if (e.shiftKey || Math.abs(e.clientX - (this.downX ?? e.clientX)) > 3) return;
      const t = this.u.posToVal(e.offsetX, "x");
      this.place(this.armed, t);
    });
    over.addEventListener("dblclick", () => this.follow());
    over.addEventListener("wheel", (e) => {
      e.preventDefault();
      const { min, max } = this.u.scales.x;
      if (min == null || max == null) return;
      const at = this.u.posToVal(e.offsetX, "x");
      const k = e.deltaY < 0 ? 0.8 : 1.25;
      this.setZoomed(true);
      this.u.setScale("x", { min: at - (at - min) * k, max: at + (max - at) * k });
    }, { passive: false });
    this.el.querySelector(".chart-title").textContent = sig.unit ? `${sig.label} (${sig.unit})` : sig.label;
  }

  startPan(e) {
    const { min, max } = this.u.scales.x;
    if (min == null || max == null) return;
    const x0 = e.clientX;
    const perPx = (max - min) / this.u.over.clientWidth;
    this.setZoomed(true);
    const move = (m) => {
      const dt = (m.clientX - x0) * perPx;
      this.u.setScale("x", { min: min - dt, max: max - dt });
    };
    const up = () => {
      document.removeEventListener("mousemove", move);
      document.removeEventListener("mouseup", up);
    };
    document.addEventListener("mousemove", move);
    document.addEventListener("mouseup", up);
  }

  arm(which) {
    this.armed = which;
    this.el.querySelector(".arm-a").classList.toggle("armed", which === "A");
    this.el.querySelector(".arm-b").classList.toggle("armed", which === "B");
  }

  /** Places cursor `which` on the sample nearest to time `t`; A then arms B. */
  place(which, t) {
    const [ts, vs] = this.u.data;
    if (!ts.length) return;
    const i = nearest(ts, t);
    this.cursors[which] = { t: ts[i], v: vs[i] };
    if (which === "A") this.arm("B");
    this.redraw();
  }

  drawCursors(u) {
    const ctx = u.ctx;
    const { left, top, width, height } = u.bbox;
    for (const [name, c] of Object.entries(this.cursors)) {
      if (!c) continue;
      const x = Math.round(u.valToPos(c.t, "x", true));
      if (x < left || x > left + width) continue;
      ctx.save();
      ctx.strokeStyle = name === "A" ? "#e37400" : "#8e24aa";
      ctx.fillStyle = ctx.strokeStyle;
      ctx.lineWidth = 1.5 * devicePixelRatio;
      ctx.setLineDash([4 * devicePixelRatio, 3 * devicePixelRatio]);
      ctx.beginPath();
      ctx.moveTo(x, top);
      ctx.lineTo(x, top + height);
      ctx.stroke();
      ctx.font = `${11 * devicePixelRatio}px sans-serif`;
      ctx.fillText(name, x + 3 * devicePixelRatio, top + 12 * devicePixelRatio);
      ctx.restore();
    }
  }

  readout() {
    const { A, B } = this.cursors;
    const unit = this.sig().unit ? ` ${this.sig().unit}` : "";
    const one = (n, c) => `${n} ${fmt(c.t)} s = ${fmt(c.v)}${unit}`;
    const r = this.el.querySelector(".chart-readout");
    const parts = [];
    if (A) parts.push(one("A", A));
    if (B) parts.push(one("B", B));
    if (A && B) parts.push(`Δt ${fmt(B.t - A.t)} s`, `Δ ${fmt(B.v - A.v)}${unit}`);
    r.textContent = parts.length ? parts.join(" · ") : "drag to zoom · wheel zooms · shift-drag pans · click places a cursor";
    r.dataset.dt = A && B ? String(B.t - A.t) : "";
    r.dataset.dv = A && B ? String(B.v - A.v) : "";
  }

  redraw() {
    this.u.redraw(false, false);
    this.readout();
  }

  setZoomed(z) {
    this.zoomed = z;
    this.state();
  }

  setPaused(p) {
    this.paused = p;
    this.el.querySelector(".pause").textContent = p ? "Resume" : "Pause";
    this.state();
    if (!p) this.update();
  }

  state() {
    const s = [];
    if (this.paused) s.push("paused");
    if (this.zoomed) s.push("zoomed");
    this.el.querySelector(".chart-state").textContent = s.join(" · ");
    this.el.classList.toggle("paused", this.paused);
  }

  /** Follows the newest samples again (the x range fits the data). */
  follow() {
    this.setZoomed(false);
    this.update(true);
  }

  /** Shows the newest samples, keeping a zoomed x range; nothing while paused. */
  update(force) {
    if (this.paused && !force) return;
    if (this.zoomed) {
      // Keep the user's x range; setting it again fits the y axis to what is in view.
      const { min, max } = this.u.scales.x;
      this.u.setData(this.data(), false);
      this.u.setScale("x", { min, max });
    } else {
      this.u.setData(this.data(), true);
    }
    this.readout();
  }

  resize() {
    const plot = this.el.querySelector(".chart-plot");
    this.u.setSize({ width: Math.max(plot.clientWidth, 320), height: 190 });
  }

  /** The samples in view (all when not zoomed) as CSV, saved as a download. */
  exportCsv() {
    const [ts, vs] = this.u.data;
    const { min, max } = this.u.scales.x;
    const sig = this.sig();
    const head = `time_s,${csvField(sig.unit ? `${sig.label} (${sig.unit})` : sig.label)}`;
    const rows = [];
    for (let i = 0; i < ts.length; i++) {
      if (this.zoomed && (ts[i] < min || ts[i] > max)) continue;
      rows.push(`${ts[i]},${vs[i]}`);
    }
    this.lastCsv = [head, ...rows].join("\n") + "\n";
    const url = URL.createObjectURL(new Blob([this.lastCsv], { type: "text/csv" }));
    const a = document.createElement("a");
    a.href = url;
    a.download = `${this.key.replace(/[^A-Za-z0-9._-]+/g, "_")}.csv`;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
    this.el.querySelector(".chart-state").textContent = `${rows.length} samples saved`;
  }
}

/** The charts on the page, in order. */
const charts = [];

/** Writes the charts shown into the address (`#charts=KEY,KEY`), without a new history
 * entry. */
function rememberCharts() {
  const h = new URLSearchParams(location.hash.slice(1));
  h.set("charts", charts.map((c) => c.key).join(","));
  history.replaceState(null, "", `#${h.toString()}`);
}

function addChart(key) {
  if (charts.some((c) => c.key === key)) return;
  const c = new Chart(document.querySelector("#charts"), key, (gone) => {
    charts.splice(charts.indexOf(gone), 1);
    rememberCharts();
  });
  charts.push(c);
  rememberCharts();
}

/** Takes a snapshot's samples and moves the charts. */
function chartSnapshot(s) {
  for (const sig of s.signals) storeSample(sig, s.uptime_s, sig.value);
  for (const c of charts) c.update();
}

window.addEventListener("resize", () => charts.forEach((c) => c.resize()));

// The page script (app.js) and the browser test reach the charts through this.
window.cantwinCharts = { charts, addChart, chartSnapshot, storeHistory, store, yRange };
