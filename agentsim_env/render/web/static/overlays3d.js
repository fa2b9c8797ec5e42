// What the 3D view draws besides bodies: the scenario's markers (goals, targets, generic discs; zones are drawn by
// scene3d.js), the agents' trails, and the links from a marker to the agent it belongs to (a relay target to its
// scout, a goal to its agent). Markers and agents keep a minimum size on screen (see pixelSize).
import * as THREE from 'three';

export const TRAIL_LENGTH = 90; // positions kept per agent
export const MAX_TRAIL_AGENTS = 400; // above this many agents trails are not drawn (too many lines to read)
export const MIN_MARKER_PX = 9; // a marker's radius on screen never drops below this (CSS pixels)
export const MSG_COLOURS = [0x0097a7, 0x7b1fa2, 0x2e7d32, 0xd81b60]; // agent, group, environment, overlay
const MSG_RGB = MSG_COLOURS.map((hex) => { const c = new THREE.Color(hex); return [c.r, c.g, c.b]; });
const MAX_SEGMENTS = 2000; // message lines kept in the ring buffer (as scene3d.js allocates)
const FADE_MS = 600; // a message line fades out over this time
const ZONE_LOW = 0xfff3b0; // density 0
const ZONE_HIGH = 0xd7301f; // density 1
const RAY_HIT = [0.9, 0.05, 0.05, 1]; // linear RGBA
const RAY_MISS = [0.3, 0.3, 0.3, 0.3];

/** World metres per CSS pixel at world point p (perspective: depends on the distance; orthographic: constant). */
export function pixelSize(camera, canvas, p, tmp) {
  const h = Math.max(canvas.clientHeight, 1);
  if (camera.isOrthographicCamera) return (camera.top - camera.bottom) / camera.zoom / h;
  const d = tmp.set(p[0], p[1], p[2]).applyMatrix4(camera.matrixWorldInverse).z;
  return (2 * Math.max(-d, camera.near) * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2)) / h;
}

/** A LineSegments with preallocated position (xyz) and RGBA colour buffers, drawn up to setDrawRange. */
export function makeLines(capacity, opacity = 1) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(capacity * 6), 3)
    .setUsage(THREE.DynamicDrawUsage));
  geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(capacity * 8), 4)
    .setUsage(THREE.DynamicDrawUsage));
  geometry.setDrawRange(0, 0);
  const material = new THREE.LineBasicMaterial({ vertexColors: true, transparent: true, opacity, depthWrite: false });
  const lines = new THREE.LineSegments(geometry, material);
  lines.frustumCulled = false;
  lines.userData.capacity = capacity;
  return lines;
}

