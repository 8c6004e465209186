// The inspector page's time travel: a recording's timeline under the scene (scrub, step, tick,
// play), its properties at the scrubbed moment, branches made with the agent's keys or a policy
// (a small tree), and two branches side by side. It asks the inspector's api/timeline* routes
// (relative URLs: the page's key comes along) one thing at a time: while an answer is awaited,
// newer wishes replace older ones (a fast drag asks for the step it ends on, never for every
// step it crossed). It uses inspector.js's drawScene, showObservations, select, plot and post.
"use strict";

const PLAY_INTERVAL = 100;   // ms between steps while playing
const RECENT_INTERVAL = 5000;  // the recent episodes of the watched instance
const TICK_PAGE = 100;  // ticks asked for at a time (the server's most: a long step comes in pages)

const timeline = {
  active: false,       // the page shows a timeline (the live loops stand aside)
  offline: false,      // no server watched: rlenv replay FILE --inspect
  list: [], policies: [], unavailable: {},
  number: null, info: null, branch: 0, step: 0, shown: null, loads: 0,
  wanted: null, inflight: false,
  tick: null,          // {step, index, count} while between two steps, else null
  ticks: null,         // a page of the ticks of one step: {step, branch, frames, first, next, ticks}
  playing: false,
  branching: null,     // {parent, step, branch}: key presses make and lengthen a branch
  queue: Promise.resolve(),
  a: 0, b: 0, compared: null, compareWanted: false, compareInflight: false,
  recentSignature: "",
};
window.timeline = timeline;  // for whoever drives the page (its browser test)

async function timelineGet(path, params) {
  const response = await fetch(`api/${path}?${new URLSearchParams(params)}`, {cache: "no-store"});
  const body = await response.json();
  if (!response.ok) throw new Error(body.error || response.statusText);
  return body;
}

function timelineNote(id, text, bad = false) {
  const note = $(id);
  note.textContent = text;
  note.classList.toggle("bad", bad);
}

// --- which timeline ---------------------------------------------------------------------------

async function refreshTimelines() {
  const answer = await timelineGet("timelines", {});
  timeline.list = answer.timelines;
  timeline.policies = answer.policies;
  timeline.unavailable = answer.unavailable;
  const select = $("timeline-select");
  // A file's name comes with as much of its folder as tells it from others of the same name.
  const label = (t) => t.name + (t.error ? " (did not open)" : "");
  const signature = answer.timelines.map((t) => `${t.timeline}=${label(t)}`).join("|");
  if (select.dataset.signature !== signature) {
    select.replaceChildren(...answer.timelines.map((t) => {
      const option = new Option(label(t), t.timeline);
      option.title = t.origin.file || t.name;
      return option;
    }));
    select.dataset.signature = signature;
  }
  if (timeline.number !== null) select.value = String(timeline.number);
}

// Open a timeline. If it cannot be opened, the section still shows, with why and the menu to
// choose another (its scrubber and branches stand aside).
async function openTimeline(number) {
  timeline.playing = false;
  stopBranching();
  const section = $("timeline");
  section.hidden = false;
  $("timeline-live").hidden = timeline.offline;
  $("timeline-select").value = String(number);
  timelineNote("timeline-status", "opening (the episode is re-simulated once)…");
  let info;
  try {
    info = await timelineGet("timeline", {timeline: number});
  } catch (error) {
    timeline.active = false;
    timeline.number = number;
    timeline.shown = null;
    $("timeline-body").hidden = true;
    $("compare").hidden = true;
    section.dataset.failed = number;
    await refreshTimelines().catch(() => {});  // the menu marks it
    $("timeline-select").value = String(number);
    timelineNote("timeline-status", error.message, true);
    return;
  }
  delete section.dataset.failed;
  $("timeline-body").hidden = false;
  timeline.active = true;
  document.body.classList.add("time-travel");
  timeline.number = number;
  timeline.branch = 0;
  timeline.a = 0;
  timeline.b = newestBranch(info);  // side by side: the episode and its newest branch
  timeline.compared = null;
  timeline.ticks = null;
  showTimeline(info);
  $("recent").hidden = true;
  timelineNote("timeline-status", info.target || "");
  want(0);
}

