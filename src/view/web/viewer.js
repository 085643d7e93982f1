// lightbake's viewer page: the baked glTF drawn by three.js as a renderer would draw it.
// The settings that make three.js show a lightbake bake right are marked "(renderer)".

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const canvas = document.getElementById('canvas');
const status = document.getElementById('status');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.outputColorSpace = THREE.SRGBColorSpace;
// The exposure slider scales linear radiance before the sRGB encoding; no curve.
renderer.toneMapping = THREE.LinearToneMapping;

const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 1000);
const controls = new OrbitControls(camera, canvas);
const scene = new THREE.Scene();
const overlays = { charts: new THREE.Group(), error: new THREE.Group() };
/** The light probes (with a --probes bake): the file, the dots that show them and the sphere
 *  they light. */
const probes = { file: null, dots: new THREE.Group(), sphere: null, step: 0.1, pending: null, latest: null };

/** Per mesh: its material for each view. */
const meshes = [];
/** The glTF cameras, in scene order. */
const cameras = [];

async function load() {
  const info = await (await fetch('/info.json')).json();
  const sceneUrl = new URL(info.scene, location.href);
  const gltf = await new GLTFLoader().loadAsync(sceneUrl.href);
  scene.add(gltf.scene);
  gltf.scene.updateMatrixWorld(true);

  // The bake already holds all light: punctual lights would count direct light twice.
  const lights = [];
  gltf.scene.traverse((o) => { if (o.isLight) lights.push(o); });
  lights.forEach((l) => l.removeFromParent());

  const pages = new Map();
  const loadPage = (name) => {
    if (!pages.has(name)) pages.set(name, loadExr(new URL(encodePath(name), sceneUrl).href));
    return pages.get(name);
  };
  const found = [];
  gltf.scene.traverse((o) => {
    if (o.isMesh) found.push(o);
    if (o.isCamera) cameras.push(o);
  });
  const named = gltf.parser.json.extras?.light_probes;
  if (info.probes && named?.uri !== undefined) {
    probes.file = await (await fetch(new URL(encodePath(named.uri), sceneUrl).href)).json();
  }
  for (const mesh of found) {
    const rect = nodeRect(mesh);
    const page = (rect ?? mesh.geometry.userData.lightmap)?.exr;
    let lightMap = page === undefined ? null : await loadPage(page);
    if (rect && lightMap) lightMap = rectTexture(lightMap, rect.scale_offset);
    const views = materials(mesh.material, lightMap);
    // (renderer) a mesh without a lightmap is lit by the probes at its centre, per object.
    if (!lightMap && probes.file) {
      views.lit = probeMaterial(mesh.material);
      const centre = new THREE.Box3().setFromObject(mesh).getCenter(new THREE.Vector3());
      views.lit.uniforms.sh.value = await probeSh(centre);
    }
    meshes.push({ mesh, views });
    if (lightMap) overlays.charts.add(chartBorders(mesh));
  }
  scene.add(overlays.charts, overlays.error, probes.dots);
  if (info.points) overlays.error.add(await pointErrors(gltf.scene));
  if (probes.file) await addProbes(gltf.scene);

  frameScene(gltf.scene);
  const select = document.getElementById('camera');
  cameras.forEach((c, i) => select.add(new Option(c.name || `camera ${i}`, i)));
  if (info.points) document.querySelector('#view option[value=error]').disabled = false;
}

/** An EXR page as a float texture, as the glTF's PNG pages are laid out. */
async function loadExr(url) {
  const texture = await new EXRLoader().setDataType(THREE.HalfFloatType).loadAsync(url);
  // (renderer) EXRLoader leaves the last EXR row first; glTF images (and lightbake's pages)
  // have row 0 at the top, and glTF textures are not flipped on upload.
  const { data, width, height } = texture.image;
  const row = width * 4;
  const flipped = new data.constructor(data.length);
  for (let y = 0; y < height; y++) flipped.set(data.subarray(y * row, (y + 1) * row), (height - 1 - y) * row);
  texture.image.data = flipped;
  texture.flipY = false;
  texture.colorSpace = THREE.LinearSRGBColorSpace;
  texture.minFilter = texture.magFilter = THREE.LinearFilter;
  texture.generateMipmaps = false;
  texture.wrapS = texture.wrapT = THREE.ClampToEdgeWrapping;
  texture.channel = 1; // (renderer) the lightmap UVs are TEXCOORD_1
  texture.needsUpdate = true;
  return texture;
}

