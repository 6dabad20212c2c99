// The live view of ijoy drive: a top-down drawing of the drive's state, and the stick from keys or a gamepad.
"use strict";
const mapCanvas = document.getElementById("map");
const ctx = mapCanvas.getContext("2d");
const status = document.getElementById("status");
let scene = null, terrainImg = null, state = null, ws = null;
window.ijoy = { frames: 0, states: 0, sent: 0, axes: [0, 0, 0], initial: false };
// the scene and the latest state, for the 3D view (view3d.js, a module loaded when it is first shown)
window.ijoy.current = () => ({ scene, state });
let mode3d = false;

// The scene and latest state the server wrote into the page (#ijoy-initial), so the first paint shows the robot
// before the WebSocket connects; null where the page came without them (the drive had not started).
function initialData() {
  const el = document.getElementById("ijoy-initial");
  try { return el ? JSON.parse(el.textContent) : null; } catch (e) { return null; }
}

async function loadScene() {
  for (;;) {
    const r = await fetch("scene.json");
    const s = await r.json();
    if (s && s.shape) { scene = s; break; }
    await new Promise(res => setTimeout(res, 200));
  }
  terrainImg = new Image();
  terrainImg.src = "terrain.png?" + Date.now();
  await terrainImg.decode();
}

function connect() {
  ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  ws.onmessage = ev => { state = JSON.parse(ev.data); window.ijoy.states++; };
  ws.onclose = () => { status.textContent = "disconnected (the drive ended?)"; setTimeout(connect, 1000); };
}

// ---- world <-> canvas
// canvas px kept free around the map for the metre axes: their labels left and below, the titles, the last labels
const AXIS_LEFT = 52, AXIS_BOTTOM = 40, AXIS_TOP = 24, AXIS_RIGHT = 24;

function view() {
  // the map fitted into the canvas less the axes' margins: k px per metre, (ox, oy) its top-left corner in px
  const W = mapCanvas.width, H = mapCanvas.height;
  const wx = scene.shape[0] * scene.resolution, wy = scene.shape[1] * scene.resolution;
  const aw = Math.max(1, W - AXIS_LEFT - AXIS_RIGHT), ah = Math.max(1, H - AXIS_BOTTOM - AXIS_TOP);
  const k = Math.min(aw / wx, ah / wy);
  const ox = AXIS_LEFT + (aw - k * wx) / 2, oy = AXIS_TOP + (ah - k * wy) / 2;
  return { k, tx: x => ox + (x - scene.origin[0]) * k, ty: y => oy + k * wy - (y - scene.origin[1]) * k, wx, wy, ox, oy };
}

// The metre axes' tick step: the smallest of 1, 2, 2.5, 5 times a power of ten that cuts the map's longer side
// into at most 6 intervals and keeps ticks at least 60 px apart (labels readable at any canvas size).
function tickStep(extent, pxPerMetre) {
  for (let e = -3; e <= 6; e++) {
    for (const m of [1, 2, 2.5, 5]) {
      const step = m * Math.pow(10, e);
      if (extent / step <= 6 && step * pxPerMetre >= 60) return step;
    }
  }
  return extent;
}

// Tick values (m): the multiples of step within [lo, hi], in world coordinates, with the decimals step needs.
function ticks(lo, hi, step) {
  const dec = [0, 1, 2, 3, 4, 5, 6].find(d => Math.abs(step * 10 ** d - Math.round(step * 10 ** d)) < 1e-9) ?? 6;
  const eps = 1e-9 * Math.max(1, Math.abs(lo), Math.abs(hi));
  const out = [];
  for (let i = Math.ceil((lo - eps) / step); i * step <= hi + eps; i++) {
    const value = Number((i * step).toFixed(dec));
    out.push({ value: Object.is(value, -0) ? 0 : value, label: (Object.is(value, -0) ? 0 : value).toFixed(dec) });
  }
  return out;
}