/** Markers: a translucent disc, a ring and a pole with a pennant each (one InstancedMesh per part). */
export class Markers {
  constructor(group, markers, lift) {
    this.items = (markers || []).filter((m) => m.kind !== 'zone');
    const n = this.items.length;
    this.lift = lift;
    const mat = (opts) => new THREE.MeshBasicMaterial({ side: THREE.DoubleSide, ...opts });
    this.disc = new THREE.InstancedMesh(new THREE.CircleGeometry(1, 40),
      mat({ transparent: true, opacity: 0.3, depthWrite: false }), Math.max(n, 1));
    this.ring = new THREE.InstancedMesh(new THREE.RingGeometry(0.78, 1, 40), mat({}), Math.max(n, 1));
    // a pole 2.2 radii high with a small pennant at its top: reads as "a place to reach" from any angle
    const pole = new THREE.CylinderGeometry(0.04, 0.04, 2.2, 6).rotateX(Math.PI / 2).translate(0, 0, 1.1);
    const flag = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(0, 0, 2.2),
      new THREE.Vector3(0.7, 0, 1.95), new THREE.Vector3(0, 0, 1.7)]);
    this.pole = new THREE.InstancedMesh(pole, new THREE.MeshLambertMaterial({ color: 0x37474f }), Math.max(n, 1));
    this.flag = new THREE.InstancedMesh(flag, mat({}), Math.max(n, 1));
    for (const mesh of [this.disc, this.ring, this.pole, this.flag]) {
      mesh.count = n;
      mesh.frustumCulled = false;
      group.add(mesh);
    }
    this.disc.renderOrder = 1;
    const c = new THREE.Color();
    this.items.forEach((m, i) => {
      c.set(m.colour || '#2e9e44');
      this.disc.setColorAt(i, c);
      this.ring.setColorAt(i, c);
      this.flag.setColorAt(i, c);
    });
    this.links = new THREE.LineSegments(new THREE.BufferGeometry(),
      new THREE.LineDashedMaterial({ color: 0x455a64, dashSize: 1, gapSize: 0.6, transparent: true, opacity: 0.7 }));
    this.links.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * Math.max(n, 1)), 3));
    this.links.frustumCulled = false;
    group.add(this.links);
    this.m = new THREE.Matrix4();
    this.q = new THREE.Quaternion();
    this.v = new THREE.Vector3();
    this.s = new THREE.Vector3();
    this.tmp = new THREE.Vector3();
  }

  /** Recolour markers that belong to an agent with that agent's colour (its group's or its own). */
  recolour(colourOf) {
    const c = new THREE.Color();
    this.items.forEach((m, i) => {
      if (m.slot === undefined || m.slot === null || m.group !== undefined) return;
      const rgb = colourOf(m.slot);
      if (!rgb) return;
      c.setRGB(rgb[0], rgb[1], rgb[2]);
      this.ring.setColorAt(i, c);
      this.disc.setColorAt(i, c);
      this.flag.setColorAt(i, c);
    });
    for (const mesh of [this.disc, this.ring, this.flag]) if (mesh.instanceColor) mesh.instanceColor.needsUpdate = true;
  }

  /** Size every marker: its true radius, or MIN_MARKER_PX on screen when that is larger; links to agents. */
  layout(camera, canvas, pos, showLinks) {
    const n = this.items.length;
    const lp = this.links.geometry.attributes.position.array;
    let k = 0;
    this.items.forEach((m, i) => {
      const [x, y] = m.pos;
      const r = Math.max(m.radius || 1, MIN_MARKER_PX * pixelSize(camera, canvas, [x, y, 0], this.tmp));
      this.s.set(r, r, 1);
      this.disc.setMatrixAt(i, this.m.compose(this.v.set(x, y, this.lift), this.q, this.s));
      this.ring.setMatrixAt(i, this.m.compose(this.v.set(x, y, 2 * this.lift), this.q, this.s));
      this.s.set(r, r, r);
      this.pole.setMatrixAt(i, this.m.compose(this.v.set(x, y, 0), this.q, this.s));
      this.flag.setMatrixAt(i, this.m.compose(this.v, this.q, this.s));
      const a = m.slot;
      if (showLinks && m.kind === 'target' && pos && a !== undefined && a !== null && 3 * a + 2 < pos.length) {
        lp.set([pos[3 * a], pos[3 * a + 1], pos[3 * a + 2], x, y, 2 * this.lift], 6 * k);
        k += 1;
      }
    });
    for (const mesh of [this.disc, this.ring, this.pole, this.flag]) {
      mesh.count = n;
      mesh.instanceMatrix.needsUpdate = true;
    }
    this.links.geometry.attributes.position.needsUpdate = true;
    this.links.geometry.setDrawRange(0, 2 * k);
    this.links.computeLineDistances();
  }

  /** Screen positions (CSS pixels in the page) of the markers' centres: [{kind, slot, label, x, y}]. */
  screen(project) {
    return this.items.map((m) => {
      const [x, y] = project([m.pos[0], m.pos[1], 0]);
      return { kind: m.kind, slot: m.slot ?? null, label: m.label || '', x, y };
    });
  }
}

/** The agents' recent paths: a ring buffer of TRAIL_LENGTH positions per agent drawn as fading segments. */
export class Trails {
  constructor(group) {
    this.n = 0;
    this.count = 0; // positions stored (<= TRAIL_LENGTH)
    this.head = 0; // next row to write
    this.buf = new Float32Array(0);
    this.lines = new THREE.LineSegments(new THREE.BufferGeometry(),
      new THREE.LineBasicMaterial({ vertexColors: true, transparent: true, depthWrite: false }));
    this.lines.frustumCulled = false;
    group.add(this.lines);
    this.lastStep = null;
  }

  clear() {
    this.count = 0;
    this.head = 0;
    this.lastStep = null;
    this.lines.geometry.setDrawRange(0, 0);
  }