function backToLive() {
  timeline.active = false;
  timeline.playing = false;
  stopBranching();
  document.body.classList.remove("time-travel");
  $("timeline").hidden = true;
  $("compare").hidden = true;
  const body = $("properties").tBodies[0];
  body.replaceChildren();
  delete body.dataset.signature;
  delete $("tree").dataset.signature;
  refreshRecent().catch(() => {});
}

// The timeline's description (api/timeline, or what a branch returned): its tree, the policies.
function showTimeline(info) {
  timeline.info = info;
  showBranches();
  const policies = info.policies;
  const select = $("policy-select");
  if (select.dataset.signature !== policies.join("|")) {
    select.replaceChildren(...policies.map((name) => new Option(name, name)));
    select.dataset.signature = policies.join("|");
  }
  const unavailable = Object.entries(info.unavailable);
  $("policy-box").hidden = !policies.length;
  if (!policies.length && unavailable.length) {
    timelineNote("branch-status", unavailable.map(([name, why]) => `policy ${name}: ${why}`)
      .join("; "), true);
  }
  $("branch-here").disabled = !info.keys.length;
  $("branch-here").title = info.keys.length ? `take control from this step with the agent's ` +
    `keys (${info.keys.map(keyName).join(", ")})` : info.keys_error;
  for (const id of ["compare-a", "compare-b"]) {
    const chooser = $(id);
    const options = info.branches.map((b) => new Option(`#${b.branch} ${b.label}`, b.branch));
    const signature = info.branches.map((b) => `${b.branch}:${b.label}`).join("|");
    if (chooser.dataset.signature !== signature) {
      chooser.replaceChildren(...options);
      chooser.dataset.signature = signature;
    }
  }
  if (timeline.a === timeline.b) timeline.b = newestBranch(info);  // never one branch twice
  $("compare-a").value = String(timeline.a);
  $("compare-b").value = String(timeline.b);
  $("compare").hidden = info.branches.length < 2;
}

const keyName = (key) => (key === " " ? "Space" : key);
const newestBranch = (info) => Math.max(...info.branches.map((b) => b.branch));

function branchOf(number) {
  return timeline.info.branches.find((b) => b.branch === number);
}

function showBranches() {
  const list = $("branches");
  const children = {};
  for (const branch of timeline.info.branches) {
    (children[branch.parent] = children[branch.parent] || []).push(branch);
  }
  const item = (branch) => {
    const li = document.createElement("li");
    li.dataset.branch = branch.branch;
    li.classList.toggle("selected", branch.branch === timeline.branch);
    const label = document.createElement("span");
    label.textContent = branch.parent === null ? `#0 the episode · ${branch.length} steps` :
      `#${branch.branch} ${branch.label} · from step ${branch.at} · ${branch.length} steps` +
      (branch.ended ? " · ended" : "");
    label.addEventListener("click", () => chooseBranch(branch.branch));
    li.append(label);
    if (children[branch.branch]) {
      const ul = document.createElement("ul");
      ul.append(...children[branch.branch].map(item));
      li.append(ul);
    }
    return li;
  };
  list.replaceChildren(...(children[null] || []).map(item));
  list.dataset.count = timeline.info.branches.length;
}

function chooseBranch(number) {
  stopBranching();
  timeline.branch = number;
  showBranches();
  want(Math.min(timeline.step, branchOf(number).length));
}

// --- going to a step, a tick ------------------------------------------------------------------

function branchLength() {
  return timeline.info ? branchOf(timeline.branch).length : 0;
}

// Ask for a step; while one is awaited only the latest wish is kept.
function want(step) {
  timeline.wanted = Math.max(0, Math.min(step, branchLength()));
  timeline.tick = null;
  pump();
}