function drawAxes(v) {
  // x along the map's bottom edge, y along its left edge: ticks and labels in metres (world coordinates); the
  // tick values and their canvas positions go on the canvas's data attributes (data-x-ticks etc.) for tests
  const step = tickStep(Math.max(v.wx, v.wy), v.k);
  const x0 = scene.origin[0], y0 = scene.origin[1];
  const xt = ticks(x0, x0 + v.wx, step), yt = ticks(y0, y0 + v.wy, step);
  const left = v.ox, bottom = v.oy + v.k * v.wy;
  // 2 px lines on whole pixels: crisp at the default size
  const px = Math.round, bl = px(bottom), ll = px(left);
  ctx.strokeStyle = "#c8d0d8"; ctx.fillStyle = "#c8d0d8"; ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(ll - 2, bl + 1); ctx.lineTo(px(left + v.k * v.wx), bl + 1);
  ctx.moveTo(ll - 1, bl + 2); ctx.lineTo(ll - 1, px(v.oy));
  for (const t of xt) { ctx.moveTo(px(v.tx(t.value)), bl); ctx.lineTo(px(v.tx(t.value)), bl + 8); }
  for (const t of yt) { ctx.moveTo(ll, px(v.ty(t.value))); ctx.lineTo(ll - 8, px(v.ty(t.value))); }
  ctx.stroke();
  ctx.font = "13px system-ui, sans-serif";
  ctx.textAlign = "center"; ctx.textBaseline = "top";
  for (const t of xt) ctx.fillText(t.label, v.tx(t.value), bottom + 9);
  ctx.textAlign = "right"; ctx.textBaseline = "middle";
  for (const t of yt) ctx.fillText(t.label, left - 10, v.ty(t.value));
  ctx.textAlign = "left"; ctx.textBaseline = "top";
  ctx.fillText("y (m)", 4, 4);
  ctx.textAlign = "right"; ctx.textBaseline = "top";
  ctx.fillText("x (m)", left + v.k * v.wx, bottom + 24);
  ctx.textAlign = "start"; ctx.textBaseline = "alphabetic";
  const d = mapCanvas.dataset, key = JSON.stringify([step, x0, y0, v.k, v.ox, v.oy]);
  if (d.axesKey === key) return;   // unchanged since the last frame: leave the DOM alone
  d.axesKey = key; d.tickStep = String(step);
  d.xTicks = JSON.stringify(xt.map(t => t.value)); d.yTicks = JSON.stringify(yt.map(t => t.value));
  d.xTickLabels = JSON.stringify(xt.map(t => t.label)); d.yTickLabels = JSON.stringify(yt.map(t => t.label));
  d.xTicksPx = JSON.stringify(xt.map(t => v.tx(t.value))); d.yTicksPx = JSON.stringify(yt.map(t => v.ty(t.value)));
  d.mapPx = JSON.stringify([left, v.oy, left + v.k * v.wx, bottom]);   // the terrain's left, top, right, bottom
}

function foot(v, pose, fill, stroke, width) {
  const [L, Wd] = scene.foot;
  ctx.save();
  ctx.translate(v.tx(pose[0]), v.ty(pose[1]));
  ctx.rotate(-pose[2]);
  ctx.beginPath();
  ctx.rect(-L / 2 * v.k, -Wd / 2 * v.k, L * v.k, Wd * v.k);
  if (fill) { ctx.fillStyle = fill; ctx.fill(); }
  if (stroke) { ctx.lineWidth = width || 2; ctx.strokeStyle = stroke; ctx.stroke(); }
  ctx.restore();
}

function costColour(c, lo, hi) {
  const u = hi > lo ? Math.min(1, Math.max(0, (c - lo) / (hi - lo))) : 0;
  const r = Math.round(46 + u * (241 - 46)), g = Math.round(204 + u * (224 - 204)), b = Math.round(113 + u * (90 - 113));
  return `rgb(${r},${g},${b})`;
}

