// The view's page. It pulls: /state, then the frame the state names, then draws and asks
// again, at most MAX_RATE_HZ times a second. A slow browser asks less often and the server
// never queues for it; the boxes drawn are those of the frame shown (the state pairs them).
// No library: the plots are a few lines of canvas below. `window.slipstream` holds what was
// drawn, for the tests and for anyone curious in the console.
"use strict";

const MAX_RATE_HZ = 20;
const SERIES_S = 60;
const PAGE_ID = Math.random().toString(36).slice(2, 10);
const COLORS = { truth: "#00d0e0", detection: "#30d050", lead: "#ff9a1a", ego: "#3a7bff", other: "#9aa3ad",
                 text: "#d8dee6", dim: "#8a94a3", grid: "#2b323c", violet: "#c07aff", red: "#ff5050" };

const view = (window.slipstream = {
  updates: 0, frames: 0, failures: 0, series: [], last: null, shown: null, drawn: null, narrow: null, paused: false,
});

const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const fmt = (v, digits, unit) => (v === null || v === undefined || !isFinite(v) ? "–" : v.toFixed(digits) + (unit || ""));

// A recording (`slipstream view FILE.mcap`): play, pause, move it in simulated time and set
// its speed; the slider follows the replay except while it is being dragged. The replay waits
// for a page: the first page that sees it paused at its start plays it.
let dragging = false, asked = false;
$("replay-rate").addEventListener("change", (e) => fetch("replay?rate=" + e.target.value));
$("replay-play").addEventListener("click", () => {
  const playing = view.last && view.last.replay && view.last.replay.playing;
  fetch("replay?play=" + (playing ? 0 : 1));
});
$("replay-slider").addEventListener("input", () => { dragging = true; });
$("replay-slider").addEventListener("change", (e) => {
  dragging = false;
  fetch("replay?seek=" + e.target.value);
});

function drawReplay(replay) {
  $("replay").hidden = !replay;
  if (!replay) return;
  if (!asked) {
    asked = true;
    if (!replay.playing && replay.t_s === 0) fetch("replay?play=1");
  }
  const rate = $("replay-rate");
  if (document.activeElement !== rate && rate.value !== String(replay.rate)) rate.value = String(replay.rate);
  const end = replay.duration_s === null ? Math.max(replay.t_s, 1) : replay.duration_s;
  const slider = $("replay-slider");
  slider.max = end.toFixed(1);
  if (!dragging) slider.value = replay.t_s.toFixed(1);
  $("replay-play").textContent = replay.playing ? "pause" : "play";
  $("replay-time").textContent = `${replay.t_s.toFixed(1)} / ${replay.duration_s === null ? "?" : end.toFixed(1)} s simulated`;
}

// Freezing the page is not pausing the loop or the replay: a word of its own.
$("freeze").addEventListener("click", () => {
  view.paused = !view.paused;
  $("freeze").textContent = view.paused ? "unfreeze" : "freeze";
});

async function update() {
  const newest = view.series.length ? view.series[view.series.length - 1].t_s : null;
  const resp = await fetch("state" + (newest === null ? "" : "?since=" + newest));
  if (!resp.ok) throw new Error("state: HTTP " + resp.status);
  const state = await resp.json();
  mergeSeries(state.series);
  view.last = state;
  drawFigures(state);
  drawPlots();
  drawBirdseye(state.scene);
  drawTables(state);
  drawReplay(state.replay);
  if (state.front && (!view.shown || view.shown.stamp !== state.front.stamp)) await showFront(state.front);
  if (state.narrow && (!view.narrow || view.narrow.stamp !== state.narrow.stamp)) await showNarrow(state.narrow);
  view.updates += 1;
}

function mergeSeries(fresh) {
  if (!fresh.length) return;
  const last = view.series.length ? view.series[view.series.length - 1].t_s : -Infinity;
  // The server answers with everything kept when the run started again.
  view.series = fresh[0].t_s <= last ? fresh.slice() : view.series.concat(fresh);
  const from = view.series[view.series.length - 1].t_s - SERIES_S;
  let cut = 0;
  while (cut < view.series.length && view.series[cut].t_s < from) cut += 1;
  if (cut) view.series = view.series.slice(cut);
}

/// The width to ask a frame at: what the canvas shows on screen, never more than the frame.
function wantedWidth(canvas, frameWidth) {
  const onScreen = Math.round(canvas.clientWidth * (window.devicePixelRatio || 1));
  return Math.max(16, Math.min(frameWidth, onScreen || frameWidth));
}

