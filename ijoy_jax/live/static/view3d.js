// The live view of ijoy drive in 3D (three.js, vendored next to this file): the terrain as a height-field mesh, the
// robot's bodies at their simulated poses, the chosen and past footholds, and a camera that follows the robot.
// World frame: x, y on the ground, z up, metres; the scene, the state and the mesh come from the view's server.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

const LOW = [205, 214, 196], HIGH = [96, 128, 88], OBSTACLE = [70, 40, 36];   // the 2D map's terrain colours
const LEFT_RGB = 0x3a7bd5, RIGHT_RGB = 0xe8a33d;   // the feet's colours of the 2D view
const FOLLOW = 0.15;   // fraction of the way to the robot the camera's target moves per frame

function srgb(r, g, b) { return new THREE.Color().setRGB(r, g, b, THREE.SRGBColorSpace); }

// The meshes of /meshes.bin (ijoy_jax.live.view.mesh_bytes): little-endian 4-byte words, the count N, each
// mesh's vertex and triangle counts, then each mesh's vertices (float32 x, y, z) and triangles (uint32).
function parseMeshes(buffer) {
  const words = new DataView(buffer), n = words.getUint32(0, true), out = [];
  let at = 4 * (1 + 2 * n);
  for (let k = 0; k < n; k++) {
    const nv = words.getUint32(4 * (1 + 2 * k), true), nf = words.getUint32(4 * (2 + 2 * k), true);
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(buffer, at, 3 * nv), 3));
    at += 12 * nv;
    g.setIndex(new THREE.BufferAttribute(new Uint32Array(buffer, at, 3 * nf), 1));
    at += 12 * nf;
    g.computeVertexNormals();
    out.push(g);
  }
  return out;
}

// A MuJoCo geom as a three.js geometry in the geom's frame (capsules and cylinders along z, as in MuJoCo; a mesh
// is its bounding box until its vertices arrive).
function geomGeometry(type, size) {
  const [a, b, c] = size;
  if (type === "sphere") return new THREE.SphereGeometry(a, 20, 14);
  if (type === "ellipsoid") return new THREE.SphereGeometry(1, 20, 14).scale(a, b, c);
  if (type === "capsule") return new THREE.CapsuleGeometry(a, 2 * b, 6, 16).rotateX(Math.PI / 2);
  if (type === "cylinder") return new THREE.CylinderGeometry(a, a, 2 * b, 20).rotateX(Math.PI / 2);
  return new THREE.BoxGeometry(2 * a, 2 * b, 2 * c);
}