function drawMap() {
  mapCanvas.width = mapCanvas.clientWidth; mapCanvas.height = mapCanvas.clientHeight;
  ctx.fillStyle = "#15181c"; ctx.fillRect(0, 0, mapCanvas.width, mapCanvas.height);
  if (!scene || !terrainImg) return;
  const v = view();
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(terrainImg, v.ox, v.oy, v.wx * v.k, v.wy * v.k);
  drawAxes(v);
  if (!state || !state.feet) return;
  // candidates of the current decision
  if (state.candidates) {
    const costs = state.candidate_cost.filter((c, i) => state.candidate_valid[i]);
    const lo = Math.min(...costs), hi = Math.max(...costs);
    state.candidates.forEach((p, i) => {
      ctx.beginPath();
      ctx.arc(v.tx(p[0]), v.ty(p[1]), Math.max(2, 0.008 * v.k), 0, 2 * Math.PI);
      ctx.fillStyle = state.candidate_valid[i] ? costColour(state.candidate_cost[i], lo, hi) : "rgba(217,70,59,0.8)";
      ctx.fill();
    });
  }
  // the cue's reach for the next decision
  if (state.reach_world && state.reach_world.length) {
    ctx.beginPath();
    state.reach_world.forEach((p, i) => i ? ctx.lineTo(v.tx(p[0]), v.ty(p[1])) : ctx.moveTo(v.tx(p[0]), v.ty(p[1])));
    ctx.closePath();
    ctx.fillStyle = "rgba(179,127,235,0.18)"; ctx.fill();
    ctx.lineWidth = 2; ctx.strokeStyle = "#b37feb"; ctx.stroke();
  }
  // feet: left blue, right orange; the swing foot lighter while it swings
  foot(v, state.feet[0], "rgba(58,123,213,0.85)", "#1b3f73", 1.5);
  foot(v, state.feet[1], "rgba(232,163,61,0.85)", "#7a4d12", 1.5);
  // the chosen next foothold
  if (state.foothold) {
    const f = state.foothold;
    foot(v, [f[0], f[1], f[5]], null, state.valid ? "#ffffff" : "#d9463b", 3);
  }
  // the command as an arrow from the feet's midpoint, in the stance frame
  const mx = (state.feet[0][0] + state.feet[1][0]) / 2, my = (state.feet[0][1] + state.feet[1][1]) / 2;
  const th = state.feet[state.stance_side > 0 ? 0 : 1][2];
  const c = state.command, s = 2.0;
  const ex = mx + s * (Math.cos(th) * c[0] - Math.sin(th) * c[1]), ey = my + s * (Math.sin(th) * c[0] + Math.cos(th) * c[1]);
  ctx.beginPath(); ctx.moveTo(v.tx(mx), v.ty(my)); ctx.lineTo(v.tx(ex), v.ty(ey));
  ctx.lineWidth = 3; ctx.strokeStyle = "#ff5ca8"; ctx.stroke();
  ctx.beginPath(); ctx.arc(v.tx(ex), v.ty(ey), 4, 0, 2 * Math.PI); ctx.fillStyle = "#ff5ca8"; ctx.fill();
}

function drawStick() {
  const cv = document.getElementById("stick"), g = cv.getContext("2d");
  g.clearRect(0, 0, cv.width, cv.height);
  const cx = 75, cy = 75, r = 62;
  g.beginPath(); g.arc(cx, cy, r, 0, 2 * Math.PI); g.strokeStyle = "#5b6672"; g.lineWidth = 2; g.stroke();
  if (!state || !state.axes) return;
  const a = state.axes, f = state.cue_force || [0, 0, 0];
  const px = cx - a[1] * r, py = cy - a[0] * r;   // forward up, left to the left
  g.beginPath(); g.arc(px, py, 9, 0, 2 * Math.PI); g.fillStyle = "#ff5ca8"; g.fill();
  // the cue's force on the stick (forward, left)
  g.beginPath(); g.moveTo(px, py); g.lineTo(px - f[1] * r, py - f[0] * r); g.strokeStyle = "#b37feb"; g.lineWidth = 4; g.stroke();
  // turn: a bar
  g.fillStyle = "#3a434d"; g.fillRect(160, 68, 110, 14);
  g.fillStyle = "#ff5ca8"; const w = -a[2] * 55; g.fillRect(215 + Math.min(0, w), 68, Math.abs(w), 14);
  g.fillStyle = "#98a2ad"; g.font = "12px system-ui"; g.fillText("turn", 200, 62);
}

function drawLatency() {
  // one bar per decision on a log scale from 1 ms to 2 s; the dashed line is the step time (the deadline)
  const cv = document.getElementById("latency"), g = cv.getContext("2d");
  g.clearRect(0, 0, cv.width, cv.height);
  if (!state || !scene) return;
  const h = state.latency_history || [], T = scene.step_time, n = 60, left = 38, bw = (cv.width - left) / n;
  const lo = 1e-3, hi = 2.0, H = cv.height - 6;
  const y = t => 3 + H - H * Math.log(Math.min(Math.max(t, lo), hi) / lo) / Math.log(hi / lo);
  g.font = "10px system-ui"; g.fillStyle = "#98a2ad"; g.strokeStyle = "#3a434d";
  for (const [t, label] of [[1e-3, "1 ms"], [1e-2, "10 ms"], [1e-1, "100 ms"], [1, "1 s"]]) {
    g.fillText(label, 0, y(t) + 3); g.beginPath(); g.moveTo(left, y(t)); g.lineTo(cv.width, y(t)); g.stroke();
  }
  h.forEach((t, i) => {
    g.fillStyle = t > T ? "#d9463b" : t > 0.5 * T ? "#f1e05a" : "#2ecc71";
    const x = left + (n - h.length + i) * bw;
    g.fillRect(x + 1, y(t), Math.max(1, bw - 2), 3 + H - y(t));
  });
  g.strokeStyle = "#d9463b"; g.setLineDash([4, 3]); g.beginPath(); g.moveTo(left, y(T)); g.lineTo(cv.width, y(T)); g.stroke();
  g.setLineDash([]);
}

