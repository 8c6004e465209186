// The rlenv inspector page: polls the inspector's JSON API (relative URLs, so the per-run key
// in the page's address comes along) and draws what it gets. Every loop waits for its answer
// before asking again: a slow browser drops frames, it never queues them.
"use strict";

const FRAME_INTERVAL = 33;   // ms: up to ~30 frames a second
const NODE_INTERVAL = 250;   // the selected node's properties
const TREE_INTERVAL = 1000;
const STATS_INTERVAL = 500;
const SERVERS_INTERVAL = 2000;
const PLOTTED = 500;         // episodes kept in the plots
const CONTROL_INTERVAL = 500;
const OTHERS_QUIET = 2000;   // ms without another client's steps before taking control is offered

const state = {
  server: 0, instance: 0, path: null, frames: 0, servers: [],
  episodes: [], next: 0, speed: [], lastTotals: null, generation: 0,
  control: {enabled: false, controlling: false, keys: [], episodes: 0}, held: [], othersSteppedAt: -Infinity,
};
window.inspector = state;  // for whoever drives the page (its browser test)

const $ = (id) => document.getElementById(id);
// Whether the page shows a timeline (timeline.js): the live loops then leave the scene, the tree
// and the properties to it.
const timeTravelling = () => !!(window.timeline && window.timeline.active);
const watching = () => state.servers.length > 0;

async function api(path, params = {}) {
  const query = new URLSearchParams({server: state.server, instance: state.instance, ...params});
  const response = await fetch(`api/${path}?${query}`, {cache: "no-store"});
  const body = await response.json();
  if (!response.ok) throw new Error(body.error || response.statusText);
  return body;
}

function every(interval, task) {
  const run = async () => {
    const started = performance.now();
    try { await task(); } catch (error) { showStatus(error.message, true); }
    setTimeout(run, Math.max(0, interval - (performance.now() - started)));
  };
  run();
}

function showStatus(text, bad = false) {
  const status = $("status");
  status.textContent = text;
  status.classList.toggle("bad", bad);
}

// --- servers and instances -----------------------------------------------------------------

async function refreshServers() {
  const response = await fetch("api/servers", {cache: "no-store"});
  state.servers = await response.json();
  const select = $("target");
  const options = [];
  for (const server of state.servers) {
    for (let instance = 0; instance < (server.instances || 1); instance++) {
      const name = server.environment || "?";
      const suffix = server.instances > 1 ? ` · instance ${instance}` : "";
      options.push([`${server.index}/${instance}`, `${name} @ ${server.address}${suffix}`]);
    }
  }
  const signature = options.map((o) => o.join("=")).join("|");
  if (select.dataset.signature !== signature) {
    select.replaceChildren(...options.map(([value, label]) => new Option(label, value)));
    select.dataset.signature = signature;
    select.value = `${state.server}/${state.instance}`;
  }
  const current = state.servers[state.server] || {};
  if (!state.servers.length) showStatus("no server watched: recordings as timelines");
  else if (current.error) showStatus(current.error, true);
  else showStatus(`protocol ${current.protocol} · ${current.observation_space} → ` +
                  `${current.action_space} · restarts ${current.restarts}`);
}

function choose(value) {
  [state.server, state.instance] = value.split("/").map(Number);
  state.path = null;
  forgetEpisodes();
  state.generation++;
  clearProperties();
  $("selected").textContent = "";
}

function forgetEpisodes() {
  state.episodes = [];
  state.next = 0;
  state.speed = [];
  state.lastTotals = null;
}

function clearProperties() {
  const body = $("properties").tBodies[0];
  body.replaceChildren();
  delete body.dataset.signature;
}

// --- the scene -----------------------------------------------------------------------------

const color = (rgb) => "#" + rgb.toString(16).padStart(6, "0");