  /** Add the frame's positions (a step back, as a replay seek, clears them); rebuild the segments. */
  add(pos, step, colourOf, active) {
    const n = pos.length / 3;
    if (n > MAX_TRAIL_AGENTS) { this.clear(); return; }
    if (n !== this.n) {
      this.n = n;
      this.buf = new Float32Array(n * TRAIL_LENGTH * 3);
      const seg = n * (TRAIL_LENGTH - 1);
      this.lines.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(seg * 6), 3));
      this.lines.geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(seg * 8), 4));
      this.clear();
    }
    if (this.lastStep !== null && (step < this.lastStep || step > this.lastStep + 50)) this.clear();
    if (step === this.lastStep) return;
    this.lastStep = step;
    this.buf.set(pos, this.head * n * 3);
    this.head = (this.head + 1) % TRAIL_LENGTH;
    this.count = Math.min(this.count + 1, TRAIL_LENGTH);
    const P = this.lines.geometry.attributes.position.array;
    const C = this.lines.geometry.attributes.color.array;
    let k = 0;
    for (let i = 0; i < n; i++) {
      const c = colourOf(i);
      for (let j = 1; j < this.count; j++) { // j-th newest to (j-1)-th newest
        const a = ((this.head - j - 1 + 2 * TRAIL_LENGTH) % TRAIL_LENGTH) * n * 3 + 3 * i;
        const b = ((this.head - j + 2 * TRAIL_LENGTH) % TRAIL_LENGTH) * n * 3 + 3 * i;
        const jump = Math.abs(this.buf[a] - this.buf[b]) + Math.abs(this.buf[a + 1] - this.buf[b + 1]);
        if (jump === 0 && !active[i]) continue; // an agent standing still (ended): nothing to draw
        P.set(this.buf.subarray(a, a + 3), 6 * k);
        P.set(this.buf.subarray(b, b + 3), 6 * k + 3);
        const alpha = 0.85 * (1 - j / TRAIL_LENGTH);
        C.set([c[0], c[1], c[2], alpha, c[0], c[1], c[2], alpha], 8 * k);
        k += 1;
      }
    }
    this.lines.geometry.attributes.position.needsUpdate = true;
    this.lines.geometry.attributes.color.needsUpdate = true;
    this.lines.geometry.setDrawRange(0, 2 * k);
  }
}

// ----- zones and message lines (functions of a Scene3D, `view`) --------------------------------------------------
/** A flat disc shaded radially by the zone's density samples (r = 0 .. radius), warm = dense. */
export function buildZone(view, zone, z) {
  const geometry = new THREE.RingGeometry(0, zone.radius, 48, 24);
  const position = geometry.attributes.position;
  const colours = new Float32Array(position.count * 4);
  const low = new THREE.Color(ZONE_LOW);
  const high = new THREE.Color(ZONE_HIGH);
  const c = new THREE.Color();
  const d = zone.density || [];
  for (let i = 0; i < position.count; i++) {
    const r = Math.hypot(position.getX(i), position.getY(i)) / zone.radius;
    const t = Math.min(Math.max(r, 0), 1) * (d.length - 1); // linear interpolation between samples
    const k = Math.min(Math.floor(t), Math.max(d.length - 2, 0));
    const v = d.length ? (d.length > 1 ? d[k] + (d[k + 1] - d[k]) * (t - k) : d[0]) : 0;
    c.copy(low).lerp(high, v);
    colours.set([c.r, c.g, c.b, 0.25 + 0.6 * v], i * 4);
  }
  geometry.setAttribute('color', new THREE.BufferAttribute(colours, 4));
  const disc = new THREE.Mesh(geometry, new THREE.MeshBasicMaterial({
    vertexColors: true, transparent: true, depthWrite: false, side: THREE.DoubleSide,
  }));
  disc.position.set(zone.centre[0], zone.centre[1], z);
  const edge = new THREE.LineLoop(new THREE.BufferGeometry().setFromPoints(
    Array.from({ length: 64 }, (_, i) => new THREE.Vector3(
      zone.radius * Math.cos((i / 64) * 2 * Math.PI), zone.radius * Math.sin((i / 64) * 2 * Math.PI), 0))),
  new THREE.LineBasicMaterial({ color: ZONE_HIGH, transparent: true, opacity: 0.6 }));
  edge.position.copy(disc.position);
  view.world.add(disc, edge);
}