/** extras.lightmap of the node placing a shared mesh (--instancing share): GLTFLoader gives
 *  node extras to the node's object, the mesh itself or the group of its primitives. */
function nodeRect(mesh) {
  for (let o = mesh; o; o = o.parent) {
    const lightmap = o.userData.lightmap;
    if (lightmap?.exr !== undefined && Array.isArray(lightmap.scale_offset)) return lightmap;
  }
  return undefined;
}

/** (renderer) A shared mesh's TEXCOORD_1 is its base layout; the node's rect places it on the
 *  page: uv_page = uv * scale + offset, in the page's glTF orientation (row 0 at the top, which
 *  loadExr keeps with flipY = false), so offset and repeat take the numbers as they are. */
function rectTexture(page, [sx, sy, ox, oy]) {
  const texture = page.clone(); // shares the image, uploads once
  texture.repeat.set(sx, sy);
  texture.offset.set(ox, oy);
  texture.userData.rect = [sx, sy, ox, oy];
  return texture;
}

function encodePath(path) {
  return path.split('/').map(encodeURIComponent).join('/');
}

/** The materials of one mesh for each view; `source` is GLTFLoader's. */
function materials(source, lightMap) {
  const surface = {
    side: source.side,
    vertexColors: source.vertexColors,
    transparent: source.transparent,
    opacity: source.opacity,
    alphaTest: source.alphaTest,
  };
  // (renderer) a Lambert material without lights shades albedo × irradiance/π; a texel holds
  // H/π, so lightMapIntensity = π gives albedo × lightmap.
  const lit = lightMap ? { lightMap, lightMapIntensity: Math.PI } : {};
  const views = {
    lit: new THREE.MeshLambertMaterial({
      ...surface, ...lit, color: source.color, map: source.map,
      emissive: source.emissive, emissiveMap: source.emissiveMap,
      emissiveIntensity: source.emissiveIntensity,
    }),
    lightmap: new THREE.MeshLambertMaterial({ ...surface, ...lit, vertexColors: false }),
    albedo: new THREE.MeshBasicMaterial({ ...surface, color: source.color, map: source.map }),
    density: lightMap ? texelChecker(lightMap, source.side) : new THREE.MeshBasicMaterial({ color: 0x202020 }),
  };
  views.charts = views.lightmap;
  views.error = views.lightmap;
  return views;
}

/** The lightmap texels as a checker (grey tones follow the lightmap, dimmed on odd texels). */
function texelChecker(lightMap, side) {
  return new THREE.ShaderMaterial({
    side,
    uniforms: {
      lightMap: { value: lightMap },
      size: { value: new THREE.Vector2(lightMap.image.width, lightMap.image.height) },
      rect: { value: new THREE.Vector4(...(lightMap.userData.rect ?? [1, 1, 0, 0])) },
    },
    vertexShader: `
      attribute vec2 uv1;
      uniform vec4 rect;
      varying vec2 vUv1;
      void main() {
        vUv1 = uv1 * rect.xy + rect.zw;
        gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
      }`,
    fragmentShader: `
      uniform sampler2D lightMap;
      uniform vec2 size;
      varying vec2 vUv1;
      void main() {
        vec2 texel = floor(vUv1 * size);
        float odd = mod(texel.x + texel.y, 2.0);
        vec3 value = texture2D(lightMap, vUv1).rgb;
        float grey = clamp(dot(value, vec3(0.2126, 0.7152, 0.0722)), 0.0, 1.0);
        gl_FragColor = vec4(vec3(0.25 + 0.75 * grey) * mix(1.0, 0.55, odd), 1.0);
      }`,
  });
}