function drawScene(canvas, drawing) {
  const context = canvas.getContext("2d");
  const [left, bottom, right, top] = drawing.view;
  const scale = Math.min(canvas.width / (right - left), canvas.height / (top - bottom));
  const x0 = (left + right) / 2 - canvas.width / (2 * scale);
  const y0 = (bottom + top) / 2 + canvas.height / (2 * scale);
  const px = (x) => (x - x0) * scale;
  const py = (y) => (y0 - y) * scale;
  context.fillStyle = "#fff";
  context.fillRect(0, 0, canvas.width, canvas.height);
  context.lineCap = context.lineJoin = "round";
  for (const [kind, rgb, ...g] of drawing.shapes) {
    context.fillStyle = context.strokeStyle = color(rgb);
    context.beginPath();
    if (kind === "circle") {
      const [x, y, radius, angle] = g;
      context.arc(px(x), py(y), Math.max(radius * scale, 1), 0, 2 * Math.PI);
      context.fill();
      context.strokeStyle = "rgba(0,0,0,.45)";
      context.lineWidth = 1;
      context.beginPath();
      context.moveTo(px(x), py(y));
      context.lineTo(px(x + radius * Math.cos(angle)), py(y + radius * Math.sin(angle)));
      context.stroke();
    } else if (kind === "segment") {
      const [ax, ay, bx, by, radius] = g;
      context.lineWidth = Math.max(2 * radius * scale, 1.5);
      context.moveTo(px(ax), py(ay));
      context.lineTo(px(bx), py(by));
      context.stroke();
    } else if (kind === "polygon") {
      const [radius, points] = g;
      for (let i = 0; i < points.length; i += 2) context.lineTo(px(points[i]), py(points[i + 1]));
      context.closePath();
      context.fill();
      if (radius > 0) { context.lineWidth = 2 * radius * scale; context.stroke(); }
    }
  }
}

function showObservations(observations) {
  const box = $("observations");
  const rows = [];
  const add = (name, shown) => {
    if (shown.parts) {
      for (const [part, inner] of Object.entries(shown.parts)) add(`${name}.${part}`, inner);
    } else rows.push([name, shown]);
  };
  for (const [agent, shown] of Object.entries(observations)) add(agent, shown);
  if (box.childElementCount !== rows.length) {
    box.replaceChildren(...rows.map(([name]) => {
      const figure = document.createElement("figure");
      figure.dataset.name = name;
      return figure;
    }));
  }
  rows.forEach(([name, shown], index) => {
    const figure = box.children[index];
    if (shown.image) {
      let canvas = figure.querySelector("canvas");
      if (!canvas) { canvas = document.createElement("canvas"); figure.replaceChildren(canvas); }
      paintImage(canvas, shown.image);
      canvas.title = name;
    } else {
      const text = `${name} ${JSON.stringify(shown.shape)} ${shown.dtype}\n` +
        shown.numbers.map((n) => (typeof n === "number" ? n.toFixed(4) : n)).join("  ");
      figure.className = "numbers";
      figure.textContent = text;
    }
  });
}

function paintImage(canvas, image) {
  const {width, height, channels} = image;
  const bytes = Uint8Array.from(atob(image.data), (c) => c.charCodeAt(0));
  canvas.width = width;
  canvas.height = height;
  const context = canvas.getContext("2d");
  const pixels = context.createImageData(width, height);
  for (let i = 0, j = 0; i < width * height; i++, j += channels) {
    const gray = channels < 3;
    pixels.data[4 * i] = bytes[j];
    pixels.data[4 * i + 1] = gray ? bytes[j] : bytes[j + 1];
    pixels.data[4 * i + 2] = gray ? bytes[j] : bytes[j + 2];
    pixels.data[4 * i + 3] = channels === 4 ? bytes[j + 3] : 255;
  }
  context.putImageData(pixels, 0, 0);
}

let frameTimes = [];
async function refreshFrame() {
  if (!watching() || timeTravelling()) return;
  const generation = state.generation;
  const frame = await api("frame");
  if (generation !== state.generation) return;
  const canvas = $("scene");
  drawScene(canvas, frame.draw);
  showObservations(frame.observation);
  state.frames++;
  canvas.dataset.frames = state.frames;
  const now = performance.now();
  frameTimes = frameTimes.filter((t) => now - t < 1000).concat(now);
  $("fps").textContent = `${frameTimes.length} frames/s`;
}

// --- the tree and the selected node ----------------------------------------------------------