async function fetchFrame(camera, stamp, width) {
  const resp = await fetch(`frame?camera=${camera}&stamp=${stamp}&w=${width}&page=${PAGE_ID}`);
  if (!resp.ok) return null;
  const bitmap = await createImageBitmap(await resp.blob());
  // Stamps stay strings: nanoseconds since the epoch are beyond a JavaScript number's precision.
  return { bitmap, stamp: resp.headers.get("X-Frame-Stamp") };
}

async function showFront(shot) {
  const canvas = $("front"), overlay = $("front-boxes");
  const got = await fetchFrame("front", shot.stamp, wantedWidth(canvas, shot.width));
  if (!got) return;
  const { bitmap } = got;
  for (const c of [canvas, overlay]) {
    if (c.width !== bitmap.width || c.height !== bitmap.height) { c.width = bitmap.width; c.height = bitmap.height; }
  }
  canvas.getContext("2d").drawImage(bitmap, 0, 0);
  const scale = bitmap.width / shot.width;
  // The boxes belong to the frame the state named; a frame no longer kept comes without them.
  const boxes = got.stamp === shot.stamp ? shot.boxes : [];
  drawBoxes(overlay, boxes, scale);
  view.shown = { stamp: got.stamp, width: bitmap.width, height: bitmap.height, frameWidth: shot.width };
  view.frames += 1;
  $("camera-info").textContent = `${shot.width}×${shot.height}, shown at ${bitmap.width}×${bitmap.height}` +
    (shot.detected ? "" : " (no detections for this frame)");
}

const LABEL_H = 14;

// Where a label goes: above its box, moved up (then below the box) past the labels already
// placed, so that two boxes side by side or nested never print over each other.
function labelSlot(placed, x, y, w, below) {
  const overlaps = (top) => placed.some((r) => x < r.x + r.w && r.x < x + w && top < r.y + LABEL_H && r.y < top + LABEL_H);
  for (let top = y - LABEL_H - 1; top >= 0; top -= LABEL_H) if (!overlaps(top)) return top;
  for (let top = below; ; top += LABEL_H) if (!overlaps(top)) return top;
}

function drawBoxes(overlay, boxes, scale) {
  const g = overlay.getContext("2d");
  g.clearRect(0, 0, overlay.width, overlay.height);
  g.font = "12px system-ui, sans-serif";
  const drawn = [], labels = [];
  for (const b of boxes) {
    const x0 = b.u0 * scale, y0 = b.v0 * scale, x1 = b.u1 * scale, y1 = b.v1 * scale;
    g.strokeStyle = COLORS[b.kind];
    g.lineWidth = b.kind === "truth" ? 1 : b.kind === "lead" ? 3 : 2;
    g.strokeRect(x0, y0, x1 - x0, y1 - y0);
    if (b.kind !== "truth") {
      const label = `#${b.id} ${fmt(b.distance_m, 0, " m")}${b.kind === "lead" ? " lead" : ""}`;
      const w = g.measureText(label).width + 6;
      const top = labelSlot(labels, x0, y0, w, y1 + 1);
      labels.push({ x: x0, y: top, w, text: label });
      g.fillStyle = "rgba(0,0,0,0.6)";
      g.fillRect(x0, top, w, LABEL_H);
      g.fillStyle = COLORS[b.kind];
      g.fillText(label, x0 + 3, top + LABEL_H - 3);
    }
    drawn.push({ kind: b.kind, id: b.id, x0, y0, x1, y1 });
  }
  view.drawn = { scale, boxes: drawn, labels };
}

async function showNarrow(other) {
  $("narrow-panel").hidden = false;
  const canvas = $("narrow");
  const got = await fetchFrame("narrow", other.stamp, wantedWidth(canvas, other.width));
  if (!got) return;
  if (canvas.width !== got.bitmap.width || canvas.height !== got.bitmap.height) {
    canvas.width = got.bitmap.width; canvas.height = got.bitmap.height;
  }
  canvas.getContext("2d").drawImage(got.bitmap, 0, 0);
  view.narrow = { stamp: got.stamp };
}