/** The chart borders of a mesh: TEXCOORD_1 edges used by one triangle only (lightbake splits
 *  vertices at chart seams, so those are chart or mesh borders). */
function chartBorders(mesh) {
  const g = mesh.geometry;
  const index = g.index ? g.index.array : [...Array(g.attributes.position.count).keys()];
  const count = new Map();
  for (let t = 0; t + 2 < index.length; t += 3) {
    for (let k = 0; k < 3; k++) {
      const a = index[t + k], b = index[t + (k + 1) % 3];
      const key = a < b ? `${a},${b}` : `${b},${a}`;
      count.set(key, (count.get(key) || 0) + 1);
    }
  }
  const p = g.attributes.position;
  const points = [];
  for (const [key, n] of count) {
    if (n !== 1) continue;
    for (const v of key.split(',')) points.push(new THREE.Vector3().fromBufferAttribute(p, +v));
  }
  const lines = new THREE.LineSegments(
    new THREE.BufferGeometry().setFromPoints(points),
    new THREE.LineBasicMaterial({ color: 0xff3030, depthFunc: THREE.LessEqualDepth, toneMapped: false }),
  );
  lines.matrixAutoUpdate = false;
  lines.matrix.copy(mesh.matrixWorld);
  return lines;
}

/** The point reference's points, coloured by the bake's relative error there: green 0,
 *  yellow 10%, red 30% and above, grey where no baked surface lies under the point. */
