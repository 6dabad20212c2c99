// The live view of ijoy drive: a top-down drawing of the drive's state, and the stick from keys or a gamepad.
"use strict";
const mapCanvas = document.getElementById("map");
const ctx = mapCanvas.getContext("2d");
const status = document.getElementById("status");
let scene = null, terrainImg = null, state = null, ws = null;
window.ijoy = { frames: 0, states: 0, sent: 0, axes: [0, 0, 0] };

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
function view() {
  const W = mapCanvas.width, H = mapCanvas.height;
  const wx = scene.shape[0] * scene.resolution, wy = scene.shape[1] * scene.resolution;
  const k = Math.min(W / wx, H / wy) * 0.97;
  const ox = (W - k * wx) / 2, oy = (H - k * wy) / 2;
  return { k, tx: x => ox + (x - scene.origin[0]) * k, ty: y => H - oy - (y - scene.origin[1]) * k, wx, wy, ox, oy };
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

function frame() {
  drawMap(); drawStick(); drawLatency();
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

loadScene().then(() => { connect(); requestAnimationFrame(frame); });