async function pump() {
  if (timeline.inflight || timeline.wanted === null) return;
  timeline.inflight = true;
  const [step, branch, number] = [timeline.wanted, timeline.branch, timeline.number];
  timeline.wanted = null;
  try {
    const state = await timelineGet("timeline/step", {timeline: number, branch, step});
    if (number === timeline.number && branch === timeline.branch && timeline.active) {
      showStep(state);
    }
  } catch (error) {
    timelineNote("timeline-status", error.message, true);
    timeline.playing = false;
  } finally {
    timeline.inflight = false;
  }
  if (timeline.wanted !== null) pump();
}

function showStep(state) {
  timeline.shown = state;
  timeline.step = state.step;
  timeline.loads++;
  drawScene($("scene"), state.draw);
  showObservations(state.observation);
  showTree(Object.keys(state.properties));
  showProperties();
  showPosition();
  showAgents(state);
  compareSoon();
}

// Who is in play at this step (+ joined now, "left" as they go) and each agent's return so far.
// A group of agents shows its members in play, those that joined (+) and left (-) now.
function showAgents(state) {
  const box = $("timeline-agents");
  const agents = state.agents_in_play || [];
  const groups = state.groups || {};
  box.hidden = agents.length < 2 && Object.keys(groups).length === 0;
  const joined = (name) => (state.step > 0 && state.arrived.includes(name) ? "+" : "");
  const left = (name) => (state.left.includes(name) ? " (left)" : "");
  const members = (name) => {
    const group = groups[name];
    if (!group) return "";
    const moved = (group.arrived.length ? ` +${group.arrived.length}` : "") +
      (group.left.length ? ` -${group.left.length}` : "");
    return ` [${group.in_play} members${moved}]`;
  };
  const returns = Object.entries(state.agent_returns || {});
  box.textContent = "in play: " +
    agents.map((n) => joined(n) + n + members(n) + left(n)).join(", ") +
    ` · returns: ${returns.map(([n, r]) => `${n} ${formatNumber(r)}`).join(", ")}`;
  box.dataset.inPlay = agents.join(",");
  box.dataset.members = Object.entries(groups).map(([n, g]) => `${n}:${g.in_play}`).join(",");
}

function showPosition() {
  const scrubber = $("scrubber");
  scrubber.max = branchLength();
  if (document.activeElement !== scrubber || !timeline.dragging) scrubber.value = timeline.step;
  const state = timeline.shown;
  const tick = timeline.tick;
  const end = state.terminated ? " · terminated" : state.truncated ? " · truncated" : "";
  $("position").textContent = `step ${timeline.step} / ${branchLength()}` +
    (tick ? ` · tick ${tick.index}/${tick.count} of step ${tick.step}` : "") +
    ` · reward ${formatNumber(tick ? shownTick().reward : state.reward)}` +
    end + (timeline.branch ? ` · branch #${timeline.branch}` : "");
  $("fps").textContent = `time travel · ${timeline.info.name}`;
  $("episode").textContent = tick ? `tick ${tick.index} of step ${tick.step}` :
    `step ${timeline.step}`;
  const position = $("position").dataset;
  position.step = timeline.step;
  position.tick = tick ? tick.index : 0;
  position.branch = timeline.branch;
  $("play").textContent = timeline.playing ? "❚❚ pause" : "▶ play";
  $("play").dataset.playing = timeline.playing;
}

const formatNumber = (n) => (typeof n === "number" ? +n.toFixed(4) : n);

// The tree of the scrubbed moment (its nodes' paths), in inspector.js's list.
function showTree(paths) {
  const list = $("tree");
  const signature = "timeline:" + paths.join("|");
  if (list.dataset.signature !== signature) {
    const root = paths.length ? paths[0].split("/").length : 0;
    list.replaceChildren(...paths.map((path) => {
      const item = document.createElement("li");
      item.dataset.path = path;
      item.style.paddingLeft = `${4 + 14 * (path.split("/").length - root)}px`;
      item.textContent = path.split("/").pop();
      item.addEventListener("click", () => select(path));
      return item;
    }));
    list.dataset.signature = signature;
  }
  if ((state.path === null || !paths.includes(state.path)) && paths.length) {
    state.path = paths.find((p) => p.endsWith("/Agent")) || paths[0];
    $("selected").textContent = state.path;
  }
  for (const item of list.children) item.classList.toggle("selected", item.dataset.path === state.path);
}