async function pointErrors(root) {
  const { points } = await (await fetch('/points.json')).json();
  // Lifted off their surface a little, or the depth test hides half of them.
  const lift = new THREE.Box3().setFromObject(root).getSize(new THREE.Vector3()).length() * 1e-3;
  const positions = [], colors = [];
  for (const p of points) {
    positions.push(...p.position.map((x, k) => x + p.normal[k] * lift));
    const c = p.error === null ? new THREE.Color(0.5, 0.5, 0.5)
      : new THREE.Color().setHSL(Math.max(0, 1 - p.error / 0.3) / 3, 1, 0.5);
    colors.push(c.r, c.g, c.b);
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
  g.setAttribute('color', new THREE.Float32BufferAttribute(colors, 3));
  const errors = points.filter((p) => p.error !== null).map((p) => p.error).sort((a, b) => a - b);
  overlays.error.userData.median = errors[Math.floor(errors.length / 2)];
  return new THREE.Points(g, new THREE.PointsMaterial({
    size: 4, sizeAttenuation: false, vertexColors: true, toneMapped: false,
  }));
}

/** The probes' L2 SH interpolated at `p` (a THREE.Vector3) by the server, through the same
 *  lookup as `lightbake probes --at` and `render` (visibility-tested): nine Vector3s,
 *  coefficients of incident radiance in three.js's SphericalHarmonics3 order. */
async function probeSh(p) {
  const reply = await fetch(`/probes/at?${p.x},${p.y},${p.z}`);
  if (!reply.ok) throw new Error(`probes/at: ${reply.status}`);
  const { sh } = await reply.json();
  return Array.from({ length: 9 }, (_, m) => new THREE.Vector3(sh[3 * m], sh[3 * m + 1], sh[3 * m + 2]));
}

/** (renderer) A material lit by L2 SH of radiance (uniform `sh`, set per object): outgoing
 *  radiance albedo × E(n)/π, E(n) the clamped-cosine convolution (band weights π, 2π/3, π/4),
 *  which is three.js's getIrradianceAt(n) and the lightmaps' unit. */
function probeMaterial(source = {}) {
  return new THREE.ShaderMaterial({
    side: source.side ?? THREE.FrontSide,
    uniforms: {
      sh: { value: Array.from({ length: 9 }, () => new THREE.Vector3()) },
      albedo: { value: (source.color ?? new THREE.Color(1, 1, 1)).clone() },
      map: { value: source.map ?? null },
      hasMap: { value: Boolean(source.map) },
      emissive: { value: (source.emissive ?? new THREE.Color(0, 0, 0)).clone().multiplyScalar(source.emissiveIntensity ?? 1) },
    },
    vertexShader: `
      varying vec3 vNormal;
      varying vec2 vUv;
      void main() {
        vNormal = transpose(inverse(mat3(modelMatrix))) * normal; // world space
        vUv = uv;
        gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
      }`,
    fragmentShader: `
      uniform vec3 sh[9];
      uniform vec3 albedo;
      uniform vec3 emissive;
      uniform sampler2D map;
      uniform bool hasMap;
      varying vec3 vNormal;
      varying vec2 vUv;
      vec3 irradianceOverPi(vec3 n) {
        float x = n.x, y = n.y, z = n.z;
        vec3 e = sh[0] * 0.282095;
        e += (sh[1] * y + sh[2] * z + sh[3] * x) * (0.488603 * 2.0 / 3.0);
        e += (sh[4] * (1.092548 * x * y) + sh[5] * (1.092548 * y * z)
          + sh[6] * (0.315392 * (3.0 * z * z - 1.0)) + sh[7] * (1.092548 * x * z)
          + sh[8] * (0.546274 * (x * x - y * y))) * 0.25;
        return max(e, vec3(0.0));
      }
      void main() {
        vec3 n = normalize(vNormal) * (gl_FrontFacing ? 1.0 : -1.0);
        vec3 base = hasMap ? albedo * texture2D(map, vUv).rgb : albedo;
        gl_FragColor = vec4(base * irradianceOverPi(n) + emissive, 1.0);
        #include <tonemapping_fragment>
        #include <colorspace_fragment>
      }`,
  });
}

/** The probe dots (coloured by their mean light E/π over all normals, invalid probes red) and
 *  the movable sphere, white (albedo 1: it shows E/π), placed at the valid probe nearest the
 *  scene's centre. */
async function addProbes(root) {
  const { positions, valid, sh } = probes.file;
  const n = valid.length;
  const box = new THREE.Box3().setFromObject(root);
  const size = box.getSize(new THREE.Vector3()).length();
  const dot = new THREE.InstancedMesh(
    new THREE.SphereGeometry(size * 0.004, 8, 6),
    new THREE.MeshBasicMaterial(),
    n,
  );
  const m = new THREE.Matrix4();
  let start = null, nearest = Infinity;
  const centre = box.getCenter(new THREE.Vector3());
  for (let i = 0; i < n; i++) {
    const p = new THREE.Vector3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
    dot.setMatrixAt(i, m.makeTranslation(p.x, p.y, p.z));
    // The mean of E(n)/π over all normals is the band-0 term, c_0·Y_0.
    const c = valid[i] ? new THREE.Color(sh[27 * i] * 0.282095, sh[27 * i + 1] * 0.282095, sh[27 * i + 2] * 0.282095)
      : new THREE.Color(1, 0, 0);
    dot.setColorAt(i, c);
    if (valid[i] && p.distanceTo(centre) < nearest) { nearest = p.distanceTo(centre); start = p; }
  }
  probes.dots.add(dot);
  probes.dots.visible = false;
  probes.step = size * 0.01;
  probes.sphere = new THREE.Mesh(new THREE.SphereGeometry(size * 0.02, 48, 24), probeMaterial());
  probes.sphere.position.copy(start ?? centre);
  scene.add(probes.sphere);
  await updateSphere();
}

/** Fetches the sphere's SH for where it is now; moves made while a fetch is out are folded
 *  into one more fetch. Resolves once the sphere's light is for its latest position. */
function updateSphere() {
  if (!probes.sphere) return Promise.resolve();
  probes.latest = probes.sphere.position.clone();
  if (!probes.pending) {
    probes.pending = (async () => {
      while (probes.latest) {
        const at = probes.latest;
        probes.latest = null;
        probes.sphere.material.uniforms.sh.value = await probeSh(at);
      }
      probes.pending = null;
    })();
  }
  return probes.pending;
}

function moveSphere(delta) {
  if (!probes.sphere) return;
  probes.sphere.position.add(delta);
  updateSphere();
}

/** Arrow keys move the sphere across the view (in the horizontal plane), Page Up/Down up and
 *  down, one step (a hundredth of the scene) per press. */
function onKey(event) {
  if (!probes.sphere || event.target.tagName === 'SELECT' || event.target.tagName === 'INPUT') return;
  const forward = camera.getWorldDirection(new THREE.Vector3()).setY(0).normalize();
  const right = new THREE.Vector3().crossVectors(forward, new THREE.Vector3(0, 1, 0));
  const moves = {
    ArrowUp: forward, ArrowDown: forward.clone().negate(), ArrowRight: right,
    ArrowLeft: right.clone().negate(), PageUp: new THREE.Vector3(0, 1, 0), PageDown: new THREE.Vector3(0, -1, 0),
  };
  const dir = moves[event.key];
  if (!dir) return;
  event.preventDefault();
  moveSphere(dir.clone().multiplyScalar(probes.step));
}

/** Dragging the sphere moves it in the plane through it facing the camera (the orbit
 *  controls pause meanwhile). */
function dragSphere() {
  const raycaster = new THREE.Raycaster();
  const plane = new THREE.Plane();
  let dragging = false;
  const ray = (event) => {
    const r = canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((event.clientX - r.left) / r.width) * 2 - 1, -((event.clientY - r.top) / r.height) * 2 + 1);
    raycaster.setFromCamera(ndc, camera);
    return raycaster.ray;
  };
  // In the capture phase: before the orbit controls see the press.
  canvas.addEventListener('pointerdown', (event) => {
    const sphere = probes.sphere;
    if (!sphere?.visible) return;
    const bounds = new THREE.Sphere(sphere.position, sphere.geometry.parameters.radius);
    if (!ray(event).intersectsSphere(bounds)) return;
    dragging = true;
    controls.enabled = false;
    plane.setFromNormalAndCoplanarPoint(camera.getWorldDirection(new THREE.Vector3()), probes.sphere.position);
    canvas.setPointerCapture(event.pointerId);
  }, { capture: true });
  canvas.addEventListener('pointermove', (event) => {
    if (!dragging) return;
    const to = ray(event).intersectPlane(plane, new THREE.Vector3());
    if (to) moveSphere(to.sub(probes.sphere.position));
  });
  const stop = () => { dragging = false; controls.enabled = true; };
  canvas.addEventListener('pointerup', stop);
  canvas.addEventListener('pointercancel', stop);
}

