// Hot-zone designer page: a top-down map on which zones are drawn (press at the centre, drag out the radius),
// a form for the selected zone, and previews of the density and the expected sensor layouts from the server
// (agentsim_env/uav/designer/__init__.py). The server validates; its messages are shown verbatim in #error.

const $ = (id) => document.getElementById(id);
const PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2"];
const MARGIN = { left: 56, right: 14, top: 12, bottom: 40 };
const PREVIEW_DELAY_MS = 150;
const ZONE_FIELDS = ["name", "cx", "cy", "radius", "n_sensors", "profile", "alpha", "sigma", "floor", "weight",
  "altitude"];

const state = {
  mapSize: [600, 400],
  base: null,
  zones: [],            // full zone objects: {name, centre, radius, n_sensors, profile, alpha, sigma, floor, ...}
  selected: -1,
  preview: null,        // last successful preview (ok: true), or null after an error
  canSave: false,
  path: null,
  defaults: { n_sensors: 50, profile: "gauss", alpha: 1.0, floor: 0.0, weight: 1.0 },
  drag: null,           // {centre: [x, y], radius} while drawing a zone
};
let ws = null;
let previewTimer = null;
let previewSent = 0;      // id of the newest preview request; the server may skip older ones that had to wait
let previewAnswered = 0;  // id of the newest preview answered
let downloadUrl = null;

// ------------------------------------------------------------------ zone file <-> state
function fullZone(z) {
  const d = state.defaults;
  return {
    name: z.name ?? null, centre: z.centre, radius: z.radius, n_sensors: z.n_sensors,
    profile: z.profile ?? d.profile, alpha: z.alpha ?? d.alpha, sigma: z.sigma ?? null,
    floor: z.floor ?? d.floor, weight: z.weight ?? d.weight, altitude: z.altitude ?? null,
  };
}

function setFile(file) {
  state.mapSize = Array.isArray(file.map_size) ? file.map_size.slice() : [600, 400];
  state.base = Array.isArray(file.base) ? file.base.slice() : null;
  state.zones = (file.zones || []).map(fullZone);
  state.selected = state.zones.length ? 0 : -1;
  state.preview = null;
  fillMapForm();
  fillZoneForm();
  render();
}

function zoneFile() {
  const out = { version: 1, map_size: state.mapSize.slice() };
  if (state.base !== null) out.base = state.base.slice();
  out.zones = state.zones.map((z) => {
    const e = {};
    for (const [k, v] of Object.entries(z)) if (v !== null) e[k] = Array.isArray(v) ? v.slice() : v;
    return e;
  });
  return out;
}

// ------------------------------------------------------------------ server messages
function send(msg) {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg));
  else showError("not connected to the designer server: reload the page (is `agentsim zones design` running?)");
}

function schedulePreview() {
  clearTimeout(previewTimer);
  previewTimer = setTimeout(() => {
    previewTimer = null;
    previewSent += 1;
    send({ cmd: "zones.preview", zones: zoneFile(), id: previewSent });
  }, PREVIEW_DELAY_MS);
}

function onMessage(msg) {
  switch (msg.type) {
    case "zones.hello":
      state.canSave = !!msg.can_save;
      state.path = msg.path ?? null;
      if (msg.defaults) Object.assign(state.defaults, msg.defaults);
      fillProfiles(msg.profile_kinds || ["uniform", "power", "gauss", "linear"]);
      $("save").title = state.canSave ? `Write ${state.path}` : "Started without a file: use Download";
      if (state.path) $("download").download = state.path.split(/[\\/]/).pop() || "zones.json";
      setFile(msg.zones);
      setStatus(state.canSave ? `editing ${state.path}` + (msg.source === "file" ? "" : " (new file; showing the default zones)")
        : "no file: Save is off, use Download");
      schedulePreview();
      window.designer.ready = true;
      break;
    case "zones.preview":
      if (typeof msg.id === "number") previewAnswered = Math.max(previewAnswered, msg.id);
      window.designer.lastPreview = msg;
      if (msg.ok) {
        state.preview = msg;
        clearError();
      } else {
        state.preview = null;
        showError(msg.error);
      }
      render();
      break;
    case "zones.saved":
      setStatus(`saved to ${msg.path} (${msg.n_zones} zone${msg.n_zones === 1 ? "" : "s"})`);
      break;
    case "zones.loaded":
      setFile(msg.zones);
      setStatus(`loaded ${msg.path}`);
      schedulePreview();
      break;
    case "error":
      showError(msg.message);
      break;
    default:
      break;
  }
}

