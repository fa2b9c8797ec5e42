// The viewer's camera: the first view of a scene (the bounds), framing the agents' extent, following the selected
// agent, and the top-down orthographic frustum. Functions of a Scene3D (`view`), kept apart from its drawing.
import * as THREE from 'three';

/** Initial camera: a 3/4 perspective view of the bounds, or (top) the whole bounds straight down. */
export function frameCamera(view) {
  const [x0, x1, y0, y1] = view.bounds;
  const cx = (x0 + x1) / 2;
  const cy = (y0 + y1) / 2;
  const size = view.size;
  if (view.top) {
    view.camera.position.set(cx, cy, size * 10);
    view.camera.near = size * 0.01;
    view.camera.far = size * 20;
    view.camera.lookAt(cx, cy, 0);
    view.fitTop();
    return;
  }
  // Back the camera off along a fixed 3/4 direction until the four bounds corners project inside 90% of the view.
  const dir = new THREE.Vector3(0.25, -0.75, 0.62).normalize();
  const corners = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
  let dist = size * 0.5;
  for (let i = 0; i < 40; i++) {
    view.camera.position.set(cx + dir.x * dist, cy + dir.y * dist, dir.z * dist);
    view.camera.near = dist * 0.005;
    view.camera.far = dist * 20;
    view.camera.lookAt(cx, cy, 0);
    view.camera.updateMatrixWorld();
    view.camera.updateProjectionMatrix();
    const fits = corners.every(([x, y]) => {
      const v = view.tmp.set(x, y, 0).project(view.camera);
      return Math.abs(v.x) <= 0.9 && Math.abs(v.y) <= 0.9;
    });
    if (fits) break;
    dist *= 1.08;
  }
  view.controls.target.set(cx, cy, 0);
  view.controls.update();
}

/** Orthographic frustum holding the bounds (5% margin), centred, at the canvas aspect ratio. */
export function fitTop(view) {
  const [x0, x1, y0, y1] = view.bounds;
  const aspect = view.aspect();
  let w = (x1 - x0) * 1.05;
  let h = (y1 - y0) * 1.05;
  if (w / h < aspect) w = h * aspect;
  else h = w / aspect;
  Object.assign(view.camera, { left: -w / 2, right: w / 2, top: h / 2, bottom: -h / 2 });
  view.camera.updateProjectionMatrix();
}

/** Frame the agents' extent (and the markers'): the 3/4 view backed off until they fill ~80% of it. */
export function frameAgents(view) {
  if (view.top || !view.frame) return;
  const pos = view.frame.arrays.pos;
  const pts = [];
  for (let i = 0; i < pos.length / 3; i++) pts.push([pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]]);
  for (const m of view.sceneMsg?.markers || []) {
    const r = m.kind === 'zone' ? m.radius : 0;
    pts.push([m.pos[0] - r, m.pos[1] - r, 0], [m.pos[0] + r, m.pos[1] + r, 0]);
  }
  if (!pts.length) return;
  const lo = [0, 1, 2].map((j) => Math.min(...pts.map((p) => p[j])));
  const hi = [0, 1, 2].map((j) => Math.max(...pts.map((p) => p[j])));
  // at least a fifth of the map across, so a tight cluster is not magnified beyond reading the map around it
  const pad = Math.max(0.03 * Math.max(hi[0] - lo[0], hi[1] - lo[1]), 3);
  const [x0, x1, y0, y1] = [lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad];
  const c = new THREE.Vector3((x0 + x1) / 2, (y0 + y1) / 2, 0);
  const corners = [];
  // the padded ground rectangle and every agent itself (not the box's upper corners: a box up to the highest
  // agent over the whole rectangle would waste the top of the view)
  for (const x of [x0, x1]) for (const y of [y0, y1]) corners.push([x, y, 0]);
  corners.push(...pts.filter((p) => p[2] > 0));
  // ~34 degrees up so that altitude reads; a long thin extent (a corridor) is seen from higher up, so that its
  // width is not squashed to a line
  const thin = Math.min(x1 - x0, y1 - y0) / Math.max(x1 - x0, y1 - y0) < 0.3;
  const dir = (thin ? new THREE.Vector3(0.1, -0.6, 0.8) : new THREE.Vector3(0.2, -0.8, 0.56)).normalize();
  let dist = Math.max(x1 - x0, y1 - y0) * 0.3;
  for (let i = 0; i < 60; i++) {
    view.camera.position.copy(c).addScaledVector(dir, dist);
    view.camera.near = dist * 0.005;
    view.camera.far = dist * 30;
    view.camera.lookAt(c);
    view.camera.updateMatrixWorld();
    view.camera.updateProjectionMatrix();
    const fits = corners.every(([x, y, z]) => {
      const v = view.tmp.set(x, y, z).project(view.camera);
      return Math.abs(v.x) <= 0.9 && Math.abs(v.y) <= 0.9;
    });
    if (fits) break;
    dist *= 1.06;
  }
  view.controls.target.copy(c);
  view.controls.update();
  view.dirty = true;
}

/** Keep the selected agent in the middle: move the orbit target and the camera by the agent's motion. */
export function followSelected(view) {
  const s = view.selected;
  const pos = view.frame?.arrays.pos;
  if (!view.follow || view.top || s === null || !pos || 3 * s + 2 >= pos.length) return;
  const d = view.tmp.set(pos[3 * s], pos[3 * s + 1], pos[3 * s + 2]).sub(view.controls.target);
  if (d.lengthSq() < 1e-8) return;
  view.camera.position.add(d);
  view.controls.target.add(d);
  view.controls.update();
}