// The selected node's properties at the scrubbed moment (a tick's, between two steps): read-only.
timeline.showProperties = () => {
  if (!timeline.shown || state.path === null) return;
  const tick = timeline.tick;
  const properties = (tick ? shownTick() : timeline.shown).properties;
  const values = properties[state.path] || {};
  const body = $("properties").tBodies[0];
  const names = Object.keys(values);
  const signature = "timeline:" + state.path + names.join("|");
  if (body.dataset.signature !== signature) {
    body.replaceChildren(...names.map((name) => {
      const {row, input} = propertyCells(name);
      input.readOnly = true;
      return row;
    }));
    body.dataset.signature = signature;
  }
  const moment = tick ? `tick ${tick.index} of step ${tick.step}` : `step ${timeline.step}`;
  for (const row of body.rows) {
    row.querySelector("input").value = JSON.stringify(values[row.dataset.name]);
    row.cells[2].textContent = moment;
  }
  body.dataset.moment = moment;
};

// The tick shown between two steps, from the page of ticks held.
const shownTick = () => timeline.ticks.ticks[timeline.tick.index - timeline.ticks.first];

// The page of the ticks of ``step`` that holds tick ``index`` (pages of TICK_PAGE, from tick 1).
async function ticksPage(step, index) {
  const held = timeline.ticks;
  const first = Math.floor((index - 1) / TICK_PAGE) * TICK_PAGE + 1;
  if (!held || held.step !== step || held.branch !== timeline.branch || held.first !== first) {
    const branch = timeline.branch;
    const answer = await timelineGet("timeline/ticks", {timeline: timeline.number, branch, step,
                                                        first, count: TICK_PAGE});
    timeline.ticks = {...answer, branch};
  }
  return timeline.ticks;
}

// One physics tick forward (+1) or back (-1); the last tick of a step is the next step.
async function tickBy(direction) {
  if (timeline.inflight || !timeline.shown) return;
  const tick = timeline.tick;
  const action = tick ? tick.step : direction > 0 ? timeline.step + 1 : timeline.step;
  if (action < 1 || action > branchLength()) return;
  let index = tick ? tick.index + direction : direction > 0 ? 1 :
    (await ticksPage(action, 1)).frames - 1;
  if (index <= 0) { want(action - 1); return; }
  let page = await ticksPage(action, index);
  const lastOf = (p) => (p.next === null ? p.first + p.ticks.length - 1 : Infinity);
  if (!tick && direction < 0 && index >= lastOf(page)) {  // the episode ended inside the step
    index = lastOf(page) - 1;
    if (index <= 0) { want(action - 1); return; }
    page = await ticksPage(action, index);
  }
  if (index >= lastOf(page)) { want(action); return; }
  timeline.tick = {step: action, index, count: page.frames};
  timeline.step = action - 1;
  const shown = shownTick();
  drawScene($("scene"), shown.draw);
  showObservations(shown.observation);
  showProperties();
  showPosition();
}

function showProperties() { timeline.showProperties(); }

function stepBy(direction) {
  if (!timeline.shown) return;
  const from = timeline.tick ? (direction > 0 ? timeline.tick.step - 1 : timeline.tick.step)
    : timeline.step;
  want(from + direction);
}

function togglePlay() {
  timeline.playing = !timeline.playing;
  if (timeline.playing && timeline.step >= branchLength()) want(0);
  if (timeline.shown) showPosition();
}