function drawFigures(state) {
  const s = view.series.length ? view.series[view.series.length - 1] : null;
  $("mode").textContent = s && s.mode ? s.mode : "–";
  $("warnings").textContent = s && s.warnings.length ? s.warnings.join(", ") : "";
  $("speed").textContent = s ? fmt(s.speed_mps, 1, " m/s") : "–";
  $("set-speed").textContent = s ? fmt(s.set_speed_mps, 1, " m/s") : "–";
  $("gap").textContent = s ? fmt(s.gap_m, 1, " m") : "–";
  $("desired-gap").textContent = s ? fmt(s.desired_gap_m, 1, " m") : "–";
  $("time-gap").textContent = s ? fmt(s.time_gap_s, 1, " s") : "–";
  $("ttc").textContent = s ? fmt(s.ttc_s, 1, " s") : "–";
  const sim = state.top.sim;
  $("clock").textContent = sim ? `t = ${sim.sim_time_s.toFixed(1)} s, step ${sim.step}, ` +
    `×${sim.real_time_factor.toFixed(2)} real time (${sim.mode})` : "no simulator clock seen";
}

/// Lines over the last minute: `lines` are [label, colour, value of a sample or null].
function plot(canvas, title, unit, lines) {
  const g = canvas.getContext("2d"), w = canvas.width, h = canvas.height;
  const pad = { l: 44, r: 8, t: 16, b: 24 };
  g.clearRect(0, 0, w, h);
  const data = view.series;
  if (!data.length) return;
  const t1 = data[data.length - 1].t_s, t0 = t1 - SERIES_S;
  let lo = Infinity, hi = -Infinity;
  for (const s of data) for (const [, , f] of lines) { const v = f(s); if (v !== null && isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); } }
  if (!isFinite(lo)) { lo = 0; hi = 1; }
  if (hi - lo < 1e-6) { lo -= 1; hi += 1; }
  const span = hi - lo; lo -= span * 0.08; hi += span * 0.08;
  const x = (t) => pad.l + ((t - t0) / SERIES_S) * (w - pad.l - pad.r);
  const y = (v) => pad.t + (1 - (v - lo) / (hi - lo)) * (h - pad.t - pad.b);
  g.font = "10px system-ui, sans-serif"; g.strokeStyle = COLORS.grid; g.fillStyle = COLORS.dim; g.lineWidth = 1;
  for (let k = 0; k <= 3; k += 1) {
    const v = lo + ((hi - lo) * k) / 3;
    g.beginPath(); g.moveTo(pad.l, y(v)); g.lineTo(w - pad.r, y(v)); g.stroke();
    g.fillText(v.toFixed(Math.abs(hi - lo) < 10 ? 1 : 0), 4, y(v) + 3);
  }
  // The time axis: simulated seconds, a tick every 10 s.
  g.fillStyle = COLORS.dim; g.strokeStyle = COLORS.grid;
  for (let t = Math.ceil(t0 / 10) * 10; t <= t1; t += 10) {
    if (t < 0) continue;
    g.beginPath(); g.moveTo(x(t), pad.t); g.lineTo(x(t), h - pad.b); g.stroke();
    g.fillText(`${t.toFixed(0)} s`, x(t) - 8, h - pad.b + 11);
  }
  g.font = "11px system-ui, sans-serif";
  g.fillText(`${title} (${unit})`, pad.l, 11);
  let legendX = pad.l + g.measureText(`${title} (${unit})`).width + 14;
  for (const [label, color, f] of lines) {
    g.strokeStyle = color; g.lineWidth = 1.5; g.beginPath();
    let pen = false;
    for (const s of data) {
      const v = f(s);
      if (v === null || !isFinite(v)) { pen = false; continue; }
      if (pen) g.lineTo(x(s.t_s), y(v)); else g.moveTo(x(s.t_s), y(v));
      pen = true;
    }
    g.stroke();
    g.fillStyle = color; g.fillText(label, legendX, 11); legendX += g.measureText(label).width + 12;
  }
}

// One unit system on the page: SI (m, s, m/s, m/s²), as every topic carries it.
function drawPlots() {
  plot($("plot-speed"), "speed", "m/s", [["speed", COLORS.ego, (s) => s.speed_mps], ["set", COLORS.dim, (s) => s.set_speed_mps]]);
  plot($("plot-gap"), "gap", "m", [["measured", COLORS.detection, (s) => s.gap_m], ["wanted", COLORS.lead, (s) => s.desired_gap_m], ["true", COLORS.truth, (s) => s.truth_gap_m]]);
  plot($("plot-accel"), "acceleration", "m/s²", [["ego", COLORS.violet, (s) => s.accel_mps2]]);
  plot($("plot-timegap"), "time gap", "s", [["set", COLORS.dim, (s) => s.time_gap_s], ["actual", COLORS.detection,
    (s) => (s.gap_m !== null && s.speed_mps > 1 ? s.gap_m / s.speed_mps : null)]]);
}