async function refreshTree() {
  if (!watching() || timeTravelling()) return;
  const generation = state.generation;
  const nodes = await api("tree");
  if (generation !== state.generation) return;
  const list = $("tree");
  const signature = nodes.map((n) => n.path).join("|");
  if (list.dataset.signature !== signature) {
    const root = nodes.length ? nodes[0].path.split("/").length : 0;
    list.replaceChildren(...nodes.map((node) => {
      const item = document.createElement("li");
      const depth = node.path.split("/").length - root;
      item.dataset.path = node.path;
      item.style.paddingLeft = `${4 + 14 * depth}px`;
      item.append(node.path.split("/").pop() + " ");
      const type = document.createElement("small");
      type.textContent = node.type;
      item.append(type);
      item.addEventListener("click", () => select(node.path));
      return item;
    }));
    list.dataset.signature = signature;
  }
  if (state.path === null && nodes.length) select(nodes[0].path);
  for (const item of list.children) item.classList.toggle("selected", item.dataset.path === state.path);
}

function select(path) {
  state.path = path;
  $("selected").textContent = path;
  clearProperties();
  for (const item of $("tree").children) item.classList.toggle("selected", item.dataset.path === path);
  refreshNode().catch((error) => showStatus(error.message, true));
}

async function refreshNode() {
  if (timeTravelling()) { window.timeline.showProperties(); return; }
  if (state.path === null || !watching()) return;
  const [path, generation] = [state.path, state.generation];
  const node = await api("node", {path});
  if (path !== state.path || generation !== state.generation) return;
  const body = $("properties").tBodies[0];
  const names = Object.keys(node.exported);
  if (body.dataset.signature !== path + names.join("|")) {
    body.replaceChildren(...names.map((name) => propertyRow(node, name)));
    body.dataset.signature = path + names.join("|");
  }
  for (const row of body.rows) {
    const input = row.querySelector("input");
    if (document.activeElement !== input) input.value = JSON.stringify(node.exported[row.dataset.name]);
  }
}

// A row of the properties table: the name, an input for the value, a badge (the timeline's too).
function propertyCells(name) {
  const row = document.createElement("tr");
  row.dataset.name = name;
  const label = document.createElement("td");
  label.textContent = name;
  const cell = document.createElement("td");
  const input = document.createElement("input");
  input.name = name;
  cell.append(input);
  const badge = document.createElement("td");
  badge.className = "badge";
  row.append(label, cell, badge);
  return {row, input, badge};
}

function propertyRow(node, name) {
  const {row, input, badge} = propertyCells(name);
  input.readOnly = node.read_only.includes(name);
  input.addEventListener("change", () => edit(node, name, input));
  input.addEventListener("keydown", (event) => { if (event.key === "Escape") input.blur(); });
  badge.textContent = input.readOnly ? "read-only" :
    node.settings.includes(name) ? "setting" : "episode";
  return row;
}

// A setting of an agent is that agent's alone (config.agent by its name, protocol 2.6).
async function edit(node, name, input) {
  const path = node.path;
  const note = $("edit-status");
  let value;
  try { value = JSON.parse(input.value); } catch (error) {
    note.textContent = `${name}: not a value (numbers, true/false, [x, y], "text"): ${input.value}`;
    note.className = "note bad";
    return;
  }
  const response = await fetch("api/edit", {
    method: "POST", headers: {"Content-Type": "application/json"},
    body: JSON.stringify({server: state.server, instance: state.instance, path, property: name, value}),
  });
  const answer = await response.json();
  note.textContent = response.ok ? `${name} = ${JSON.stringify(value)} (${answer.scope === "setting" ?
    `a setting${node.config === "agent" ? " of this agent" : ""}: kept across episodes` :
    "until the next reset"})` : `refused: ${answer.error}`;
  note.className = response.ok ? "note" : "note bad";
  input.blur();
}

async function takeSnapshot() {
  const snapshot = await api("snapshot");
  const text = JSON.stringify(snapshot, null, 1);
  const events = snapshot.events || [];
  $("snapshot").textContent = `${events.length} events; the last ones:\n` +
    events.slice(-6).map((e) => JSON.stringify(e)).join("\n");
  const link = $("snapshot-download");
  if (link.href) URL.revokeObjectURL(link.href);
  link.href = URL.createObjectURL(new Blob([text], {type: "application/json"}));
  link.hidden = false;
}

// --- statistics and plots ------------------------------------------------------------------