function playOn() {
  if (timeline.playing && timeline.active && !timeline.inflight && timeline.wanted === null) {
    if (timeline.step >= branchLength()) { timeline.playing = false; showPosition(); } else want(timeline.step + 1);
  }
  setTimeout(playOn, PLAY_INTERVAL);
}

// --- branching ----------------------------------------------------------------------------------

function startBranching() {
  if (!timeline.shown) return;
  timeline.playing = false;
  timeline.branching = {parent: timeline.branch, step: timeline.step, branch: null};
  $("branch-here").hidden = true;
  $("branch-done").hidden = false;
  timelineNote("branch-status", `branching from step ${timeline.step}: press ` +
    `${timeline.info.keys.map(keyName).join(", ")} (each press: one action); Escape or Done ` +
    `to stop`);
  $("branch-done").focus();
}

function stopBranching() {
  timeline.branching = null;
  $("branch-here").hidden = false;
  $("branch-done").hidden = true;
}

// Each key press while branching: one more action (the first makes the branch).
function branchKey(key) {
  const branching = timeline.branching;
  timeline.queue = timeline.queue.then(async () => {
    if (timeline.branching !== branching) return;
    const answer = branching.branch === null ?
      await post("timeline/branch", {timeline: timeline.number, branch: branching.parent,
                                     step: branching.step, key}) :
      await post("timeline/extend", {timeline: timeline.number, branch: branching.branch, key});
    branching.branch = answer.branch;
    timeline.branch = answer.branch;
    timeline.a = branching.parent;
    timeline.b = answer.branch;
    showTimeline(answer);
    const made = branchOf(answer.branch);
    timelineNote("branch-status", `branch #${made.branch}: ${made.label} · ` +
      `${made.length} steps` + (made.ended ? " · its episode ended" : ""));
    want(made.length);
  }).catch((error) => timelineNote("branch-status", `refused: ${error.message}`, true));
}

async function branchWithPolicy() {
  const policy = $("policy-select").value;
  const steps = Number($("policy-steps").value);
  timelineNote("branch-status", `${policy} plays from step ${timeline.step}…`);
  try {
    const parent = timeline.branch;
    const answer = await post("timeline/policy", {timeline: timeline.number, branch: parent,
                                                  step: timeline.step, policy, max_steps: steps});
    timeline.branch = answer.branch;
    timeline.a = parent;
    timeline.b = answer.branch;
    showTimeline(answer);
    const made = branchOf(answer.branch);
    timelineNote("branch-status", `branch #${made.branch}: ${made.label} · ${made.length} steps`);
    want(timeline.step);
  } catch (error) { timelineNote("branch-status", `refused: ${error.message}`, true); }
}

// --- side by side -------------------------------------------------------------------------------

function compareSoon() {
  if ($("compare").hidden) return;
  timeline.compareWanted = true;
  compareNow();
}

async function compareNow() {
  if (timeline.compareInflight || !timeline.compareWanted) return;
  timeline.compareInflight = true;
  timeline.compareWanted = false;
  const [a, b, step, number] = [timeline.a, timeline.b, timeline.step, timeline.number];
  try {
    const answer = await timelineGet("timeline/compare", {timeline: number, a, b, step});
    if (number === timeline.number) showComparison(answer);
  } catch (error) {
    timelineNote("compare-status", error.message, true);
  } finally {
    timeline.compareInflight = false;
  }
  if (timeline.compareWanted) compareNow();
}