/// The road and vehicles around the ego, ahead up: 100 m ahead, 30 m behind.
function drawBirdseye(scene) {
  const canvas = $("birdseye"), g = canvas.getContext("2d"), w = canvas.width, h = canvas.height;
  g.clearRect(0, 0, w, h);
  if (!scene) return;
  const ahead = 100, behind = 30, scale = h / (ahead + behind);
  const px = (x, y) => [w / 2 - y * scale, h - (x + behind) * scale];
  for (const line of scene.road) {
    g.strokeStyle = line.edge ? "#e8e8e8" : "#6a717b"; g.lineWidth = line.edge ? 2 : 1;
    g.setLineDash(line.edge ? [] : [6, 6]); g.beginPath();
    line.points.forEach(([x, y], i) => { const [u, v] = px(x, y); if (i) g.lineTo(u, v); else g.moveTo(u, v); });
    g.stroke();
  }
  g.setLineDash([]);
  for (const b of scene.vehicles) {
    const [u, v] = px(b.x_m, b.y_m);
    g.save(); g.translate(u, v); g.rotate(-b.yaw_rad);
    g.fillStyle = b.role === "ego" ? COLORS.ego : b.role === "lead" ? COLORS.lead : COLORS.other;
    g.fillRect((-b.width_m / 2) * scale, (-b.length_m / 2) * scale, b.width_m * scale, b.length_m * scale);
    g.restore();
    if (b.role !== "ego" && b.x_m > -behind && b.x_m < ahead) {
      g.fillStyle = COLORS.text; g.font = "10px system-ui, sans-serif";
      g.fillText(`${b.x_m.toFixed(0)} m`, u + b.width_m * scale, v);
    }
  }
}

function cells(row, values) {
  row.replaceChildren(...values.map(([text, cls]) => { const td = document.createElement("td"); td.textContent = text; if (cls) td.className = cls; return td; }));
}

function fillTable(id, rows) {
  const body = $(id).tBodies[0];
  while (body.rows.length > rows.length) body.deleteRow(-1);
  rows.forEach((values, i) => cells(body.rows[i] || body.insertRow(), values));
}

function bandwidth(bps) {
  return bps >= 1e6 ? (bps / 1e6).toFixed(1) + " Mb/s" : (bps / 1e3).toFixed(1) + " kb/s";
}

function drawTables(state) {
  fillTable("hops", state.hops.map((h) => [[h.hop], [String(h.count)], [fmt(h.p50_ms, 2)], [fmt(h.p99_ms, 2)], [fmt(h.max_ms, 2)]]));
  fillTable("topics", state.top.keys.map((k) => [[k.key], [k.from || "–"], [String(k.received)], [fmt(k.rate_hz, 1)],
    [bandwidth(k.bandwidth_bps)], [fmt(k.latency_p50_us, 0)], [fmt(k.latency_p99_us, 0)],
    [String(k.lost), k.lost ? "bad" : ""], [String(k.decode_errors), k.decode_errors ? "bad" : ""], [fmt(k.age_s, 1)]]));
  $("nodes").textContent = state.top.nodes.length ? state.top.nodes.join(", ") : "none seen";
  const v = state.view;
  $("served").textContent = `slipstream ${state.version}, namespace ${state.top.namespace || "(none)"} · ` +
    `page: ${v.states} states, ${v.frames} frames served, ${v.skipped} skipped by slower pages, ` +
    `${v.bad_requests} bad requests · this page: ${view.updates} updates`;
}

// What the page shows: a replay or the live loop, running, ended (the simulator said so) or
// silent.
function statusOf(state) {
  const age = state.top.keys.reduce((a, k) => Math.min(a, k.age_s === null ? Infinity : k.age_s), Infinity);
  if (state.replay) {
    if (state.replay.playing) return ["replay", "ok"];
    const atEnd = state.replay.duration_s !== null && state.replay.t_s >= state.replay.duration_s - 0.05;
    return [atEnd ? "replay at its end" : "replay paused", "stale"];
  }
  if (state.ended && age >= 2) return ["run ended: " + state.ended, "ended"];
  if (age < 2) return ["live", "ok"];
  return ["no message for " + fmt(age, 0, " s"), "stale"];
}

function setStatus(text, cls) {
  const el = $("status");
  el.textContent = text; el.className = "status " + cls;
}

async function run() {
  for (;;) {
    const started = performance.now();
    if (!view.paused) {
      try {
        await update();
        setStatus(...statusOf(view.last));
      } catch (e) {
        view.failures += 1;
        setStatus("view unreachable: " + e.message, "down");
        await sleep(1000);
      }
    }
    await sleep(Math.max(0, 1000 / MAX_RATE_HZ - (performance.now() - started)));
  }
}

run();