function frameScene(root) {
  const box = new THREE.Box3().setFromObject(root);
  const center = box.getCenter(new THREE.Vector3());
  const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-3);
  camera.near = radius / 1000;
  camera.far = radius * 100;
  camera.position.copy(center).add(new THREE.Vector3(0.6, 0.5, 1).normalize().multiplyScalar(radius * 2.5));
  controls.target.copy(center);
  camera.updateProjectionMatrix();
  controls.update();
}

/** Puts the orbit camera where glTF camera `i` is (orbiting from there). */
function useCamera(i) {
  const c = cameras[i];
  if (!c) return;
  c.getWorldPosition(camera.position);
  c.getWorldQuaternion(camera.quaternion);
  camera.fov = c.isPerspectiveCamera ? c.fov : camera.fov;
  camera.near = c.near;
  camera.far = c.far;
  const distance = controls.target.distanceTo(camera.position) || 1;
  controls.target.copy(camera.position)
    .add(new THREE.Vector3(0, 0, -distance).applyQuaternion(camera.quaternion));
  camera.updateProjectionMatrix();
}

function setView(view) {
  for (const { mesh, views } of meshes) mesh.material = views[view];
  overlays.charts.visible = view === 'charts';
  overlays.error.visible = view === 'error';
  const median = overlays.error.userData.median;
  status.textContent = view === 'error' && median !== undefined
    ? `point error: green 0, yellow 10%, red ≥ 30%; median ${(median * 100).toFixed(1)}%`
    : `${meshes.length} meshes, ${cameras.length} cameras`;
}