function connect() {
  const url = new URL("ws", location.href);
  url.protocol = location.protocol === "https:" ? "wss:" : "ws:";
  ws = new WebSocket(url.href);
  ws.onmessage = (ev) => {
    let msg;
    try { msg = JSON.parse(ev.data); } catch { return; }
    if (msg && typeof msg === "object") onMessage(msg);
  };
  ws.onclose = () => setStatus("disconnected from the server: reload the page to reconnect");
}

// ------------------------------------------------------------------ messages on the page
function showError(text) {
  const el = $("error");
  el.textContent = String(text);
  el.hidden = false;
}

function clearError() {
  $("error").textContent = "";
  $("error").hidden = true;
}

function setStatus(text) { $("status").textContent = text; }

// ------------------------------------------------------------------ forms
function fillProfiles(kinds) {
  const sel = $("f-profile");
  sel.replaceChildren(...kinds.map((k) => Object.assign(document.createElement("option"), { value: k, textContent: k })));
}

const fmt = (v) => (v === null || v === undefined ? "" : String(v));

function fillZoneForm() {
  const z = state.zones[state.selected];
  $("zone-form").disabled = !z;
  $("sel-label").textContent = z ? `#${state.selected}` : "(none: draw one on the map)";
  const values = z ? {
    name: z.name, cx: z.centre[0], cy: z.centre[1], radius: z.radius, n_sensors: z.n_sensors, profile: z.profile,
    alpha: z.alpha, sigma: z.sigma, floor: z.floor, weight: z.weight, altitude: z.altitude,
  } : {};
  for (const f of ZONE_FIELDS) $(`f-${f}`).value = fmt(values[f]);
  showProfileParams();
}

function showProfileParams() {
  const kind = $("f-profile").value;
  document.querySelector("label.p-power").classList.toggle("off", kind !== "power");
  document.querySelector("label.p-gauss").classList.toggle("off", kind !== "gauss");
}

function fillMapForm() {
  $("f-map-w").value = fmt(state.mapSize[0]);
  $("f-map-h").value = fmt(state.mapSize[1]);
  $("f-base-x").value = state.base ? fmt(state.base[0]) : "";
  $("f-base-y").value = state.base ? fmt(state.base[1]) : "";
}

// A form value as JSON: a number when it reads as one, else the raw text (so the validator names it);
// an empty optional field is null.
function readNumber(id, optional = false) {
  const raw = $(id).value.trim();
  if (raw === "") return optional ? null : raw;
  const v = Number(raw);
  return Number.isFinite(v) ? v : raw;
}

function onZoneEdit() {
  const z = state.zones[state.selected];
  if (!z) return;
  const name = $("f-name").value;
  z.name = name.trim() === "" ? null : name;
  z.centre = [readNumber("f-cx"), readNumber("f-cy")];
  z.radius = readNumber("f-radius");
  z.n_sensors = readNumber("f-n_sensors");
  z.profile = $("f-profile").value;
  z.alpha = readNumber("f-alpha");
  z.sigma = readNumber("f-sigma", true);
  z.floor = readNumber("f-floor");
  z.weight = readNumber("f-weight");
  z.altitude = readNumber("f-altitude", true);
  showProfileParams();
  render();
  schedulePreview();
}

function onMapEdit() {
  state.mapSize = [readNumber("f-map-w"), readNumber("f-map-h")];
  const bx = readNumber("f-base-x", true);
  const by = readNumber("f-base-y", true);
  state.base = bx === null && by === null ? null : [bx, by];
  render();
  schedulePreview();
}

// ------------------------------------------------------------------ zone list
function zoneLabel(z, i) { return z.name ?? `zone ${i}`; }
const num = (v) => (typeof v === "number" ? +v.toFixed(1) : JSON.stringify(v));

