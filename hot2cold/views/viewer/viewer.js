// hot2cold report: the interactive 3D view (written into the page by hot2cold.views.viewer).
//
// Everything it needs is in the page: the JSON element #v3-data holds the geometry (typed arrays, base64), and
// the page's import map gives three.js as data: URLs, so the browser loads the modules before this script runs.
// Nothing here waits: the view is drawn while the module runs, before the page's load event.

import * as THREE from 'three';
import { OrbitControls } from 'three-orbit-controls';

const data = JSON.parse(document.getElementById('v3-data').textContent);
const stage = document.getElementById('v3-stage');
const canvas = document.getElementById('v3-canvas');
const status = document.getElementById('v3-status');
const info = document.getElementById('v3-info');

// ------------------------------------------------------------------------------------------ unpacking
const TYPES = { float32: Float32Array, uint16: Uint16Array, uint32: Uint32Array };

function array(entry) {
  const bytes = Uint8Array.from(atob(entry.data), (c) => c.charCodeAt(0));
  return new TYPES[entry.type](bytes.buffer, 0, bytes.byteLength / TYPES[entry.type].BYTES_PER_ELEMENT);
}

// -------------------------------------------------------------------------------------------- the view
function main() {
  const a = {};
  for (const key of ['hot', 'displacement', 'deviation', 'triangles', 'triangleFace', 'outlines',
                     'nodeHot', 'nodeDisplacement', 'nodeDeviation']) {
    a[key] = array(data[key]);
  }

  // viridis (sRGB bytes) -> linear colours; NaN (no nodes) grey
  const lutBytes = Uint8Array.from(atob(data.lut), (c) => c.charCodeAt(0));
  const lut = [];
  for (let i = 0; i < lutBytes.length; i += 3) {
    lut.push(new THREE.Color().setRGB(lutBytes[i] / 255, lutBytes[i + 1] / 255, lutBytes[i + 2] / 255,
                                      THREE.SRGBColorSpace));
  }
  const grey = new THREE.Color().setRGB(0.71, 0.71, 0.71, THREE.SRGBColorSpace);
  function colours(values, top) {
    const out = new Float32Array(values.length * 3);
    values.forEach((v, i) => {
      const c = Number.isNaN(v) ? grey
        : lut[Math.max(0, Math.min(lut.length - 1, Math.round((v / top) * (lut.length - 1))))];
      out.set([c.r, c.g, c.b], 3 * i);
    });
    return new THREE.BufferAttribute(out, 3);
  }

  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
  renderer.setPixelRatio(window.devicePixelRatio);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xffffff);
  const camera = new THREE.PerspectiveCamera(30, 1, 1, 1000);
  scene.add(camera);
  scene.add(new THREE.AmbientLight(0xffffff, 1.6));
  const headlight = new THREE.DirectionalLight(0xffffff, 1.9);       // follows the camera
  headlight.position.set(-0.3, 0.5, 1);
  camera.add(headlight);

  // the cold part: positions hot + s * displacement, rewritten when the slider moves
  const index = new THREE.BufferAttribute(a.triangles, 1);
  const position = new THREE.BufferAttribute(new Float32Array(a.hot.length), 3);
  const cold = new THREE.BufferGeometry();
  cold.setAttribute('position', position);
  // what the colours show: the deviation from the field (nodes: their errors), or the displacement's length
  const lengths = (v) => Float32Array.from({ length: v.length / 3 },
                                           (_, i) => Math.hypot(v[3 * i], v[3 * i + 1], v[3 * i + 2]));
  const shades = {
    deviation: { top: data.scaleTop, surface: a.deviation, nodes: a.nodeDeviation },
    displacement: { top: data.displacementTop, surface: lengths(a.displacement), nodes: lengths(a.nodeDisplacement) },
  };
  const colourBy = document.getElementById('v3-colour');
  let shade = shades[colourBy.value];
  cold.setAttribute('color', colours(shade.surface, shade.top));
  cold.setIndex(index);
  const coldMesh = new THREE.Mesh(cold, new THREE.MeshLambertMaterial({
    vertexColors: true, side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1,
    polygonOffsetUnits: 1 }));
  scene.add(coldMesh);

  // face outlines and the picked face share the cold positions
  const outlines = new THREE.BufferGeometry();
  outlines.setAttribute('position', position);
  outlines.setIndex(new THREE.BufferAttribute(a.outlines, 1));
  const outlineLines = new THREE.LineSegments(outlines, new THREE.LineBasicMaterial({
    color: 0x202020, transparent: true, opacity: 0.55 }));
  outlineLines.frustumCulled = false;
  scene.add(outlineLines);
  const picked = new THREE.BufferGeometry();
  picked.setAttribute('position', position);
  const pickedMesh = new THREE.Mesh(picked, new THREE.MeshBasicMaterial({
    color: 0xff8f00, transparent: true, opacity: 0.22, side: THREE.DoubleSide, depthWrite: false }));
  pickedMesh.frustumCulled = false;
  pickedMesh.visible = false;
  scene.add(pickedMesh);

  // the hot part: a see-through ghost
  const hot = new THREE.BufferGeometry();
  hot.setAttribute('position', new THREE.BufferAttribute(a.hot, 3));
  hot.setIndex(index);
  hot.computeVertexNormals();
  const ghost = new THREE.Mesh(hot, new THREE.MeshLambertMaterial({
    color: 0xd62728, transparent: true, opacity: 0.15, depthWrite: false, side: THREE.DoubleSide }));
  scene.add(ghost);

  // the FE nodes, hidden until asked for
  const nodePosition = new THREE.BufferAttribute(new Float32Array(a.nodeHot.length), 3);
  const nodes = new THREE.BufferGeometry();
  nodes.setAttribute('position', nodePosition);
  nodes.setAttribute('color', colours(shade.nodes, shade.top));
  const nodePoints = new THREE.Points(nodes, new THREE.PointsMaterial({
    size: 3, sizeAttenuation: false, vertexColors: true }));
  nodePoints.frustumCulled = false;
  nodePoints.visible = false;
  scene.add(nodePoints);

  function render() { renderer.render(scene, camera); }

  function setScale(s) {
    for (const [target, base, move] of [[position, a.hot, a.displacement],
                                        [nodePosition, a.nodeHot, a.nodeDisplacement]]) {
      const p = target.array;
      for (let i = 0; i < p.length; i++) p[i] = base[i] + s * move[i];
      target.needsUpdate = true;
    }
    cold.computeVertexNormals();
    cold.computeBoundingSphere();                                      // for picking
    document.getElementById('v3-scale-value').textContent = s.toPrecision(3);
    render();
  }

  // camera: looking along data.view[0] with data.view[1] up, as close as the whole hot part fits
  const controls = new OrbitControls(camera, canvas);
  function resetView() {
    const [dir, up] = data.view.map((v) => new THREE.Vector3(...v).normalize());
    const right = new THREE.Vector3().crossVectors(dir, up).normalize();
    up.crossVectors(right, dir);
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    const p = new THREE.Vector3();
    for (let i = 0; i < a.hot.length; i += 3) {                      // the part's box in view axes
      p.fromArray(a.hot, i);
      [p.dot(right), p.dot(up), p.dot(dir)].forEach((x, j) => { lo[j] = Math.min(lo[j], x); hi[j] = Math.max(hi[j], x); });
    }
    const centre = new THREE.Vector3().addScaledVector(right, (lo[0] + hi[0]) / 2)
      .addScaledVector(up, (lo[1] + hi[1]) / 2).addScaledVector(dir, (lo[2] + hi[2]) / 2);
    const tan = Math.tan(THREE.MathUtils.degToRad(camera.fov / 2));
    const half = Math.max((hi[1] - lo[1]) / 2, (hi[0] - lo[0]) / 2 / camera.aspect) * 1.12;
    const distance = half / tan + (hi[2] - lo[2]) / 2;
    camera.up.copy(up);
    camera.position.copy(centre).addScaledVector(dir, -distance);
    camera.near = distance / 100;
    camera.far = distance * 20;
    camera.updateProjectionMatrix();
    controls.target.copy(centre);
    controls.update();
  }
  controls.addEventListener('change', render);

  function resize() {
    const { clientWidth: w, clientHeight: h } = stage;
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
    render();
  }
  new ResizeObserver(resize).observe(stage);

  // picking: a click (not a drag) on the part selects its face; so does a click on a row of the face table
  const fmt = (x) => (x === null || x === undefined || Number.isNaN(x) ? '–' : x.toExponential(2));
  const faces = new Map(data.faces.map((f) => [f.index, f]));
  let row = null;
  function select(k, here) {
    const f = faces.get(k);
    if (!f) return;
    const lines = [`face ${f.index}` + (f.name ? ` · ${f.name}` : ''),
                   `${f.nodes.toLocaleString('en')} FE nodes · Δmax ${fmt(f.delta_max)} mm · ` +
                   `Δmean ${fmt(f.delta_mean)} mm`];
    if (here !== undefined) lines.push(`${colourBy.value} here ≈ ${fmt(here)} mm`);
    info.replaceChildren(...lines.map((text, i) => {
      const line = document.createElement(i === 0 ? 'b' : 'div');
      line.textContent = text;
      return line;
    }));
    info.hidden = false;
    info.dataset.face = String(k);
    if (row) row.classList.remove('picked');
    row = document.getElementById(`face-row-${k}`);
    if (row) row.classList.add('picked');
    const own = [];
    for (let t = 0; t < a.triangleFace.length; t++) {
      if (a.triangleFace[t] === k) own.push(a.triangles[3 * t], a.triangles[3 * t + 1], a.triangles[3 * t + 2]);
    }
    picked.setIndex(own);
    pickedMesh.visible = true;
    render();
  }
  const raycaster = new THREE.Raycaster();
  const triangle = new THREE.Triangle();
  const bary = new THREE.Vector3();
  let down = null;
  canvas.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
  canvas.addEventListener('pointerup', (e) => {
    if (!down || Math.hypot(e.clientX - down[0], e.clientY - down[1]) > 4) return;
    const r = canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    raycaster.setFromCamera(ndc, camera);
    const hit = raycaster.intersectObject(coldMesh)[0];
    if (!hit) return;
    const { a: i, b: j, c: k } = hit.face;
    triangle.setFromAttributeAndIndices(position, i, j, k).getBarycoord(hit.point, bary);
    const v = shade.surface;
    const here = bary.x * v[i] + bary.y * v[j] + bary.z * v[k];
    select(a.triangleFace[hit.faceIndex], here);
  });
  document.querySelectorAll('tr[data-face]').forEach((tr) => {
    tr.addEventListener('click', () => select(Number(tr.dataset.face)));
  });

  // controls under the view
  const slider = document.getElementById('v3-scale');
  slider.addEventListener('input', () => setScale(Number(slider.value)));
  document.getElementById('v3-true').addEventListener('click', () => { slider.value = '1'; setScale(1); });
  document.getElementById('v3-ghost').addEventListener('change', (e) => { ghost.visible = e.target.checked; render(); });
  document.getElementById('v3-outlines').addEventListener('change', (e) => {
    outlineLines.visible = e.target.checked; render();
  });
  document.getElementById('v3-nodes').addEventListener('change', (e) => { nodePoints.visible = e.target.checked; render(); });
  document.getElementById('v3-reset').addEventListener('click', () => { resetView(); render(); });
  colourBy.addEventListener('change', () => {
    shade = shades[colourBy.value];
    cold.setAttribute('color', colours(shade.surface, shade.top));
    nodes.setAttribute('color', colours(shade.nodes, shade.top));
    for (const kind of Object.keys(shades)) {
      document.getElementById(`v3-bar-${kind}`).hidden = kind !== colourBy.value;
    }
    render();
  });

  resize();
  resetView();
  setScale(Number(slider.value));
  status.hidden = true;
  stage.dataset.ready = 'true';
}

try {
  main();
} catch (error) {
  status.textContent = `The 3D view could not be shown: ${error.message || error}`;
  stage.dataset.ready = 'failed';
  console.error(error);
}