function setExposure(stops) {
  renderer.toneMappingExposure = 2 ** stops;
  document.getElementById('stops').textContent = `${stops} EV`;
}

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * renderer.getPixelRatio())) renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}

function draw() {
  resize();
  renderer.render(scene, camera);
}

/** The current view drawn into a float target: linear radiance, rows from the top, RGB. */
function readLinear(width, height) {
  const target = new THREE.WebGLRenderTarget(width, height, { type: THREE.FloatType });
  const aspect = camera.aspect;
  camera.aspect = width / height;
  camera.updateProjectionMatrix();
  renderer.setRenderTarget(target);
  renderer.render(scene, camera);
  const rgba = new Float32Array(width * height * 4);
  renderer.readRenderTargetPixels(target, 0, 0, width, height, rgba);
  renderer.setRenderTarget(null);
  target.dispose();
  camera.aspect = aspect;
  camera.updateProjectionMatrix();
  const rgb = new Array(width * height * 3);
  for (let y = 0; y < height; y++) {
    for (let x = 0; x < width; x++) {
      const from = ((height - 1 - y) * width + x) * 4, to = (y * width + x) * 3;
      rgb[to] = rgba[from]; rgb[to + 1] = rgba[from + 1]; rgb[to + 2] = rgba[from + 2];
    }
  }
  return rgb;
}

const cameraSelect = document.getElementById('camera');
const viewSelect = document.getElementById('view');
const exposure = document.getElementById('exposure');
const probesToggle = document.getElementById('probes');
const sphereToggle = document.getElementById('sphere');
cameraSelect.addEventListener('change', () => useCamera(+cameraSelect.value));
probesToggle.addEventListener('change', () => { probes.dots.visible = probesToggle.checked; });
sphereToggle.addEventListener('change', () => { if (probes.sphere) probes.sphere.visible = sphereToggle.checked; });
window.addEventListener('keydown', onKey);
dragSphere();
viewSelect.addEventListener('change', () => setView(viewSelect.value));
exposure.addEventListener('input', () => setExposure(+exposure.value));

// What a test drives: the same controls as the panel, and the pixels.
window.lightbake = {
  ready: load().then(() => {
    const has = probes.file !== null;
    probesToggle.disabled = sphereToggle.disabled = !has;
    if (probes.sphere) probes.sphere.visible = sphereToggle.checked;
    setView(viewSelect.value);
    setExposure(+exposure.value);
    renderer.setAnimationLoop(() => { controls.update(); draw(); });
  }).catch((e) => { status.textContent = `failed: ${e.message}`; throw e; }),
  cameras: () => cameras.map((c) => c.name),
  setCamera(i) { cameraSelect.value = i; useCamera(i); draw(); },
  setView(view) { viewSelect.value = view; setView(view); draw(); },
  setExposure(stops) { exposure.value = stops; setExposure(stops); draw(); },
  readLinear,
  probes: {
    available: () => probes.file !== null,
    showProbes(on) { probesToggle.checked = on; probes.dots.visible = on; draw(); },
    /** Moves the sphere to `at` ([x, y, z]) and resolves with its SH (27 floats) once lit. */
    async moveSphere(at) {
      probes.sphere.position.fromArray(at);
      await updateSphere();
      draw();
      return probes.sphere.material.uniforms.sh.value.flatMap((v) => v.toArray());
    },
    /** Puts the orbit camera at `eye` ([x, y, z]) looking at the sphere. */
    lookAtSphere(eye) {
      camera.position.fromArray(eye);
      controls.target.copy(probes.sphere.position);
      camera.lookAt(probes.sphere.position);
      camera.updateProjectionMatrix();
      controls.update();
      draw();
    },
  },
};
