// The three.js side of the viewer: builds the scene from a `scene` message and writes each frame's typed
// arrays straight into preallocated instance / line buffers (no per-agent objects, no per-frame allocation).
import * as THREE from 'three';
import { OrbitControls } from '/static/vendor/OrbitControls.js';
import {
  Markers, Trails, pixelSize, MSG_COLOURS, addMessages, buildZone, fadeMessages, layoutDrops, makeLines, setRays,
} from '/static/overlays3d.js';
import { fitTop, followSelected, frameAgents, frameCamera } from '/static/camera3d.js';

export { MSG_COLOURS };

// Colours (sRGB hex). Groups cycle through GROUP_COLOURS; group -1 is NO_GROUP; offline agents are OFFLINE.
export const GROUP_COLOURS = [0xff7f0e, 0x2ca02c, 0xd62728, 0x9467bd, 0x8c564b, 0xe377c2, 0xbcbd22, 0x17becf,
  0xf1c40f, 0x1abc9c];
export const NO_GROUP = 0x3f6fb5;
export const OFFLINE = 0x9a9a9a;
// Why an agent no longer acts (the frame's `status`: 1 arrived, 2 collided, 3 offline, 4 ended); arrived agents
// keep a pale form of their own colour, so they still read as "that agent, done".
export const COLLIDED = 0x1c1c1c;
export const ENDED = 0xc9c9c9;
export const STATUS_LABELS = ['active', 'arrived', 'collided', 'offline (missed heartbeats)', 'ended'];
const MIN_AGENT_PX = 10; // an agent's radius on screen never drops below this (CSS pixels); true size when larger
export const MSG_KINDS = ['agent', 'group', 'environment', 'overlay'];
export const PAYLOAD_FALLING = 0xff8c00;
export const PAYLOAD_LANDED = 0x2b2b2b;
const OBJECT_COLOUR = 0x9ea3aa;
const MAX_SEGMENTS = 2000; // message lines kept in the ring buffer

/** Linear-space [r, g, b] of an sRGB hex colour (instance and vertex colours are read as linear). */
function rgb(hex) {
  const c = new THREE.Color(hex);
  return [c.r, c.g, c.b];
}
const PALETTE = GROUP_COLOURS.map(rgb);
const NO_GROUP_RGB = rgb(NO_GROUP);
const OFFLINE_RGB = rgb(OFFLINE);
const COLLIDED_RGB = rgb(COLLIDED);
const ENDED_RGB = rgb(ENDED);
const pale = (c) => c.map((v) => v + (1 - v) * 0.6);
const PALE = PALETTE.map(pale);
const FALLING_RGB = rgb(PAYLOAD_FALLING);
const LANDED_RGB = rgb(PAYLOAD_LANDED);

/** An InstancedMesh with a dynamic per-instance colour buffer; never frustum-culled (instances move). */
function makeInstanced(geometry, material, capacity) {
  const mesh = new THREE.InstancedMesh(geometry, material, Math.max(1, capacity));
  mesh.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
  mesh.instanceColor = new THREE.InstancedBufferAttribute(new Float32Array(Math.max(1, capacity) * 3), 3)
    .setUsage(THREE.DynamicDrawUsage);
  mesh.frustumCulled = false;
  mesh.count = 0;
  return mesh;
}

/** Write a yaw rotation + uniform scale + translation into a column-major 4x4 at m[o..o+15]. */
function writeMatrix(m, o, x, y, z, yaw, s) {
  const c = Math.cos(yaw) * s;
  const n = Math.sin(yaw) * s;
  m[o] = c; m[o + 1] = n; m[o + 2] = 0; m[o + 3] = 0;
  m[o + 4] = -n; m[o + 5] = c; m[o + 6] = 0; m[o + 7] = 0;
  m[o + 8] = 0; m[o + 9] = 0; m[o + 10] = s; m[o + 11] = 0;
  m[o + 12] = x; m[o + 13] = y; m[o + 14] = z; m[o + 15] = 1;
}

