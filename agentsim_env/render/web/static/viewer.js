// The agentsim web viewer page: socket, side panel (log stream, controls, agent panel), replay bar and the
// test hooks on window.agentsim. The 3D part is in scene3d.js, the wire format in protocol.js (docs/viewer.md).
import { Connection } from '/static/protocol.js';
import {
  Scene3D, GROUP_COLOURS, NO_GROUP, OFFLINE, COLLIDED, ENDED, MSG_KINDS, MSG_COLOURS, PAYLOAD_FALLING, PAYLOAD_LANDED,
} from '/static/scene3d.js';

const MAX_LOG_LINES = 1000;
const SPEEDS = [1, 2, 5, 10, 30, 0]; // steps per second; 0 = as fast as possible ("max")
const $ = (id) => document.getElementById(id);
const hex = (c) => `#${c.toString(16).padStart(6, '0')}`;

const params = new URLSearchParams(location.search);
const view = new Scene3D($('canvas'), { top: params.get('camera') === 'top' });

const state = {
  scene: null, // the last `scene` message
  latest: null, // the newest frame received, drawn on the next animation frame
  drawn: null, // the frame currently drawn
  paused: false,
  logPaused: false,
  held: [], // log lines received while the log is paused
  dropped: 0, // log lines the server dropped (reported in `log` messages)
  hidden: new Set(), // log kinds filtered out
  filtered: {}, // per log kind: lines received while it was filtered out
  filtersSet: false, // the scene's default filters applied once; later scenes keep the user's choices
  fpsCount: 0,
  fps: 0,
  status: null,
  connected: false,
  sliderBusy: false, // the user is dragging the replay slider
};

// ----- test hooks (part of the page's contract; see docs/viewer.md) ----------------------------------------------
const hooks = {
  ready: false,
  framesDrawn: 0,
  framesReceived: 0,
  lastStep: -1,
  lastSeq: -1,
  episode: -1,
  selected: null,
  logLines: () => [...$('log').children].filter((el) => !el.hidden).map((el) => el.textContent),
  project: (p) => view.project(p),
  markers: () => view.markerScreen(), // [{kind, slot, label, x, y}]: where the scenario's markers are drawn
  agentSizes: () => Array.from(view.shown || []), // each agent's drawn radius (metres) at the current camera
  // A `select` sent through the hook also updates the page's selection (so the agent reply is shown).
  send: (obj) => (obj && obj.cmd === 'select' && 'slot' in obj ? select(obj.slot) : conn.send(obj)),
};
window.agentsim = hooks;

// ----- socket -----------------------------------------------------------------------------------------------------
const conn = new Connection({
  onOpen() {
    state.connected = true;
    if (hooks.selected !== null) conn.send({ cmd: 'select', slot: hooks.selected }); // a new server session
    renderStatus();
  },
  onClose() {
    state.connected = false;
    renderStatus();
  },
  onBadMessage: (text) => showError(text),
  onFrame(frame) {
    // latest state wins: frames arriving between two draws replace each other. The frame is acknowledged on
    // arrival, so the stream's rate does not depend on how fast this machine draws (software WebGL is slow).
    state.latest = frame;
    hooks.framesReceived += 1;
    conn.send({ cmd: 'ack', seq: frame.seq });
  },
  onJson(msg) {
    const handler = HANDLERS[msg.type];
    if (handler) handler(msg);
  },
});

const HANDLERS = {
  scene(msg) {
    state.scene = msg;
    view.build(msg);
    view.setSelected(hooks.selected);
    state.drawn = null; // redraw the latest frame (if any) on the new scene
    $('title').textContent = msg.title || msg.scenario || 'agentsim';
    document.title = `${msg.title || msg.scenario || 'agentsim'} · agentsim viewer`;
    $('mode').textContent = msg.mode || '';
    $('scenario').textContent = msg.scenario && msg.scenario !== msg.title ? msg.scenario : '';
    if (!state.filtersSet) {
      state.filtersSet = true;
      for (const kind of msg.log_hidden || []) state.hidden.add(kind);
    }
    buildFilters(msg.log_kinds || []);
    buildLegend(msg);
    setupReplay(msg.replay);
  },
  log(msg) {
    for (const line of msg.lines || []) addLogLine(line.step, line.kind, line.text);
    if (msg.dropped > 0) { // lines the server could not keep for this page (it fell behind)
      state.dropped += msg.dropped;
      $('log-dropped').textContent = `${state.dropped} lines dropped by the server`;
    }
  },
  status(msg) {
    state.status = msg;
    state.paused = !!msg.paused;
    const speed = SPEEDS.includes(msg.speed) ? String(msg.speed) : null;
    for (const id of ['speed', 'replay-speed']) if (speed !== null) $(id).value = speed;
    renderControls();
    renderStatus();
  },
  agent(msg) {
    if (msg.slot === hooks.selected) renderAgent(msg);
  },
  error(msg) {
    showError(msg.message);
  },
};