// The terrain mesh of /terrain3d.json: a vertex per cell centre, coloured as the 2D map (obstacles dark); a 2D
// map's obstacle cells raised to the height the robot meets them at.
function terrainMesh(mesh, scene) {
  const { nx, ny, origin, step, z, obstacle } = mesh;
  const raise = mesh.has_height ? 0 : (scene.obstacle_height || 0);
  const pos = new Float32Array(nx * ny * 3), col = new Float32Array(nx * ny * 3);
  let lo = Infinity, hi = -Infinity;
  for (const h of z) { lo = Math.min(lo, h); hi = Math.max(hi, h); }
  for (let j = 0; j < ny; j++) {
    for (let i = 0; i < nx; i++) {
      const k = j * nx + i, blocked = obstacle[k] === 1;
      pos[3 * k] = origin[0] + i * step; pos[3 * k + 1] = origin[1] + j * step;
      pos[3 * k + 2] = blocked && raise ? raise : z[k];
      const u = hi > lo ? (z[k] - lo) / (hi - lo) : 0.5;
      const rgb = blocked ? OBSTACLE : LOW.map((v, n) => v * (1 - u) + HIGH[n] * u);
      const c = srgb(rgb[0] / 255, rgb[1] / 255, rgb[2] / 255);
      col[3 * k] = c.r; col[3 * k + 1] = c.g; col[3 * k + 2] = c.b;
    }
  }
  const index = [];
  for (let j = 0; j + 1 < ny; j++) {
    for (let i = 0; i + 1 < nx; i++) {
      const a = j * nx + i, b = a + 1, c = a + nx, d = c + 1;
      index.push(a, b, d, a, d, c);
    }
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute("position", new THREE.BufferAttribute(pos, 3));
  g.setAttribute("color", new THREE.BufferAttribute(col, 3));
  g.setIndex(index);
  g.computeVertexNormals();
  return new THREE.Mesh(g, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
}

// A foothold's sole: a flat box (filled, past) or its outline (the chosen one), its centre at (x, y, z), turned by yaw.
function soleMesh(foot, colour, outline) {
  const box = new THREE.BoxGeometry(foot[0], foot[1], 0.006);
  if (outline) {
    return new THREE.LineSegments(new THREE.EdgesGeometry(box), new THREE.LineBasicMaterial({ color: colour }));
  }
  return new THREE.Mesh(box, new THREE.MeshLambertMaterial({ color: colour, transparent: true, opacity: 0.55 }));
}

export function start(container, current) {
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  container.appendChild(renderer.domElement);
  renderer.domElement.style.display = "block";
  const world = new THREE.Scene();
  world.background = new THREE.Color(0x1d2126);
  world.add(new THREE.HemisphereLight(0xffffff, 0x404848, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.6);
  sun.position.set(-3, -2, 6);
  world.add(sun);
  world.add(new THREE.AxesHelper(0.5));   // x red, y green, z blue: half a metre each, at the world origin
  const camera = new THREE.PerspectiveCamera(45, 1, 0.02, 200);
  camera.up.set(0, 0, 1);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.enableDamping = false;
  let dirty = true;
  controls.addEventListener("change", () => { dirty = true; });

  const api = window.ijoy3d = { frames: 0, bodies: 0, meshes: 0, terrain: false, follow: null, version: 0 };
  let terrain = null, meshText = null, bodies = [], bodiesVersion = null, fetching = false, lastState = null;
  let followed = null;
  const past = new THREE.Group(), chosen = new THREE.Group();
  world.add(past, chosen);

  // the pixel (CSS px in the page) where a world point is drawn, and whether it is in front of the camera
  api.project = (x, y, z) => {
    const v = new THREE.Vector3(x, y, z).project(camera), r = renderer.domElement.getBoundingClientRect();
    return [r.left + (v.x + 1) / 2 * r.width, r.top + (1 - v.y) / 2 * r.height, v.z < 1];
  };

  // each body's name and the pixel its centre is drawn at, as last placed ([name, x, y, in front])
  api.bodyPixels = () => bodies.filter(m => m.visible).map(m => [m.name, ...api.project(m.position.x, m.position.y, m.position.z)]);

  fetch("terrain3d.json").then(r => r.json()).then(m => { meshText = m; });

  function buildBodies(desc) {
    for (const b of bodies) { world.remove(b); b.geometry.dispose(); b.material.dispose(); }
    bodies = desc.types.map((type, g) => {
      const [r, gg, b, a] = desc.rgba[g];
      const mat = new THREE.MeshLambertMaterial({ color: srgb(r, gg, b), transparent: a < 1, opacity: a });
      const mesh = new THREE.Mesh(geomGeometry(type, desc.sizes[g]), mat);
      mesh.name = desc.names[g];
      mesh.visible = false;
      world.add(mesh);
      return mesh;
    });
    bodiesVersion = desc.version;
    api.bodies = bodies.length; api.version = desc.version; api.names = desc.names; api.meshes = 0;
    const uses = (desc.mesh || []).filter(k => k >= 0);
    if (uses.length) loadMeshes(desc.version, desc.mesh, Math.max(...uses) + 1);
  }

  // The mesh geoms' vertices and faces, fetched once per body (they come after the scene: megabytes for the G1).
  function loadMeshes(version, index, count) {
    fetch("meshes.bin?v=" + version).then(r => r.arrayBuffer()).then(buffer => {
      if (version !== bodiesVersion) return;   // another body since
      const meshes = parseMeshes(buffer);
      if (meshes.length !== count) return;    // the server holds another body's
      bodies.forEach((m, g) => {
        if (index[g] < 0) return;
        m.geometry.dispose();
        m.geometry = meshes[index[g]];
      });
      api.meshes = meshes.length; dirty = true;
    }).catch(() => {});
  }

  // The bodies' geoms come with the scene; a state with another version (a body set after this page loaded)
  // fetches the scene again.
  function syncBodies(scene, state) {
    const want = state && state.bodies ? state.bodies.version : null;
    if (want === null || want === bodiesVersion) return;
    if (scene && scene.bodies && scene.bodies.version === want) { buildBodies(scene.bodies); return; }
    if (fetching) return;
    fetching = true;
    fetch("scene.json").then(r => r.json()).then(s => {
      fetching = false;
      if (s.bodies && s.bodies.version === want) buildBodies(s.bodies);
    }).catch(() => { fetching = false; });
  }

  // Puts every geom at its pose; returns the centre of their bounding box and its largest side (m), or null.
  function place(state) {
    const p = state.bodies.pos, q = state.bodies.quat;
    const box = new THREE.Box3();
    bodies.forEach((m, g) => {
      const x = p[3 * g], y = p[3 * g + 1], z = p[3 * g + 2];
      const ok = [x, y, z, q[4 * g], q[4 * g + 1], q[4 * g + 2], q[4 * g + 3]].every(v => typeof v === "number");
      m.visible = ok;
      if (!ok) return;
      m.position.set(x, y, z);
      m.quaternion.set(q[4 * g + 1], q[4 * g + 2], q[4 * g + 3], q[4 * g]);   // MuJoCo's (w, x, y, z)
      box.expandByPoint(m.position);
    });
    if (box.isEmpty()) return null;
    const size = box.getSize(new THREE.Vector3());
    return { point: box.getCenter(new THREE.Vector3()), size: Math.max(size.x, size.y, size.z) };
  }

  function drawFootholds(scene, state) {
    past.clear(); chosen.clear();
    const foot = scene.foot;
    for (const [x, y, z, yaw, side] of state.footholds || []) {
      if ([x, y, z, yaw].some(v => typeof v !== "number")) continue;
      const m = soleMesh(foot, side > 0 ? LEFT_RGB : RIGHT_RGB, false);
      m.position.set(x, y, z + 0.004); m.rotation.z = yaw;
      past.add(m);
    }
    const f = state.foothold;
    if (f && f.slice(0, 6).every(v => typeof v === "number")) {
      const m = soleMesh(foot, state.valid === false ? 0xd9463b : 0xffffff, true);
      m.position.set(f[0], f[1], f[2] + 0.01); m.rotation.z = f[5];
      chosen.add(m);
    }
  }

  // The camera's target follows the robot (its geoms' centre, else its feet); the camera moves with it, so the
  // user's orbit and zoom are kept. It starts behind the robot and to its right, far enough to see all of it.
  function follow(point, size, heading) {
    if (!followed) {
      followed = point.clone();
      const distance = Math.min(8, Math.max(1.6, 2.4 * size));
      const back = new THREE.Vector3(-2.6, -1.5, 1.4).normalize().multiplyScalar(distance)
        .applyAxisAngle(new THREE.Vector3(0, 0, 1), heading);
      camera.position.copy(point).add(back);
      controls.target.copy(point);
      controls.update();
      return;
    }
    const delta = point.clone().sub(followed).multiplyScalar(FOLLOW);
    if (delta.lengthSq() < 1e-10) return;
    followed.add(delta);
    camera.position.add(delta);
    controls.target.add(delta);
    controls.update();
  }

  function resize() {
    const w = container.clientWidth, h = container.clientHeight;
    const c = renderer.domElement;
    if (c.width !== Math.floor(w * renderer.getPixelRatio()) || c.height !== Math.floor(h * renderer.getPixelRatio())) {
      renderer.setSize(w, h, true);
      camera.aspect = w / Math.max(1, h);
      camera.updateProjectionMatrix();
      dirty = true;
    }
  }

  function frame() {
    requestAnimationFrame(frame);
    resize();
    const { scene, state } = current();
    if (!scene || !scene.shape) return;
    if (!terrain && meshText) {
      terrain = terrainMesh(meshText, scene);
      world.add(terrain);
      api.terrain = true; dirty = true;
    }
    if (state && state !== lastState) {
      lastState = state; dirty = true;
      syncBodies(scene, state);
      const placed = state.bodies && bodies.length ? place(state) : null;
      if (state.feet) {
        const f = state.feet;
        const { point, size } = placed
          || { point: new THREE.Vector3((f[0][0] + f[1][0]) / 2, (f[0][1] + f[1][1]) / 2, 0.3), size: 0.6 };
        const heading = Math.atan2(Math.sin(f[0][2]) + Math.sin(f[1][2]), Math.cos(f[0][2]) + Math.cos(f[1][2]));
        follow(point, size, heading);
        api.follow = followed.toArray();
      }
      drawFootholds(scene, state);
    }
    if (!dirty) return;
    dirty = false;
    renderer.render(world, camera);
    api.frames++;
  }
  frame();
  return api;
}