function renderList() {
  const list = $("zone-list");
  list.replaceChildren(...state.zones.map((z, i) => {
    const row = document.createElement("div");
    row.dataset.index = String(i);
    row.className = i === state.selected ? "selected" : "";
    row.style.borderLeftColor = PALETTE[i % PALETTE.length];
    const text = document.createElement("span");
    text.className = "z-text";
    text.textContent = `${zoneLabel(z, i)} · (${num(z.centre[0])}, ${num(z.centre[1])}) · r ${num(z.radius)} m · ` +
      `${num(z.n_sensors)} sensors`;
    const del = Object.assign(document.createElement("button"), { type: "button", textContent: "Delete" });
    del.className = "delete";
    del.title = `Delete ${zoneLabel(z, i)}`;
    del.addEventListener("click", (ev) => { ev.stopPropagation(); deleteZone(i); });
    row.addEventListener("click", () => select(i));
    row.append(text, del);
    return row;
  }));
  const total = state.zones.reduce((s, z) => s + (typeof z.n_sensors === "number" ? z.n_sensors : 0), 0);
  $("totals").textContent = `(${state.zones.length}, ${total} sensors)`;
  const pairs = state.preview ? state.preview.overlaps : [];
  $("overlaps").textContent = pairs.length ? "overlapping: " + pairs.map(([a, b]) =>
    `${zoneLabel(state.zones[a], a)} & ${zoneLabel(state.zones[b], b)}`).join(", ") : "";
  // the server's line (the one `agentsim zones check` prints), refreshed with every preview
  const fleet = state.preview ? state.preview.fleet : null;
  $("capacity").textContent = fleet ? fleet.text : "";
  $("capacity").classList.toggle("short", !!fleet && !fleet.carried);
}

function select(i) {
  state.selected = i;
  fillZoneForm();
  render();
}

function deleteZone(i) {
  state.zones.splice(i, 1);
  state.preview = null;
  if (state.selected >= state.zones.length) state.selected = state.zones.length - 1;
  else if (state.selected > i) state.selected -= 1;
  fillZoneForm();
  render();
  schedulePreview();
}

// ------------------------------------------------------------------ map geometry and drawing
const canvas = () => $("map");

function geometry() {
  const c = canvas();
  const w = c.clientWidth, h = c.clientHeight;
  const [mw, mh] = state.mapSize.map((v) => (typeof v === "number" && v > 0 ? v : 1));
  const s = Math.max(1e-9, Math.min((w - MARGIN.left - MARGIN.right) / mw, (h - MARGIN.top - MARGIN.bottom) / mh));
  return { s, mw, mh, ox: MARGIN.left, oy: MARGIN.top + mh * s };
}

const toCanvas = (g, [x, y]) => [g.ox + x * g.s, g.oy - y * g.s];
const fromCanvas = (g, [px, py]) => [(px - g.ox) / g.s, (g.oy - py) / g.s];

function niceStep(span) {
  const raw = span / 6, p = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map((m) => m * p).find((v) => v >= raw);
}

function hexAlpha(hex, a) {
  const n = parseInt(hex.slice(1), 16);
  return `rgba(${n >> 16}, ${(n >> 8) & 255}, ${n & 255}, ${a.toFixed(3)})`;
}

function render() {
  renderList();
  const c = canvas(), dpr = window.devicePixelRatio || 1;
  const w = c.clientWidth, h = c.clientHeight;
  if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
    c.width = Math.round(w * dpr);
    c.height = Math.round(h * dpr);
  }
  const ctx = c.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  const g = geometry();
  drawAxes(ctx, g);
  ctx.save();
  ctx.beginPath();
  ctx.rect(g.ox, g.oy - g.mh * g.s, g.mw * g.s, g.mh * g.s);
  ctx.clip();
  const pv = state.preview && state.preview.zones.length === state.zones.length ? state.preview : null;
  state.zones.forEach((z, i) => drawZone(ctx, g, z, i, pv ? pv.zones[i] : null));
  drawBase(ctx, g);
  if (state.drag) drawDrag(ctx, g);
  ctx.restore();
}