// ----- drawing loop: draw the newest frame -------------------------------------------------
function tick(now) {
  const frame = state.latest;
  const fresh = frame !== null && frame !== state.drawn && state.scene !== null;
  if (fresh) view.setFrame(frame);
  view.render(now);
  if (fresh) {
    state.drawn = frame;
    hooks.framesDrawn += 1;
    hooks.lastStep = frame.step;
    hooks.lastSeq = frame.seq;
    hooks.episode = frame.episode;
    hooks.ready = true;
    state.fpsCount += 1;
    if (!state.sliderBusy && state.scene?.replay) updateSlider(frame.step);
  }
  requestAnimationFrame(tick);
}
requestAnimationFrame(tick);

setInterval(() => { // frames drawn per second, shown in the status line
  state.fps = state.fpsCount;
  state.fpsCount = 0;
  renderStatus();
}, 1000);

// ----- picking: a click (not a drag) on the canvas selects the agent under it, or clears the selection ---------
let down = null;
$('canvas').addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
$('canvas').addEventListener('pointerup', (e) => {
  if (!down || e.button !== 0 || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > 5) return;
  down = null;
  select(view.pick(e.clientX, e.clientY));
});

function select(slot) {
  hooks.selected = slot;
  view.setSelected(slot);
  conn.send({ cmd: 'select', slot });
  if (slot === null) $('agent-body').replaceChildren(text('Click an agent to see its state.', 'muted'));
  else $('agent-body').replaceChildren(text(`${state.scene?.agent_names?.[slot] ?? `slot ${slot}`} (slot ${slot})…`));
}

function text(str, cls) {
  const el = document.createElement('div');
  el.textContent = str;
  if (cls) el.className = cls;
  return el;
}

function fmt(v) {
  if (typeof v === 'number') return Number.isInteger(v) ? String(v) : v.toFixed(3);
  if (Array.isArray(v)) return `[${v.map(fmt).join(', ')}]`;
  if (v !== null && typeof v === 'object') return JSON.stringify(v);
  return String(v);
}

function table(rows, head) {
  const t = document.createElement('table');
  if (head) {
    const tr = t.insertRow();
    for (const h of head) tr.appendChild(Object.assign(document.createElement('th'), { textContent: h }));
  }
  for (const row of rows) {
    const tr = t.insertRow();
    row.forEach((cell, i) => {
      const td = document.createElement(!head && i === 0 ? 'th' : 'td');
      td.textContent = cell;
      tr.appendChild(td);
    });
  }
  return t;
}

function renderAgent(msg) {
  const body = [text(`${msg.name} (slot ${msg.slot})`, 'name'), table(Object.entries(msg.state || {}).map(
    ([k, v]) => [k, fmt(v)]))];
  const inbox = msg.inbox || [];
  body.push(text(`Inbox (${inbox.length})`, inbox.length ? '' : 'muted'));
  if (inbox.length) {
    body.push(table(inbox.map((m) => [m.kind, m.sender, m.age, m.hops, fmt(m.payload)].map(fmt)),
      ['kind', 'sender', 'age', 'hops', 'payload']));
  }
  $('agent-body').replaceChildren(...body);
}

// ----- log stream ------------------------------------------------------------------------------------------------
function addLogLine(step, kind, str) {
  const el = document.createElement('div');
  el.className = `line k-${kind}`;
  el.dataset.kind = kind;
  el.textContent = `step ${step} · ${kind} · ${str}`;
  el.hidden = state.hidden.has(kind);
  if (el.hidden) {
    state.filtered[kind] = (state.filtered[kind] || 0) + 1;
    renderFilterCounts();
  }
  if (state.logPaused) { // held (not shown) until the log is resumed; the simulation keeps going
    state.held.push(el);
    if (state.held.length > MAX_LOG_LINES) state.held.shift();
    renderHeld();
    return;
  }
  appendLines([el]);
}