function showComparison(answer) {
  timeline.compared = answer;
  const first = answer.first_difference;
  const box = $("compare");
  box.dataset.firstDifference = first === null ? "none" : first;
  box.dataset.step = answer.step;
  box.dataset.a = answer.a.branch;
  box.dataset.b = answer.b.branch;
  $("compare-note").textContent = `#${answer.a.branch} and #${answer.b.branch} at step ${answer.step}`;
  timelineNote("compare-status", first === null ? "the same, step for step" :
    `first difference at step ${first}` + ` · returns ${formatNumber(answer.a.return)} and ` +
    `${formatNumber(answer.b.return)}`);
  const cumulative = (rewards) => { let total = 0; return rewards.map((r, i) => [i, total += r]); };
  const each = (rewards) => rewards.map((r, i) => [i, r]);
  const last = Math.max(answer.a.rewards.length, answer.b.rewards.length) - 1;
  const marks = [[answer.step, "#1d2530"], ...(first === null ? [] : [[first, "#b3261e"]])];
  for (const [id, title, points] of [["compare-rewards", "reward per step", each],
                                     ["compare-returns", "return so far", cumulative]]) {
    plot($(id), title, [{name: `A #${answer.a.branch}`, points: points(answer.a.rewards)},
                        {name: `B #${answer.b.branch}`, points: points(answer.b.rewards)}]);
    markSteps($(id), last, marks);
  }
  const rows = [["", `A #${answer.a.branch}`, `B #${answer.b.branch}`, "B − A"],
                ["reward", answer.a.reward, answer.b.reward,
                 answer.a.reward === null || answer.b.reward === null ? "" :
                   answer.b.reward - answer.a.reward]];
  const numbers = (shown) => {
    const flat = [];
    const walk = (name, s) => {
      if (s.parts) for (const [part, inner] of Object.entries(s.parts)) walk(`${name}.${part}`, inner);
      else if (s.numbers) s.numbers.forEach((n, i) => flat.push([`${name}[${i}]`, n]));
      else if (s.image) flat.push([name, `image ${s.image.width}×${s.image.height}`]);
    };
    if (shown) for (const [agent, s] of Object.entries(shown)) walk(agent, s);
    return flat;
  };
  const [na, nb, nd] = [numbers(answer.a.observation), numbers(answer.b.observation),
                        numbers(answer.difference)];
  const names = (na.length ? na : nb).map(([name]) => name);
  names.forEach((name, i) => rows.push([name, na[i] ? na[i][1] : "", nb[i] ? nb[i][1] : "",
                                        nd[i] ? nd[i][1] : ""]));
  const body = $("compare-table").tBodies[0];
  body.replaceChildren(...rows.map((cells, index) => {
    const row = document.createElement("tr");
    if (index > 0 && typeof cells[3] === "number" && cells[3] !== 0) row.className = "differs";
    row.append(...cells.map((cell) => {
      const td = document.createElement(index === 0 ? "th" : "td");
      td.textContent = cell === null ? "—" : String(formatNumber(cell));
      return td;
    }));
    return row;
  }));
}

// Vertical marks at steps on a plot() canvas whose x axis runs from step 0 to ``last``.
function markSteps(canvas, last, marks) {
  const context = canvas.getContext("2d");
  const pad = {left: 48, right: 10, top: 20, bottom: 20};
  const width = canvas.width - pad.left - pad.right;
  for (const [step, colour] of marks) {
    const x = pad.left + (last > 0 ? step / last : 0) * width;
    context.strokeStyle = colour;
    context.setLineDash(colour === "#b3261e" ? [4, 3] : []);
    context.beginPath();
    context.moveTo(x, pad.top);
    context.lineTo(x, canvas.height - pad.bottom);
    context.stroke();
  }
  context.setLineDash([]);
}

// --- a live run's recent episodes -------------------------------------------------------------

async function refreshRecent() {
  if (timeline.offline || timeline.active || !state.servers.length) { $("recent").hidden = true; return; }
  const [server, instance] = [state.server, state.instance];
  const response = await fetch(`api/timeline/recent?${new URLSearchParams({server, instance})}`,
                               {cache: "no-store"});
  const answer = await response.json();
  if (!response.ok) {
    $("recent").hidden = true;
    $("recent").dataset.error = answer.error || "";
    return;
  }
  $("recent").hidden = false;
  const signature = `${server}/${instance}:` + answer.map((e) => e.id).join("|");
  if (timeline.recentSignature === signature) return;
  timeline.recentSignature = signature;
  const list = $("recent-list");
  list.dataset.count = answer.length;
  list.replaceChildren(...answer.map((episode) => {
    const li = document.createElement("li");
    li.dataset.episode = episode.episode;
    li.textContent = `episode ${episode.episode + 1} of ${answer.length} · ${episode.steps} steps` +
      (episode.terminated ? " · terminated" : episode.truncated ? " · truncated" : "");
    li.title = "open it as a timeline";
    li.addEventListener("click", () => openRecent(server, instance, episode.id));
    return li;
  }));
  if (!answer.length) list.replaceChildren(Object.assign(document.createElement("li"), {
    textContent: "no finished episode kept yet"}));
}