// The 3D view in place of the map (the side panel, the keys and the gamepad stay): at /3d, or by the button.
function setMode(three) {
  mode3d = three;
  document.getElementById("map").hidden = three;
  mapCanvas.style.display = three ? "none" : "";
  const el = document.getElementById("view3d");
  el.hidden = !three;
  el.style.display = three ? "block" : "none";
  if (modeButton) modeButton.textContent = three ? "2D map" : "3D view";
  history.replaceState(null, "", three ? "3d" : "./");
  if (three && !window.ijoy.view3d) {
    window.ijoy.view3d = import("./view3d.js").then(m => m.start(el, window.ijoy.current))
      .catch(e => { status.textContent = "the 3D view failed: " + e; });
  }
}
const modeButton = document.getElementById("mode");
if (modeButton) modeButton.addEventListener("click", () => setMode(!mode3d));

function frame() {
  if (!mode3d) drawMap();
  drawStick(); drawLatency();
  if (state && state.feet) {
    const lat = state.latency_s === undefined ? "-" : (1000 * state.latency_s).toFixed(1) + " ms";
    status.textContent = `step ${state.step}  decision ${lat}  ${state.valid === false ? "STOP: no valid step" : ""}  input: ${state.input_source}`;
  }
  window.ijoy.frames++;
  pollGamepad();
  requestAnimationFrame(frame);
}

// ---- the stick: keyboard and Gamepad API
const pressed = new Set();
function keyAxes() {
  const k = x => pressed.has(x) ? 1 : 0;
  const shift = pressed.has("Shift");
  return [k("w") + k("ArrowUp") - k("s") - k("ArrowDown"),
          k("a") + (shift ? 0 : k("ArrowLeft")) - k("d") - (shift ? 0 : k("ArrowRight")),
          k("q") + (shift ? k("ArrowLeft") : 0) - k("e") - (shift ? k("ArrowRight") : 0)];
}
function send(axes, source) {
  window.ijoy.axes = axes;
  if (ws && ws.readyState === 1) { ws.send(JSON.stringify({ type: "axes", axes, source })); window.ijoy.sent++; }
}
function onKey(ev, down) {
  const key = ev.key.length === 1 ? ev.key.toLowerCase() : ev.key;
  if (!["w", "a", "s", "d", "q", "e", "ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "Shift"].includes(key)) return;
  ev.preventDefault();
  down ? pressed.add(key) : pressed.delete(key);
  send(keyAxes(), "keyboard");
}
window.addEventListener("keydown", ev => onKey(ev, true));
window.addEventListener("keyup", ev => onKey(ev, false));
window.addEventListener("blur", () => { pressed.clear(); send([0, 0, 0], "keyboard"); });
let lastPad = "";
function pollGamepad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const p of pads) {
    if (!p) continue;
    const dz = x => Math.abs(x) < 0.02 ? 0 : x;   // the drive applies its own dead zone; this only quiets noise
    const axes = [-dz(p.axes[1] || 0), -dz(p.axes[0] || 0), -dz(p.axes[2] || 0)];
    const key = axes.map(x => x.toFixed(3)).join();
    if (key !== lastPad) { lastPad = key; send(axes, "gamepad"); }
    return;
  }
}
setInterval(() => { if (pressed.size) send(keyAxes(), "keyboard"); }, 200);

// The first paint: with the scene and state the server wrote into the page and the terrain image the page
// loaded with (#terrain), draw them as the page's load event fires (a screenshot taken then shows the robot);
// without them, wait for the scene as the drive sets it. Then the WebSocket brings every new state.
function start() {
  if (/\/3d$/.test(location.pathname)) setMode(true);
  const init = initialData(), img = document.getElementById("terrain");
  if (init && init.scene && init.scene.shape && img && img.complete && img.naturalWidth > 0) {
    scene = init.scene; terrainImg = img;
    if (init.state && init.state.feet) { state = init.state; window.ijoy.initial = true; }
    else status.textContent = "waiting for the drive's first state...";
    frame();
    connect();
    return;
  }
  loadScene().then(() => { connect(); requestAnimationFrame(frame); });
}
if (document.readyState === "complete") start();
else window.addEventListener("load", start);