/** Append view frame's deliveries to the ring buffer of segments (receiver or sender -1: a vertical tick). */
export function addMessages(view, msg, kinds, pos, n) {
  const P = view.messages.geometry.attributes.position.array;
  const C = view.messages.geometry.attributes.color.array;
  const now = performance.now();
  for (let k = 0; k < msg.length / 2; k++) {
    const s = msg[2 * k];
    const r = msg[2 * k + 1];
    const sOk = s >= 0 && s < n;
    const rOk = r >= 0 && r < n;
    if (!sOk && !rOk) continue;
    const i = view.msgHead;
    const o = i * 6;
    const a = sOk ? s : r;
    P[o] = pos[3 * a]; P[o + 1] = pos[3 * a + 1]; P[o + 2] = pos[3 * a + 2];
    if (sOk && rOk) {
      P[o + 3] = pos[3 * r]; P[o + 4] = pos[3 * r + 1]; P[o + 5] = pos[3 * r + 2];
    } else { // to or from the environment: a short vertical line above the agent
      const h = 4 * (a < view.radius.length ? view.radius[a] : view.meanRadius);
      P[o + 3] = P[o]; P[o + 4] = P[o + 1]; P[o + 5] = P[o + 2] + h;
    }
    const c = MSG_RGB[kinds ? kinds[k] % MSG_RGB.length : 0];
    C.set(c, i * 8); C.set(c, i * 8 + 4);
    view.msgBorn[i] = now;
    view.msgHead = (i + 1) % MAX_SEGMENTS;
    view.msgCount = Math.min(view.msgCount + 1, MAX_SEGMENTS);
    view.msgLastBorn = now;
  }
  view.messages.geometry.attributes.position.needsUpdate = true;
  view.messages.geometry.setDrawRange(0, view.msgCount * 2);
}

/** Update the message alphas; returns true while some segment is still visible. */
export function fadeMessages(view, now) {
  if (!view.messages || now - view.msgLastBorn > FADE_MS + 50) {
    if (view.messages && view.msgCount) { // everything has faded: stop drawing the buffer
      view.msgCount = 0;
      view.msgHead = 0;
      view.messages.geometry.setDrawRange(0, 0);
      return true; // one last render without them
    }
    return false;
  }
  const C = view.messages.geometry.attributes.color.array;
  for (let i = 0; i < view.msgCount; i++) {
    const alpha = Math.max(0, 1 - (now - view.msgBorn[i]) / FADE_MS);
    C[i * 8 + 3] = alpha;
    C[i * 8 + 7] = alpha;
  }
  view.messages.geometry.attributes.color.needsUpdate = true;
  return true;
}

/** A thin line from each agent down to the ground and a dot there: its altitude and ground track read. */
export function layoutDrops(view, pos, n) {
  if (!view.drops || view.drops.userData.capacity < n) {
    if (view.drops) { view.world.remove(view.drops); view.drops.geometry.dispose(); }
    view.drops = makeLines(Math.max(n, 1), 0.55);
    view.world.add(view.drops);
  }
  const P = view.drops.geometry.attributes.position.array;
  const C = view.drops.geometry.attributes.color.array;
  for (let i = 0; i < n; i++) {
    P.set([pos[3 * i], pos[3 * i + 1], pos[3 * i + 2], pos[3 * i], pos[3 * i + 1], 0], 6 * i);
    const c = view.colourOf(i, true);
    C.set([c[0], c[1], c[2], 1, c[0], c[1], c[2], 1], 8 * i);
  }
  view.drops.geometry.attributes.position.needsUpdate = true;
  view.drops.geometry.attributes.color.needsUpdate = true;
  view.drops.geometry.setDrawRange(0, 2 * n);
}

/** The selected agent's proximity rays: red for hits, faint for misses. */
export function setRays(view, rays, hits, pos, n) {
  const sel = view.selected;
  const k = rays && sel !== null && sel < n ? rays.length / 3 : 0;
  if (k > view.rays.userData.capacity) {
    view.world.remove(view.rays);
    view.rays.geometry.dispose();
    view.rays.material.dispose();
    view.rays = makeLines(Math.max(k, 2 * view.rays.userData.capacity));
    view.world.add(view.rays);
  }
  const P = view.rays.geometry.attributes.position.array;
  const C = view.rays.geometry.attributes.color.array;
  for (let i = 0; i < k; i++) {
    for (let j = 0; j < 3; j++) {
      P[i * 6 + j] = pos[3 * sel + j];
      P[i * 6 + 3 + j] = rays[3 * i + j];
    }
    const c = hits && hits[i] === 1 ? RAY_HIT : RAY_MISS;
    C.set(c, i * 8); C.set(c, i * 8 + 4);
  }
  view.rays.geometry.attributes.position.needsUpdate = true;
  view.rays.geometry.attributes.color.needsUpdate = true;
  view.rays.geometry.setDrawRange(0, k * 2);
}