function appendLines(els) {
  const log = $('log');
  const atBottom = log.scrollHeight - log.scrollTop - log.clientHeight < 30;
  log.append(...els);
  while (log.childElementCount > MAX_LOG_LINES) log.firstElementChild.remove();
  if (atBottom) log.scrollTop = log.scrollHeight; // auto-scroll unless the user scrolled up
}

function renderHeld() {
  $('log-held').textContent = state.logPaused ? `${state.held.length} new lines held` : '';
}

$('log-pause').addEventListener('click', () => {
  state.logPaused = !state.logPaused;
  $('log-pause').textContent = state.logPaused ? 'Resume log' : 'Pause log';
  if (!state.logPaused) {
    for (const el of state.held) el.hidden = state.hidden.has(el.dataset.kind); // filters may have changed
    appendLines(state.held);
    state.held = [];
    $('log').scrollTop = $('log').scrollHeight;
  }
  renderHeld();
});

function buildFilters(kinds) {
  const box = $('filters');
  box.replaceChildren(...kinds.map((kind) => {
    const label = document.createElement('label');
    const cb = Object.assign(document.createElement('input'), { type: 'checkbox', checked: !state.hidden.has(kind) });
    cb.dataset.kind = kind;
    cb.addEventListener('change', () => {
      if (cb.checked) state.hidden.delete(kind);
      else state.hidden.add(kind);
      for (const el of $('log').children) if (el.dataset.kind === kind) el.hidden = !cb.checked;
    });
    const count = Object.assign(document.createElement('span'), { className: 'count' });
    count.dataset.kind = kind;
    label.append(cb, ` ${kind}`, count);
    return label;
  }));
  renderFilterCounts();
}

/** After each filter box: how many lines of that kind it has filtered out (while it was unticked). */
let countsQueued = false;
function renderFilterCounts() {
  if (countsQueued) return;
  countsQueued = true;
  requestAnimationFrame(() => { // at most once a frame: heartbeats can come by the hundred
    countsQueued = false;
    for (const el of document.querySelectorAll('#filters .count')) {
      const n = state.filtered[el.dataset.kind] || 0;
      el.textContent = n ? ` (${n} filtered)` : '';
    }
  });
}

// ----- errors ----------------------------------------------------------------------------------------------------
function showError(message) {
  $('error-text').textContent = message;
  $('error-banner').hidden = false;
  addLogLine(hooks.lastStep, 'error', message);
}
$('error-dismiss').addEventListener('click', () => { $('error-banner').hidden = true; });

// ----- simulation controls (live) and replay bar: both send pause / resume / step / speed -----------------------
const togglePause = () => conn.send({ cmd: state.paused ? 'resume' : 'pause' });
const stepOnce = () => conn.send({ cmd: 'step' });
$('sim-pause').addEventListener('click', togglePause);
$('replay-play').addEventListener('click', togglePause);
$('sim-step').addEventListener('click', stepOnce);
$('replay-step').addEventListener('click', stepOnce);
$('replay-speed').replaceChildren(...[...$('speed').options].map((o) => new Option(o.text, o.value)));
for (const id of ['speed', 'replay-speed']) {
  $(id).value = '10';
  $(id).addEventListener('change', () => conn.send({ cmd: 'speed', value: Number($(id).value) }));
}

function renderControls() {
  const replay = !!state.scene?.replay;
  // one set of controls: the replay bar in a replay, the simulation's row live
  $('sim-row').hidden = replay;
  $('controls-title').textContent = replay ? 'Replay' : 'Simulation';
  $('sim-pause').textContent = state.paused ? 'Resume sim' : 'Pause sim';
  $('replay-play').textContent = state.paused ? 'Play' : 'Pause';
  $('sim-step').disabled = !state.paused;
  $('replay-step').disabled = !state.paused || !replay;
}