async function openRecent(server, instance, id) {
  try {
    const info = await post("timeline/open", {server, instance, id});
    await refreshTimelines();
    await openTimeline(info.timeline);
  } catch (error) { timelineNote("timeline-status", error.message, true); $("timeline").hidden = false; }
}

// --- keys ---------------------------------------------------------------------------------------

function onTimelineKey(event) {
  if (!timeline.active) return;
  const target = event.target;
  if ((target instanceof HTMLInputElement && target.type !== "range") ||
      target instanceof HTMLSelectElement) return;
  if (target instanceof HTMLButtonElement && (event.key === " " || event.key === "Enter")) {
    return;  // the focused button's own click
  }
  if (timeline.branching) {
    if (event.key === "Escape") { stopBranching(); timelineNote("branch-status", "done"); return; }
    if (timeline.info.keys.includes(event.key)) {
      event.preventDefault();
      if (!event.repeat) branchKey(event.key);
    }
    return;
  }
  const moves = {ArrowLeft: -1, ArrowRight: 1};
  if (event.key in moves) {
    event.preventDefault();
    if (event.shiftKey) tickBy(moves[event.key]).catch((e) => timelineNote("timeline-status", e.message, true));
    else stepBy(moves[event.key]);
  } else if (event.key === " ") {
    event.preventDefault();
    togglePlay();
  }
}

// --- start ----------------------------------------------------------------------------------------

async function startTimelines() {
  await refreshTimelines();
  const servers = await (await fetch("api/servers", {cache: "no-store"})).json();
  timeline.offline = servers.length === 0;
  document.body.classList.toggle("offline", timeline.offline);
  if (timeline.offline && timeline.list.length) await openTimeline(timeline.list[0].timeline);
}

window.addEventListener("DOMContentLoaded", () => {
  const failed = (error) => timelineNote("timeline-status", error.message, true);
  $("timeline-select").addEventListener("change", (event) =>
    openTimeline(Number(event.target.value)).catch(failed));
  $("timeline-live").addEventListener("click", backToLive);
  const scrubber = $("scrubber");
  scrubber.addEventListener("pointerdown", () => { timeline.dragging = true; timeline.playing = false; });
  scrubber.addEventListener("pointerup", () => { timeline.dragging = false; });
  scrubber.addEventListener("input", () => want(Number(scrubber.value)));
  $("step-back").addEventListener("click", () => stepBy(-1));
  $("step-forward").addEventListener("click", () => stepBy(1));
  $("tick-back").addEventListener("click", () => tickBy(-1).catch(failed));
  $("tick-forward").addEventListener("click", () => tickBy(1).catch(failed));
  $("play").addEventListener("click", togglePlay);
  $("branch-here").addEventListener("click", startBranching);
  $("branch-done").addEventListener("click", () => { stopBranching(); timelineNote("branch-status", "done"); });
  $("branch-policy").addEventListener("click", branchWithPolicy);
  $("compare-a").addEventListener("change", (e) => { timeline.a = Number(e.target.value); compareSoon(); });
  $("compare-b").addEventListener("change", (e) => { timeline.b = Number(e.target.value); compareSoon(); });
  document.addEventListener("keydown", onTimelineKey);
  startTimelines().catch(failed);
  playOn();
  every(RECENT_INTERVAL, refreshRecent);
});