async function refreshStats() {
  if (!watching()) return;
  const generation = state.generation;
  let stats = await api("stats", {since: state.next});
  if (generation !== state.generation) return;
  const last = state.lastTotals;
  if (last && (stats.next < state.next || stats.restarts !== last.restarts)) {
    forgetEpisodes();  // another server process: its episodes are numbered afresh
    stats = await api("stats", {since: 0});
    if (generation !== state.generation) return;
  }
  state.episodes = state.episodes.concat(stats.episodes).slice(-PLOTTED);
  state.next = stats.next;
  const previous = state.lastTotals;
  if (previous && stats.time > previous.time && stats.steps >= previous.steps) {
    const speed = (stats.steps - previous.steps) / (stats.time - previous.time);
    state.speed = state.speed.concat([[stats.time, speed]]).slice(-PLOTTED);
  }
  if (previous && stats.steps !== previous.steps && !state.control.controlling) {
    state.othersSteppedAt = performance.now();  // another client drives it: it has control
  }
  state.lastTotals = stats;
  const current = stats.current;
  if (!timeTravelling()) $("episode").textContent = current ? `episode ${stats.next}: return ${current.return.toFixed(2)}` +
    `, ${current.length} steps` + (current.returns ? " · " + Object.entries(current.returns)
      .map(([agent, r]) => `${agent} ${r.toFixed(2)}`).join(", ") : "") : "no episode under way";
  $("totals").textContent = `${stats.next} episodes · ${stats.steps} steps · ${stats.errors} errors` +
    ` · ${stats.restarts} restarts`;
  const x = state.episodes.map((e) => e.episode);
  const returns = [{name: "return", points: state.episodes.map((e, i) => [x[i], e.return])}];
  const agents = state.episodes.length && state.episodes[0].returns ? Object.keys(state.episodes[0].returns) : [];
  for (const agent of agents) {
    returns.push({name: agent, points: state.episodes.map((e, i) => [x[i], e.returns ? e.returns[agent] : NaN])});
  }
  plot($("plot-return"), "return per episode", returns);
  $("plot-return").dataset.episodes = state.next;
  plot($("plot-length"), "length per episode (steps)",
       [{name: "length", points: state.episodes.map((e, i) => [x[i], e.length])}]);
  const t0 = state.speed.length ? state.speed[0][0] : 0;
  plot($("plot-speed"), "steps per second", [{name: "steps/s",
       points: state.speed.map(([t, v]) => [t - t0, v])}]);
}

// --- demonstrations: a person takes control and plays from the keyboard -------------------

async function post(path, body) {
  const response = await fetch(`api/${path}`, {
    method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body),
  });
  const answer = await response.json();
  if (!response.ok) throw new Error(answer.error || response.statusText);
  return answer;
}

function showControl(control, note = null, bad = false) {
  state.control = control;
  $("control").hidden = !control.enabled;
  if (!control.enabled) return;
  const busy = performance.now() - state.othersSteppedAt < OTHERS_QUIET;
  const mine = control.controlling && control.server === state.server && control.instance === state.instance;
  const playable = playableAgents();
  const choice = $("control-agent");
  if (choice.dataset.agents !== playable.join("|")) {
    choice.replaceChildren(...playable.map((name) => new Option(name, name)));
    choice.dataset.agents = playable.join("|");
  }
  choice.hidden = control.controlling || playable.length < 2;
  $("take-control").hidden = control.controlling;
  $("take-control").disabled = busy;
  $("take-control").title = busy ? "another client controls this environment" : "";
  $("release-control").hidden = !control.controlling;
  const status = $("control-status");
  status.dataset.episodes = control.episodes;
  status.dataset.held = (control.held || []).join(" ");
  status.textContent = note ?? (control.error ? control.error :
    mine ? `you control ${control.agent ?? "it"}: keys ${control.keys.map((k) => k === " " ? "Space" : k).join(", ")}` +
           ` · ${control.episodes} episodes recorded in ${control.directory}` :
    control.controlling ? `you control server ${control.server} instance ${control.instance}` :
    busy ? "another client controls this environment" : `${control.episodes} episodes recorded`);
  status.classList.toggle("bad", bad || !!control.error);
}

async function refreshControl() {
  const response = await fetch("api/control", {cache: "no-store"});
  showControl(await response.json());
}

// The agents a person may play on the selected server: its agents less those it drives.
function playableAgents() {
  const server = state.servers[state.server] || {};
  return (server.agents || []).filter((name) => !(server.driven || []).includes(name));
}