function renderStatus() {
  const el = $('status');
  el.classList.toggle('disconnected', !state.connected);
  if (!state.connected) {
    el.textContent = 'disconnected (retrying every 2 s)';
    return;
  }
  // episode and step of the frame on screen; the simulation's rate from the server's status
  const s = state.status;
  const parts = [`episode ${hooks.episode}`, `step ${hooks.lastStep}`];
  const rate = Number(s?.steps_per_s);
  if (s && Number.isFinite(rate)) {
    if (state.scene?.replay) parts.push(rate > 0 ? `${rate} steps/s` : 'as fast as possible');
    else parts.push(`${rate.toFixed(1)} steps/s`);
  }
  parts.push(`${state.fps} frames/s drawn`);
  if (state.paused) parts.push('paused');
  el.textContent = parts.join(' · ');
}

// Replay: the slider covers [first_step, first_step + n_steps - 1] and seeks (throttled while dragging).
let lastSeek = 0;
function setupReplay(replay) {
  $('replay-bar').hidden = !replay;
  if (replay) {
    $('replay-slider').min = replay.first_step;
    $('replay-slider').max = replay.first_step + replay.n_steps - 1;
    updateSlider(hooks.lastStep >= 0 ? hooks.lastStep : replay.first_step);
  }
  renderControls();
}

function updateSlider(step) {
  const r = state.scene.replay;
  $('replay-slider').value = step;
  $('replay-label').textContent = `step ${step} / ${r.first_step + r.n_steps - 1}`;
}

const seek = () => conn.send({ cmd: 'seek', step: Number($('replay-slider').value) });
$('replay-slider').addEventListener('pointerdown', () => { state.sliderBusy = true; });
$('replay-slider').addEventListener('input', () => {
  updateSlider(Number($('replay-slider').value));
  if (performance.now() - lastSeek > 100) { lastSeek = performance.now(); seek(); }
});
$('replay-slider').addEventListener('change', () => { state.sliderBusy = false; seek(); });

// ----- legend ----------------------------------------------------------------------------------------------------
function buildLegend(msg) {
  const item = (colour, label, cls = '') => {
    const el = document.createElement('span');
    el.className = 'item';
    const sw = document.createElement('span');
    sw.className = `sw ${cls}`;
    if (colour) sw.style.background = hex(colour);
    el.append(sw, label);
    return el;
  };
  const nGroups = Math.min(msg.n_groups || 0, GROUP_COLOURS.length);
  const items = [];
  if ((msg.n_groups || 1) <= 1) {
    const k = Math.min(msg.n_agents || 0, 3);
    items.push(item(null, `one colour per agent${(msg.n_agents || 0) > GROUP_COLOURS.length ? ' (repeating)' : ''}`,
      'multi'));
    if (!k) items.pop();
  } else {
    for (let g = 0; g < nGroups; g++) items.push(item(GROUP_COLOURS[g], `group ${g}`));
    if ((msg.n_groups || 0) > nGroups) items.push(text('(colours repeat)', 'item'));
    items.push(item(NO_GROUP, 'no group'));
  }
  items.push(item(null, 'arrived (pale)', 'pale'), item(COLLIDED, 'collided'), item(OFFLINE, 'offline'),
    item(ENDED, 'ended'), document.createElement('br'));
  const kinds = new Set((msg.markers || []).map((m) => m.kind));
  if (kinds.has('goal')) items.push(item(null, 'goal (agent\'s colour)', 'goal'));
  if (kinds.has('target')) items.push(item(null, 'group target (dashed: its scout)', 'goal'));
  if (kinds.has('marker')) items.push(item(null, 'marker', 'goal'));
  if ((msg.zones || []).length) items.push(item(null, 'zone density', 'grad'));
  MSG_KINDS.forEach((k, i) => items.push(item(MSG_COLOURS[i], `${k} msg`, 'line')));
  if (msg.scenario === 'uav_release' || 'payload_pos' in (state.latest?.arrays || {})) {
    items.push(item(PAYLOAD_FALLING, 'falling'), item(PAYLOAD_LANDED, 'landed'));
  }
  $('legend').replaceChildren(...items);
}

// ----- view options: trails, follow the selected agent, frame the agents -------------------------------------
$('opt-trails').addEventListener('change', () => view.setTrails($('opt-trails').checked));
$('opt-follow').addEventListener('change', () => {
  view.follow = $('opt-follow').checked;
  view.dirty = true;
});
$('opt-frame').addEventListener('click', () => view.frameAgents());

renderControls();
renderStatus();