/** A "nice" grid spacing (1, 2 or 5 x 10^k) giving roughly `lines` lines over `extent`. */
function niceStep(extent, lines) {
  const raw = extent / lines;
  const p = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map((k) => k * p).find((s) => s >= raw);
}

/** True when WebGL runs on the CPU (SwiftShader, llvmpipe): draw with fewer triangles and no antialiasing. */
function softwareRenderer() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
    const name = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : '';
    gl?.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|software/i.test(String(name));
  } catch (e) {
    return false;
  }
}
const SOFTWARE = softwareRenderer();
const MANY = 2000; // above this many agents (or objects), bodies are drawn with fewer faces

export class Scene3D {
  /** canvas: the WebGL canvas; top: a fixed straight-down orthographic view instead of the orbit camera. */
  constructor(canvas, { top = false } = {}) {
    this.canvas = canvas;
    this.top = top;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: !SOFTWARE });
    this.renderer.setPixelRatio(SOFTWARE ? 1 : Math.min(window.devicePixelRatio || 1, 2));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf3f4f6);
    const hemi = new THREE.HemisphereLight(0xffffff, 0x8a8f80, 1.6);
    hemi.position.set(0, 0, 1); // z is up
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(0.4, -0.7, 1);
    this.scene.add(hemi, sun);
    if (top) {
      this.camera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0.1, 1000);
      this.camera.up.set(0, 1, 0); // looking straight down: north is up in the image
    } else {
      this.camera = new THREE.PerspectiveCamera(45, 1, 0.1, 1000);
      this.camera.up.set(0, 0, 1);
      this.controls = new OrbitControls(this.camera, canvas);
      this.controls.addEventListener('change', () => { this.dirty = true; });
      this.controls.addEventListener('start', () => { this.userMoved = true; }); // keep the user's view from now
    }
    this.world = null; // everything rebuilt per scene
    this.bounds = [-1, 1, -1, 1];
    this.radius = new Float32Array(0);
    this.frame = null; // the frame currently shown
    this.selected = null;
    this.follow = false; // keep the selected agent in the middle of the view
    this.showTrails = true;
    this.dirty = true;
    this.raycaster = new THREE.Raycaster();
    this.tmp = new THREE.Vector3();
    this.ndc = new THREE.Vector2();
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
  }

  // ----- scene ------------------------------------------------------------------------------------------------
  /** (Re)build the whole scene from a `scene` message. */
  build(msg) {
    if (this.world) {
      this.scene.remove(this.world);
      this.world.traverse((o) => { o.geometry?.dispose(); o.material?.dispose(); });
    }
    const world = new THREE.Group();
    this.world = world;
    this.scene.add(world);
    const [x0, x1, y0, y1] = msg.bounds;
    this.bounds = msg.bounds;
    const bw = x1 - x0;
    const bh = y1 - y0;
    const size = Math.max(bw, bh);
    this.size = size;
    const lift = size * 0.0015; // small z offsets that keep flat layers apart without z-fighting

    // Ground, a light grid and the bounds outline.
    const ground = new THREE.Mesh(new THREE.PlaneGeometry(bw, bh),
      new THREE.MeshLambertMaterial({ color: 0xe3e7dc }));
    ground.position.set((x0 + x1) / 2, (y0 + y1) / 2, 0);
    world.add(ground);
    const step = niceStep(size, 12);
    const grid = [];
    for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) grid.push(x, y0, lift, x, y1, lift);
    for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) grid.push(x0, y, lift, x1, y, lift);
    const gridGeometry = new THREE.BufferGeometry();
    gridGeometry.setAttribute('position', new THREE.Float32BufferAttribute(grid, 3));
    world.add(new THREE.LineSegments(gridGeometry, new THREE.LineBasicMaterial({ color: 0xc9cfc0 })));
    const outline = new THREE.BufferGeometry();
    outline.setAttribute('position', new THREE.Float32BufferAttribute(
      [x0, y0, 3 * lift, x1, y0, 3 * lift, x1, y1, 3 * lift, x0, y1, 3 * lift], 3));
    world.add(new THREE.LineLoop(outline, new THREE.LineBasicMaterial({ color: 0x303030 })));

    this.buildObjects(msg.objects || { kind: [], centre: [], half: [] });
    for (const zone of msg.zones || []) this.buildZone(zone, 2 * lift);
    this.markers = new Markers(world, msg.markers, 4 * lift);
    this.trails = new Trails(world);
    this.drops = null;
    this.trails.lines.visible = this.showTrails;
    // per agent colour when there are no groups (each agent and its goal share one colour)
    this.byAgent = (msg.n_groups || 1) <= 1;

    // Agents: one InstancedMesh of a cone pointing along +x (heading 0), scaled by the agent radius.
    const n = msg.n_agents || 0;
    // The agent's true radius; drawing keeps MIN_AGENT_PX on screen (layoutAgents).
    this.radius = new Float32Array(n).fill(0.5);
    (msg.agent_radius || []).forEach((r, i) => { if (i < n) this.radius[i] = Math.max(r, 0.05); });
    this.meanRadius = n ? this.radius.reduce((a, b) => a + b, 0) / n : 0.5;
    this.buildAgents(n);

    // Selection marker, drawn over everything: a flat ring around the agent and a pin standing above it
    // (in agent-radius units: the marker is scaled by the selected agent's display radius).
    this.marker = new THREE.Mesh(new THREE.RingGeometry(2.0, 2.8, 32),
      new THREE.MeshBasicMaterial({ color: 0xffc400, depthTest: false, side: THREE.DoubleSide }));
    const pin = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(0, 0, 0),
      new THREE.Vector3(0, 0, 12)]), new THREE.LineBasicMaterial({ color: 0x111111, depthTest: false }));
    pin.renderOrder = 10;
    this.marker.add(pin);
    this.marker.renderOrder = 10;
    this.marker.visible = false;
    world.add(this.marker);

    // Payloads (small spheres), messages (fading ring buffer of segments) and the selected agent's rays.
    this.payloads = makeInstanced(new THREE.SphereGeometry(1, 8, 6), new THREE.MeshLambertMaterial(), 64);
    world.add(this.payloads);
    this.messages = makeLines(MAX_SEGMENTS);
    this.msgBorn = new Float64Array(MAX_SEGMENTS);
    this.msgHead = 0; // next slot to write
    this.msgCount = 0; // slots in use (<= MAX_SEGMENTS)
    this.msgLastBorn = -Infinity;
    world.add(this.messages);
    this.rays = makeLines(64);
    world.add(this.rays);

    // Frame the camera on the first scene and when the bounds change, not at every episode (keeps the user's view).
    const key = JSON.stringify(msg.bounds);
    if (this.top || key !== this.framedBounds) {
      this.frameCamera();
      this.frameOnFrame = !this.top; // then on the first frame: frame the agents' extent
      this.userMoved = false;
    }
    this.framedBounds = key;
    this.sceneMsg = msg;
    this.frame = null;
    this.dirty = true;
  }

  buildObjects(objects) {
    const few = objects.kind.length > MANY / 4; // many objects: rounder shapes cost more than they show
    const geometries = [
      new THREE.BoxGeometry(2, 2, 2), // scaled by the half extents
      new THREE.CylinderGeometry(1, 1, 2, few ? 8 : 20).rotateX(Math.PI / 2), // axis along z
      new THREE.SphereGeometry(1, few ? 10 : 20, few ? 7 : 14),
    ];
    const material = new THREE.MeshLambertMaterial({ color: OBJECT_COLOUR });
    const m = new THREE.Matrix4();
    const q = new THREE.Quaternion();
    const p = new THREE.Vector3();
    const s = new THREE.Vector3();
    for (let kind = 0; kind < 3; kind++) {
      const idx = objects.kind.map((k, i) => (k === kind ? i : -1)).filter((i) => i >= 0);
      if (!idx.length) continue;
      const mesh = new THREE.InstancedMesh(geometries[kind], material, idx.length);
      idx.forEach((i, j) => {
        const [cx, cy, cz] = objects.centre[i];
        const [hx, hy, hz] = objects.half[i];
        if (kind === 0) s.set(hx, hy, hz);
        else if (kind === 1) s.set(hx, hx, hz);
        else s.set(hx, hx, hx);
        mesh.setMatrixAt(j, m.compose(p.set(cx, cy, cz), q, s));
      });
      this.world.add(mesh);
    }
  }

  /** A flat disc shaded radially by the zone's density samples (r = 0 .. radius), warm = dense. */
  buildZone(zone, z) {
    buildZone(this, zone, z);
  }

  buildAgents(capacity) {
    if (this.agents) {
      this.world.remove(this.agents, this.ghosts);
      this.agents.geometry.dispose();
      this.agents.material.dispose();
      this.ghosts.material.dispose();
    }
    const faces = capacity > MANY ? 4 : 8; // a 4-sided cone still shows the heading
    const cone = new THREE.ConeGeometry(1, 2.4, faces).rotateZ(-Math.PI / 2); // tip along +x
    this.agents = makeInstanced(cone, new THREE.MeshLambertMaterial({ flatShading: true }), capacity);
    // The same instances drawn faintly through whatever hides them (an agent behind an obstacle stays seen).
    this.ghosts = new THREE.InstancedMesh(cone, new THREE.MeshBasicMaterial({
      transparent: true, opacity: 0.35, depthTest: false, depthWrite: false }), Math.max(1, capacity));
    this.ghosts.instanceMatrix = this.agents.instanceMatrix;
    this.ghosts.instanceColor = this.agents.instanceColor;
    this.ghosts.frustumCulled = false;
    this.ghosts.renderOrder = 5;
    this.ghosts.count = 0;
    this.world.add(this.agents, this.ghosts);
  }

  /** Initial camera: a 3/4 perspective view of the bounds, or (top) the whole bounds straight down. */
  frameCamera() {
    frameCamera(this);
  }

  /** Orthographic frustum holding the bounds (5% margin), centred, at the canvas aspect ratio. */
  fitTop() {
    fitTop(this);
  }

  aspect() {
    return Math.max(this.canvas.clientWidth, 1) / Math.max(this.canvas.clientHeight, 1);
  }

  resize() {
    const w = this.canvas.clientWidth;
    const h = this.canvas.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    if (this.top) this.fitTop();
    else {
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
      if (!this.userMoved && this.frame && !this.follow) this.frameAgents(); // the page's layout settled later
    }
    this.dirty = true;
  }

  // ----- frames -----------------------------------------------------------------------------------------------
  /** Show one parsed frame: agents, payloads, new message segments, rays. */
  setFrame(frame) {
    if (!this.world) return;
    const a = frame.arrays;
    const pos = a.pos || new Float32Array(0);
    const n = pos.length / 3;
    if (n > this.agents.instanceMatrix.count) this.buildAgents(n); // grows only
    this.frame = frame;
    const col = this.agents.instanceColor.array;
    this.active = this.active?.length === n ? this.active : new Uint8Array(n);
    for (let i = 0; i < n; i++) {
      const c = this.colourOf(i, true);
      col[3 * i] = c[0]; col[3 * i + 1] = c[1]; col[3 * i + 2] = c[2];
      this.active[i] = this.statusOf(i) === 0 ? 1 : 0;
    }
    this.agents.count = n;
    this.ghosts.count = n;
    this.agents.instanceColor.needsUpdate = true;
    this.markers.recolour((slot) => (slot < n ? this.colourOf(slot, false) : null));
    if (this.showTrails) this.trails.add(pos, frame.step, (i) => this.colourOf(i, false), this.active);
    if (this.frameOnFrame) {
      this.frameOnFrame = false;
      this.frameAgents();
    }

    this.setPayloads(a.payload_pos, a.payload_state);
    if (a.msg) this.addMessages(a.msg, a.msg_kind, pos, n);
    this.setRays(a.rays, a.ray_hit, pos, n);
    this.updateMarker();
    this.dirty = true;
  }

  /** Why agent i is drawn as it is (0 active .. 4 ended; frames without `status`: offline when not online). */
  statusOf(i) {
    const a = this.frame?.arrays || {};
    if (a.status) return a.status[i];
    return a.online && a.online[i] === 0 ? 3 : 0;
  }

  /** Agent i's linear RGB: its group's colour (or its own without groups); `withStatus`: as its status shows. */
  colourOf(i, withStatus) {
    const a = this.frame?.arrays || {};
    const g = a.group ? a.group[i] : -1;
    const k = this.byAgent ? i : g; // one group (or none): each agent its own colour
    const own = k < 0 ? NO_GROUP_RGB : PALETTE[k % PALETTE.length];
    if (!withStatus) return own;
    const s = this.statusOf(i);
    if (s === 0) return own;
    if (s === 1) return k < 0 ? pale(NO_GROUP_RGB) : PALE[k % PALE.length];
    return s === 2 ? COLLIDED_RGB : s === 3 ? OFFLINE_RGB : ENDED_RGB;
  }

  /** Agent matrices for the current camera: true radius, or MIN_AGENT_PX on screen when that is larger. */
  layoutAgents() {
    const f = this.frame;
    if (!f || !this.agents) return;
    const pos = f.arrays.pos;
    const heading = f.arrays.heading;
    const n = pos.length / 3;
    const m = this.agents.instanceMatrix.array;
    this.camera.updateMatrixWorld();
    this.shown = this.shown?.length === n ? this.shown : new Float32Array(n);
    for (let i = 0; i < n; i++) {
      const p = [pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]];
      const r = Math.max(i < this.radius.length ? this.radius[i] : this.meanRadius,
        MIN_AGENT_PX * pixelSize(this.camera, this.canvas, p, this.tmp));
      this.shown[i] = r;
      writeMatrix(m, i * 16, p[0], p[1], p[2], heading ? heading[i] : 0, r);
    }
    this.agents.instanceMatrix.needsUpdate = true;
    this.agents.boundingSphere = null; // recomputed lazily for picking
    this.layoutDrops(pos, n);
    this.markers.layout(this.camera, this.canvas, pos, true);
    this.updateMarker();
  }

  /** A thin line from each agent down to the ground and a dot there: its altitude and ground track read. */
  layoutDrops(pos, n) {
    layoutDrops(this, pos, n);
  }

  /** Frame the agents' extent (and the markers'): the 3/4 view backed off until they fill ~80% of it. */
  frameAgents() {
    frameAgents(this);
  }

  /** Keep the selected agent in the middle: move the orbit target and the camera by the agent's motion. */
  followSelected() {
    followSelected(this);
  }

  setTrails(on) {
    this.showTrails = on;
    if (this.trails) {
      this.trails.lines.visible = on;
      if (!on) this.trails.clear();
    }
    this.dirty = true;
  }

  /** Screen positions of the markers' centres (a test hook). */
  markerScreen() {
    return this.markers ? this.markers.screen((p) => this.project(p)) : [];
  }

  setPayloads(ppos, pstate) {
    const p = ppos ? ppos.length / 3 : 0;
    if (p > this.payloads.instanceMatrix.count) { // grow (doubling) and replace the mesh
      this.world.remove(this.payloads);
      this.payloads.dispose();
      const bigger = makeInstanced(this.payloads.geometry, this.payloads.material,
        Math.max(p, 2 * this.payloads.instanceMatrix.count));
      this.payloads = bigger;
      this.world.add(bigger);
    }
    // payloads keep 3 px on screen (landed sensors would vanish on a big map)
    const s = Math.max(this.meanRadius * 0.45, 3 * pixelSize(this.camera, this.canvas,
      [this.controls?.target.x ?? 0, this.controls?.target.y ?? 0, 0], this.tmp));
    const m = this.payloads.instanceMatrix.array;
    const col = this.payloads.instanceColor.array;
    for (let i = 0; i < p; i++) {
      writeMatrix(m, i * 16, ppos[3 * i], ppos[3 * i + 1], ppos[3 * i + 2], 0, s);
      const c = pstate && pstate[i] === 2 ? LANDED_RGB : FALLING_RGB;
      col[3 * i] = c[0]; col[3 * i + 1] = c[1]; col[3 * i + 2] = c[2];
    }
    this.payloads.count = p;
    this.payloads.instanceMatrix.needsUpdate = true;
    this.payloads.instanceColor.needsUpdate = true;
  }

  /** Append this frame's deliveries to the ring buffer of segments (receiver or sender -1: a vertical tick). */
  addMessages(msg, kinds, pos, n) {
    addMessages(this, msg, kinds, pos, n);
  }

  /** Update the message alphas; returns true while some segment is still visible. */
  fadeMessages(now) {
    return fadeMessages(this, now);
  }

  /** The selected agent's proximity rays: red for hits, faint for misses. */
  setRays(rays, hits, pos, n) {
    setRays(this, rays, hits, pos, n);
  }

  setSelected(slot) {
    this.selected = slot;
    if (slot === null && this.rays) this.rays.geometry.setDrawRange(0, 0);
    this.updateMarker();
    this.dirty = true;
  }

  updateMarker() {
    if (!this.marker) return;
    const f = this.frame;
    const s = this.selected;
    const n = f && f.arrays.pos ? f.arrays.pos.length / 3 : 0;
    this.marker.visible = s !== null && s < n;
    if (!this.marker.visible) return;
    const p = f.arrays.pos;
    this.marker.position.set(p[3 * s], p[3 * s + 1], p[3 * s + 2]);
    this.marker.scale.setScalar(this.shown && s < this.shown.length ? this.shown[s] : this.meanRadius);
  }

  // ----- drawing, picking, projection -------------------------------------------------------------------------
  /** Render when something changed (or messages are fading); returns whether it rendered. */
  render(now) {
    const fading = this.fadeMessages(now);
    if (!this.dirty && !fading) return false;
    this.followSelected();
    this.dirty = false;
    this.layoutAgents(); // the camera may have moved: keep the minimum on-screen size
    this.renderer.render(this.scene, this.camera);
    return true;
  }

  /** The agent slot under a page point, or null: a ray cast on the instances, else the nearest within 10 px. */
  pick(clientX, clientY) {
    if (!this.agents || !this.agents.count) return null;
    const rect = this.canvas.getBoundingClientRect();
    this.ndc.set(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(this.ndc, this.camera);
    const hit = this.raycaster.intersectObject(this.agents, false)[0];
    if (hit && hit.instanceId !== undefined) return hit.instanceId;
    const pos = this.frame.arrays.pos;
    let best = null;
    let bestD = 100; // (10 px)^2
    for (let i = 0; i < this.agents.count; i++) {
      const [px, py] = this.project([pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]], rect);
      const d = (px - clientX) ** 2 + (py - clientY) ** 2;
      if (d < bestD) { bestD = d; best = i; }
    }
    return best;
  }

  /** CSS pixel position in the page of a world point with the current camera. */
  project(p, rect = this.canvas.getBoundingClientRect()) {
    this.camera.updateMatrixWorld();
    const v = this.tmp.set(p[0], p[1], p[2]).project(this.camera);
    return [rect.left + ((v.x + 1) / 2) * rect.width, rect.top + ((1 - v.y) / 2) * rect.height];
  }
}