function drawAxes(ctx, g) {
  ctx.fillStyle = "#fbfcfd";
  ctx.fillRect(g.ox, g.oy - g.mh * g.s, g.mw * g.s, g.mh * g.s);
  ctx.strokeStyle = "#9aa6b5";
  ctx.lineWidth = 1;
  ctx.strokeRect(g.ox, g.oy - g.mh * g.s, g.mw * g.s, g.mh * g.s);
  ctx.fillStyle = "#4a5568";
  ctx.font = "11px system-ui, sans-serif";
  const step = niceStep(Math.max(g.mw, g.mh));
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (let x = 0; x <= g.mw + 1e-9; x += step) {
    const [px, py] = toCanvas(g, [x, 0]);
    ctx.fillRect(px, py, 1, 4);
    ctx.fillText(String(+x.toPrecision(6)), px, py + 6);
  }
  ctx.fillText("x (m)", g.ox + (g.mw * g.s) / 2, g.oy + 22);
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (let y = 0; y <= g.mh + 1e-9; y += step) {
    const [px, py] = toCanvas(g, [0, y]);
    ctx.fillRect(px - 4, py, 4, 1);
    ctx.fillText(String(+y.toPrecision(6)), px - 6, py);
  }
  ctx.save();
  ctx.translate(12, g.oy - (g.mh * g.s) / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = "center";
  ctx.fillText("y (m)", 0, 0);
  ctx.restore();
}

function validZone(z) {
  return [z.centre[0], z.centre[1], z.radius].every((v) => typeof v === "number" && Number.isFinite(v)) && z.radius > 0;
}

function drawZone(ctx, g, z, i, pv) {
  if (!validZone(z)) return;
  const colour = PALETTE[i % PALETTE.length];
  const [cx, cy] = toCanvas(g, z.centre), r = z.radius * g.s;
  ctx.beginPath();
  ctx.arc(cx, cy, r, 0, 2 * Math.PI);
  if (pv && $("show-density").checked) {
    const grad = ctx.createRadialGradient(cx, cy, 0, cx, cy, r);
    const n = pv.density.length;
    // sqrt: a steep profile (a power law) still shows its shape, not only a bright centre
    pv.density.forEach((d, k) => grad.addColorStop(k / (n - 1), hexAlpha(colour, 0.06 + 0.5 * Math.sqrt(d))));
    ctx.fillStyle = grad;
  } else {
    ctx.fillStyle = hexAlpha(colour, 0.08);
  }
  ctx.fill();
  ctx.lineWidth = i === state.selected ? 2.5 : 1.2;
  ctx.strokeStyle = colour;
  ctx.setLineDash(i === state.selected ? [] : [5, 3]);
  ctx.stroke();
  ctx.setLineDash([]);
  if (pv && $("show-b1").checked) {
    ctx.fillStyle = "rgba(20, 24, 32, 0.75)";
    for (const p of pv.b1) {
      const [px, py] = toCanvas(g, p);
      ctx.fillRect(px - 1, py - 1, 2, 2);
    }
  }
  if (pv && $("show-b8").checked) {
    ctx.strokeStyle = hexAlpha(colour, 0.95);
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (const p of pv.b8) {
      const [px, py] = toCanvas(g, p);
      ctx.moveTo(px - 2.5, py - 2.5); ctx.lineTo(px + 2.5, py + 2.5);
      ctx.moveTo(px - 2.5, py + 2.5); ctx.lineTo(px + 2.5, py - 2.5);
    }
    ctx.stroke();
  }
  ctx.fillStyle = "#1d2430";
  ctx.font = i === state.selected ? "bold 12px system-ui, sans-serif" : "12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "bottom";
  const shown = pv && pv.shown < pv.n_sensors ? ` (${pv.shown} of ${pv.n_sensors} shown)` : "";
  ctx.fillText(`${zoneLabel(z, i)}${shown}`, cx, cy - r - 3);
}

function drawBase(ctx, g) {
  const b = state.base;
  if (!b || !b.every((v) => typeof v === "number" && Number.isFinite(v))) return;
  const [px, py] = toCanvas(g, b);
  ctx.beginPath();
  ctx.moveTo(px, py - 8); ctx.lineTo(px + 7, py + 5); ctx.lineTo(px - 7, py + 5); ctx.closePath();
  ctx.fillStyle = "#111"; ctx.fill();
  ctx.fillStyle = "#1d2430"; ctx.font = "11px system-ui, sans-serif"; ctx.textAlign = "left";
  ctx.textBaseline = "middle";
  ctx.fillText("base", px + 9, py);
}

function drawDrag(ctx, g) {
  const d = state.drag;
  const [cx, cy] = toCanvas(g, d.centre);
  ctx.beginPath();
  ctx.arc(cx, cy, d.radius * g.s, 0, 2 * Math.PI);
  ctx.fillStyle = "rgba(31, 119, 180, 0.12)"; ctx.fill();
  ctx.strokeStyle = "#1f77b4"; ctx.lineWidth = 2; ctx.setLineDash([6, 4]); ctx.stroke(); ctx.setLineDash([]);
  ctx.fillStyle = "#1d2430"; ctx.font = "12px system-ui, sans-serif"; ctx.textAlign = "left";
  ctx.fillText(`r ${d.radius.toFixed(1)} m`, cx + 6, cy - 6);
}

// ------------------------------------------------------------------ drawing zones with the mouse
function mapPoint(ev) {
  const rect = canvas().getBoundingClientRect();
  return fromCanvas(geometry(), [ev.clientX - rect.left, ev.clientY - rect.top]);
}

const round1 = (v) => Math.round(v * 10) / 10;

function onPointerDown(ev) {
  if (ev.button !== 0) return;
  const g = geometry(), p = mapPoint(ev);
  if (p[0] < 0 || p[1] < 0 || p[0] > g.mw || p[1] > g.mh) return;
  state.drag = { centre: p.map(round1), radius: 0, start: [ev.clientX, ev.clientY] };
  canvas().setPointerCapture(ev.pointerId);
  render();
}

function onPointerMove(ev) {
  const d = state.drag;
  if (!d) return;
  const g = geometry(), p = mapPoint(ev);
  const edge = Math.min(d.centre[0], d.centre[1], g.mw - d.centre[0], g.mh - d.centre[1]);
  d.radius = Math.min(round1(Math.hypot(p[0] - d.centre[0], p[1] - d.centre[1])), Math.floor(edge * 10) / 10);
  render();
}

function onPointerUp(ev) {
  const d = state.drag;
  if (!d) return;
  onPointerMove(ev);
  state.drag = null;
  const moved = Math.hypot(ev.clientX - d.start[0], ev.clientY - d.start[1]);
  if (moved < 4 || d.radius < 0.5) {   // a click: select the zone under the pointer
    const hit = zoneAt(d.centre);
    if (hit >= 0) select(hit); else render();
    return;
  }
  const used = new Set(state.zones.map((z) => z.name));
  let k = state.zones.length;
  while (used.has(`zone_${k}`)) k += 1;
  const df = state.defaults;
  state.zones.push(fullZone({ name: `zone_${k}`, centre: d.centre, radius: d.radius, n_sensors: df.n_sensors,
    profile: df.profile, floor: df.floor, weight: df.weight }));
  state.selected = state.zones.length - 1;
  fillZoneForm();
  render();
  schedulePreview();
}

function zoneAt(p) {
  let best = -1, bestRel = 1;
  state.zones.forEach((z, i) => {
    if (!validZone(z)) return;
    const rel = Math.hypot(p[0] - z.centre[0], p[1] - z.centre[1]) / z.radius;
    if (rel <= bestRel) { best = i; bestRel = rel; }
  });
  return best;
}

// ------------------------------------------------------------------ buttons and start-up
function download(ev) {
  const blob = new Blob([JSON.stringify(zoneFile(), null, 2) + "\n"], { type: "application/json" });
  if (downloadUrl) URL.revokeObjectURL(downloadUrl);
  downloadUrl = URL.createObjectURL(blob);
  ev.currentTarget.href = downloadUrl;
}

function init() {
  for (const f of ZONE_FIELDS) $(`f-${f}`).addEventListener("input", onZoneEdit);
  $("f-profile").addEventListener("change", onZoneEdit);
  for (const id of ["f-map-w", "f-map-h", "f-base-x", "f-base-y"]) $(id).addEventListener("input", onMapEdit);
  for (const id of ["show-density", "show-b1", "show-b8"]) $(id).addEventListener("change", render);
  $("save").addEventListener("click", () => send({ cmd: "zones.save", zones: zoneFile() }));
  $("load").addEventListener("click", () => send({ cmd: "zones.load" }));
  $("download").addEventListener("click", download);
  const c = canvas();
  c.addEventListener("pointerdown", onPointerDown);
  c.addEventListener("pointermove", onPointerMove);
  c.addEventListener("pointerup", onPointerUp);
  c.addEventListener("pointercancel", () => { state.drag = null; render(); });
  new ResizeObserver(render).observe(c);
  connect();
}

window.designer = {
  ready: false,
  lastPreview: null,
  zones: () => zoneFile(),
  idle: () => previewTimer === null && previewAnswered === previewSent,
  toPixel: (p) => {
    const rect = canvas().getBoundingClientRect();
    const [px, py] = toCanvas(geometry(), p);
    return [rect.left + px, rect.top + py];
  },
};

init();