async function takeControl() {
  const body = {server: state.server, instance: state.instance};
  if (playableAgents().length > 1) body.agent = $("control-agent").value;
  try {
    showControl(await post("control", body));
  } catch (error) { showControl(state.control, `refused: ${error.message}`, true); }
}

async function releaseControl() {
  state.held = [];
  showControl(await post("release", {}));
}

function onKey(event, down) {
  if (timeTravelling() || !state.control.controlling || !state.control.keys.includes(event.key)) return;
  const target = event.target;
  if (target instanceof HTMLInputElement || target instanceof HTMLSelectElement) return;
  event.preventDefault();  // the arrows and space would scroll the page
  if (event.repeat) return;
  state.held = state.held.filter((key) => key !== event.key).concat(down ? [event.key] : []);
  post("keys", {held: state.held}).catch((error) => showControl(state.control, error.message, true));
}

function releaseKeys() {
  if (!state.held.length || !state.control.controlling) return;
  state.held = [];
  post("keys", {held: []}).catch(() => {});
}

const PALETTE = ["#426eb4", "#d7782e", "#3a9a5b", "#a04cb0", "#b3261e"];

function plot(canvas, title, series) {
  const context = canvas.getContext("2d");
  const {width, height} = canvas;
  const pad = {left: 48, right: 10, top: 20, bottom: 20};
  context.clearRect(0, 0, width, height);
  context.font = "12px system-ui, sans-serif";
  context.fillStyle = "#1d2530";
  context.fillText(title, pad.left, 13);
  const points = series.flatMap((s) => s.points).filter(([, y]) => Number.isFinite(y));
  canvas.dataset.points = points.length;
  if (!points.length) return;
  const xs = points.map((p) => p[0]);
  const ys = points.map((p) => p[1]);
  let [xMin, xMax, yMin, yMax] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  if (xMax === xMin) xMax = xMin + 1;
  if (yMax === yMin) { yMax += 1; yMin -= 1; }
  const sx = (x) => pad.left + (x - xMin) / (xMax - xMin) * (width - pad.left - pad.right);
  const sy = (y) => height - pad.bottom - (y - yMin) / (yMax - yMin) * (height - pad.top - pad.bottom);
  context.strokeStyle = "#d8dde4";
  context.strokeRect(pad.left, pad.top, width - pad.left - pad.right, height - pad.top - pad.bottom);
  context.fillStyle = "#6b7380";
  context.fillText(yMax.toPrecision(4), 2, pad.top + 10);
  context.fillText(yMin.toPrecision(4), 2, height - pad.bottom);
  context.fillText(String(Math.round(xMin)), pad.left, height - 4);
  context.fillText(String(Math.round(xMax)), width - pad.right - 30, height - 4);
  series.forEach((s, index) => {
    context.strokeStyle = PALETTE[index % PALETTE.length];
    context.lineWidth = index === 0 ? 1.5 : 1;
    context.beginPath();
    s.points.forEach(([x, y], i) => {
      if (Number.isFinite(y)) (i ? context.lineTo : context.moveTo).call(context, sx(x), sy(y));
    });
    context.stroke();
    if (series.length > 1) {
      context.fillStyle = context.strokeStyle;
      context.fillText(s.name, width - pad.right - 90, pad.top + 12 + 13 * index);
    }
  });
}

// --- start ---------------------------------------------------------------------------------

window.addEventListener("DOMContentLoaded", () => {
  $("target").addEventListener("change", (event) => choose(event.target.value));
  $("snapshot-button").addEventListener("click", () =>
    takeSnapshot().catch((error) => { $("snapshot").textContent = error.message; }));
  every(SERVERS_INTERVAL, refreshServers);
  every(FRAME_INTERVAL, refreshFrame);
  every(TREE_INTERVAL, refreshTree);
  every(NODE_INTERVAL, refreshNode);
  every(STATS_INTERVAL, refreshStats);
  $("take-control").addEventListener("click", takeControl);
  $("release-control").addEventListener("click", () =>
    releaseControl().catch((error) => showControl(state.control, error.message, true)));
  document.addEventListener("keydown", (event) => onKey(event, true));
  document.addEventListener("keyup", (event) => onKey(event, false));
  window.addEventListener("blur", releaseKeys);  // a key released elsewhere is never seen
  every(CONTROL_INTERVAL, refreshControl);
});
