// The viewer's page: draws the frames the server streams over the WebSocket and sends the user's input
// back (the protocol is documented in crates/viewer/src/protocol.rs). No dependencies, no network but
// the page's own server.
"use strict";

const canvas = document.getElementById("scene");
const ctx = canvas.getContext("2d");
const plot = document.getElementById("plot");
const plotCtx = plot.getContext("2d");
// The world window the server sends in its hello ([x_min, x_max, y_min, y_max]), fitted to the canvas.
let SCALE = 100;
let ORIGIN = [350, 200];
const PLOT_SECONDS = 20;

let socket = null;
let shapes = [];
let planes = [];
let fixed = [];
let watched = { name: "", index: 0, target: null, unit: "rad" };
let targets = []; // the bodies where the task wants them: [{ body, centre, angle }]
let frame = null;
let history = []; // [t, rate of the watched entry, its value]
let dragging = false;
let lastError = "";

const toScreen = (p) => [ORIGIN[0] + SCALE * p[0], ORIGIN[1] - SCALE * p[1]];
const toWorld = (s) => [(s[0] - ORIGIN[0]) / SCALE, (ORIGIN[1] - s[1]) / SCALE];

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) {
    socket.send(JSON.stringify(message));
  }
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws`);
  socket.onopen = () => { document.getElementById("status").textContent = "connected"; };
  socket.onclose = () => {
    document.getElementById("status").textContent = "disconnected; retrying ...";
    setTimeout(connect, 1000);
  };
  socket.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === "hello") {
      shapes = message.bodies;
      planes = message.planes || [];
      fixed = message.fixed || [];
      watched = message.watched || watched;
      targets = message.targets || [];
      fit(message.window || [-3.5, 3.5, -4, 2]);
      document.getElementById("title").textContent = message.title || "";
      document.getElementById("watched-name").textContent =
        watched.target === null || watched.target === undefined
          ? `${watched.name} rate (2 s)`
          : `${watched.name} (target ${watched.target} ${unit()})`;
      document.getElementById("status").textContent =
        `connected; h = ${message.h} s; ` +
        (message.library ? `library of ${message.controllers} controllers` : "no library loaded");
      for (const input of document.querySelectorAll("input[name=policy][value=library]")) {
        input.disabled = !message.library;
      }
    } else if (message.type === "frame") {
      receive(message);
    } else if (message.type === "error") {
      lastError = message.message;
      document.getElementById("warning").textContent = message.message;
    }
  };
}

// Fit the world window to the canvas, centred, one scale for both axes.
function fit(w) {
  const [x0, x1, y0, y1] = w;
  SCALE = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
  const cx = (x0 + x1) / 2;
  const cy = (y0 + y1) / 2;
  ORIGIN = [canvas.width / 2 - SCALE * cx, canvas.height / 2 + SCALE * cy];
}

function receive(f) {
  if (frame && f.t < frame.t) {
    history = []; // a reset
  }
  frame = f;
  window.lastFrame = f; // for end-to-end tests
  history.push([f.t, f.spin_rate, f.watched]);
  while (history.length && history[0][0] < f.t - PLOT_SECONDS) {
    history.shift();
  }
  syncControls(f);
  readout(f);
}

function syncControls(f) {
  for (const input of document.querySelectorAll("input[name=policy]")) {
    input.checked = input.value === f.policy;
  }
  for (const input of document.querySelectorAll("input[name=world]")) {
    input.checked = input.value === f.world;
  }
  const sigma = document.getElementById("sigma");
  if (document.activeElement !== sigma) {
    sigma.value = f.sigma;
  }
  document.getElementById("pause").textContent = f.paused ? "resume" : "pause";
}

// The watched entry's unit, and its rate's.
const unit = () => watched.unit || "rad";
const rateUnit = () => `${unit()}/s`;

function readout(f) {
  const fixed = (v, d) => (Number.isFinite(v) ? v.toFixed(d) : "-");
  document.getElementById("time").textContent = `${fixed(f.t, 2)} s`;
  document.getElementById("spin").textContent =
    watched.target === null || watched.target === undefined
      ? `${fixed(f.spin_rate, 3)} ${rateUnit()}`
      : `${fixed(f.watched, 3)} ${unit()}`;
  document.getElementById("control-ms").textContent =
    `${fixed(f.control_ms, 3)} ms (max ${fixed(f.control_ms_max, 3)} ms over 2 s)` +
    (f.policy === "mpc" ? `; plan re-seeded ${f.mpc_reseeds}x` : "");
  const impulse = f.contacts.reduce((m, c) => Math.max(m, Math.hypot(c.impulse[0], c.impulse[1])), 0);
  document.getElementById("impulse").textContent = fixed(impulse, 4);
  document.getElementById("torques").textContent = f.u.map((u) => fixed(u, 2)).join(", ");
  document.getElementById("perturbations").textContent =
    `${f.perturbations} (unconverged steps: ${f.unconverged})`;
  document.getElementById("warning").textContent = f.warning || lastError;
}

function ellipse(pose, shape, fill, stroke) {
  const [cx, cy] = toScreen(pose.centre);
  ctx.beginPath();
  ctx.ellipse(cx, cy, SCALE * shape.semi_axes[0], SCALE * shape.semi_axes[1], -pose.angle, 0, 2 * Math.PI);
  ctx.fillStyle = fill;
  ctx.fill();
  ctx.strokeStyle = stroke;
  ctx.lineWidth = 1.5;
  ctx.stroke();
}

// The canvas part on the solid side of a half-plane (the canvas rectangle clipped by its boundary).
function drawPlane(p) {
  const corners = [[0, 0], [canvas.width, 0], [canvas.width, canvas.height], [0, canvas.height]].map(toWorld);
  const side = (q) => (q[0] - p.point[0]) * p.normal[0] + (q[1] - p.point[1]) * p.normal[1];
  const part = [];
  for (let k = 0; k < 4; k++) {
    const a = corners[k];
    const b = corners[(k + 1) % 4];
    const sa = side(a);
    const sb = side(b);
    if (sa <= 0) {
      part.push(a);
    }
    if ((sa < 0) !== (sb < 0) && sa !== sb) {
      const t = sa / (sa - sb);
      part.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
    }
  }
  if (part.length < 3) {
    return;
  }
  ctx.beginPath();
  part.map(toScreen).forEach(([x, y], i) => (i === 0 ? ctx.moveTo(x, y) : ctx.lineTo(x, y)));
  ctx.closePath();
  ctx.fillStyle = "#c8c8c8";
  ctx.fill();
  ctx.strokeStyle = "#666";
  ctx.lineWidth = 1;
  ctx.stroke();
}

function draw() {
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  planes.forEach(drawPlane);
  for (const f of fixed) {
    ellipse({ centre: f.centre, angle: f.angle }, f, "#a0a0a0", "#444");
  }
  // Where the task wants its bodies: faint dashed outlines under the bodies themselves.
  for (const t of targets) {
    const shape = shapes[t.body];
    if (!shape) {
      continue;
    }
    const [cx, cy] = toScreen(t.centre);
    ctx.beginPath();
    ctx.ellipse(cx, cy, SCALE * shape.semi_axes[0], SCALE * shape.semi_axes[1], -t.angle, 0, 2 * Math.PI);
    ctx.setLineDash([5, 4]);
    ctx.strokeStyle = "rgba(46, 125, 50, 0.8)";
    ctx.lineWidth = 1.5;
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.beginPath();
    ctx.moveTo(cx, cy);
    ctx.lineTo(cx + SCALE * shape.semi_axes[0] * Math.cos(t.angle), cy - SCALE * shape.semi_axes[0] * Math.sin(t.angle));
    ctx.stroke();
  }
  if (frame && shapes.length === frame.bodies.length) {
    frame.bodies.forEach((pose, i) => {
      const shape = shapes[i];
      ellipse(pose, shape, shape.actuated ? "#9ab7d3" : "#e3c58a", "#333");
      // Orientation mark along the body's x axis, and the hinge.
      const [cx, cy] = toScreen(pose.centre);
      const a = SCALE * shape.semi_axes[0];
      ctx.beginPath();
      ctx.moveTo(cx, cy);
      ctx.lineTo(cx + a * Math.cos(pose.angle), cy - a * Math.sin(pose.angle));
      ctx.strokeStyle = "#555";
      ctx.stroke();
      const [hx, hy] = toScreen(pose.hinge);
      ctx.beginPath();
      ctx.arc(hx, hy, 4, 0, 2 * Math.PI);
      ctx.fillStyle = "#222";
      ctx.fill();
    });
    for (const c of frame.contacts) {
      const size = Math.hypot(c.impulse[0], c.impulse[1]);
      if (size > 1e-4) {
        const [px, py] = toScreen(c.point);
        ctx.beginPath();
        ctx.arc(px, py, 3 + Math.min(12, 40 * size), 0, 2 * Math.PI);
        ctx.fillStyle = "rgba(200, 30, 30, 0.8)";
        ctx.fill();
        const k = Math.min(1, 3 * size) / size;
        ctx.beginPath();
        ctx.moveTo(px, py);
        ctx.lineTo(px + SCALE * k * c.impulse[0], py - SCALE * k * c.impulse[1]);
        ctx.strokeStyle = "#c11";
        ctx.lineWidth = 2;
        ctx.stroke();
      }
    }
    if (frame.spring) {
      const [ax, ay] = toScreen(frame.spring.from);
      const [bx, by] = toScreen(frame.spring.to);
      ctx.beginPath();
      ctx.moveTo(ax, ay);
      ctx.lineTo(bx, by);
      ctx.setLineDash([6, 4]);
      ctx.strokeStyle = "#2a7";
      ctx.lineWidth = 2;
      ctx.stroke();
      ctx.setLineDash([]);
    }
  }
  drawPlot();
  requestAnimationFrame(draw);
}

// The watched entry over the last PLOT_SECONDS: its rate, or for a task with a target its distance to
// the target (the target is the dashed line at 0). Axes: time before now along the bottom, the value on
// the left, both labelled with their units.
function drawPlot() {
  const w = plot.width;
  const h = plot.height;
  const left = 38; // room for the value axis's labels
  const bottom = h - 16; // room for the time axis's labels
  const top = 16; // room for the caption
  plotCtx.clearRect(0, 0, w, h);
  const target = watched.target;
  const hasTarget = target !== null && target !== undefined;
  const value = (p) => (hasTarget ? p[2] - target : p[1]);
  const limit = Math.max(hasTarget ? 0.1 : 0.5, ...history.map((p) => Math.abs(value(p))));
  const mid = (top + bottom) / 2;
  const y = (v) => mid - (mid - top - 2) * (v / limit);
  const x = (ago) => w - ((w - left) * ago) / PLOT_SECONDS;
  plotCtx.fillStyle = "#555";
  plotCtx.font = "11px sans-serif";
  plotCtx.textAlign = "left";
  plotCtx.fillText(
    hasTarget
      ? `${watched.name} - target (${target} ${unit()}), ${unit()}`
      : `${watched.name} rate, ${rateUnit()}`,
    left,
    11,
  );
  // Axes and their ticks.
  plotCtx.strokeStyle = "#888";
  plotCtx.lineWidth = 1;
  plotCtx.beginPath();
  plotCtx.moveTo(left, top);
  plotCtx.lineTo(left, bottom);
  plotCtx.lineTo(w, bottom);
  plotCtx.stroke();
  plotCtx.textAlign = "right";
  for (const v of [limit, 0, -limit]) {
    plotCtx.fillText(v === 0 ? "0" : v.toFixed(2), left - 3, y(v) + 4);
  }
  plotCtx.textAlign = "center";
  for (const ago of [PLOT_SECONDS, PLOT_SECONDS / 2, 0]) {
    plotCtx.fillText(ago === 0 ? "now" : `-${ago} s`, Math.min(x(ago), w - 12), h - 3);
  }
  plotCtx.textAlign = "left";
  // The zero line: the target for a task with one (dashed), no spin otherwise.
  plotCtx.strokeStyle = hasTarget ? "rgba(46, 125, 50, 0.9)" : "#bbb";
  if (hasTarget) {
    plotCtx.setLineDash([5, 4]);
  }
  plotCtx.beginPath();
  plotCtx.moveTo(left, y(0));
  plotCtx.lineTo(w, y(0));
  plotCtx.stroke();
  plotCtx.setLineDash([]);
  if (hasTarget) {
    plotCtx.fillStyle = "rgba(46, 125, 50, 0.9)";
    plotCtx.fillText("target", left + 3, y(0) - 3);
  }
  if (history.length < 2) {
    return;
  }
  const t1 = history[history.length - 1][0];
  plotCtx.strokeStyle = "#1565c0";
  plotCtx.lineWidth = 1.5;
  plotCtx.beginPath();
  history.forEach((p, i) => {
    const px = x(t1 - p[0]);
    const py = y(value(p));
    if (i === 0) {
      plotCtx.moveTo(px, py);
    } else {
      plotCtx.lineTo(px, py);
    }
  });
  plotCtx.stroke();
}

// The body under a screen point, topmost (last drawn) first.
function bodyAt(point) {
  if (!frame) {
    return -1;
  }
  for (let i = frame.bodies.length - 1; i >= 0; i--) {
    const pose = frame.bodies[i];
    const [a, b] = shapes[i].semi_axes;
    const dx = point[0] - pose.centre[0];
    const dy = point[1] - pose.centre[1];
    const c = Math.cos(pose.angle);
    const s = Math.sin(pose.angle);
    const lx = c * dx + s * dy;
    const ly = -s * dx + c * dy;
    if ((lx / a) ** 2 + (ly / b) ** 2 <= 1) {
      return i;
    }
  }
  return -1;
}

// Page (client) coordinates of a world point, for tests that drive the mouse.
window.viewerToClient = (p) => {
  const rect = canvas.getBoundingClientRect();
  const [sx, sy] = toScreen(p);
  return [rect.left + (sx * rect.width) / canvas.width, rect.top + (sy * rect.height) / canvas.height];
};

function eventPoint(event) {
  const rect = canvas.getBoundingClientRect();
  return toWorld([
    ((event.clientX - rect.left) * canvas.width) / rect.width,
    ((event.clientY - rect.top) * canvas.height) / rect.height,
  ]);
}

canvas.addEventListener("pointerdown", (event) => {
  const point = eventPoint(event);
  const body = bodyAt(point);
  if (body >= 0) {
    dragging = true;
    canvas.classList.add("dragging");
    canvas.setPointerCapture(event.pointerId);
    send({ type: "grab", body, point });
  }
});
canvas.addEventListener("pointermove", (event) => {
  if (dragging) {
    send({ type: "drag", target: eventPoint(event) });
  }
});
function release() {
  if (dragging) {
    dragging = false;
    canvas.classList.remove("dragging");
    send({ type: "release" });
  }
}
canvas.addEventListener("pointerup", release);
canvas.addEventListener("pointercancel", release);

for (const input of document.querySelectorAll("input[name=policy]")) {
  input.addEventListener("change", () => { lastError = ""; send({ type: "policy", policy: input.value }); });
}
for (const input of document.querySelectorAll("input[name=world]")) {
  input.addEventListener("change", () => send({ type: "world", world: input.value }));
}
document.getElementById("sigma").addEventListener("change", (event) => {
  lastError = "";
  send({ type: "sigma", sigma: Number(event.target.value) });
});
document.getElementById("speed").addEventListener("input", (event) => {
  const speed = 2 ** Number(event.target.value);
  document.getElementById("speed-value").textContent = `${speed}x`;
  send({ type: "speed", speed });
});
document.getElementById("pause").addEventListener("click", () => {
  send({ type: "pause", paused: !(frame && frame.paused) });
});
document.getElementById("reset").addEventListener("click", () => { lastError = ""; send({ type: "reset" }); });
document.getElementById("kick").addEventListener("click", () => {
  send({ type: "kick", std: Number(document.getElementById("kick-std").value) });
});

connect();
requestAnimationFrame(draw);
