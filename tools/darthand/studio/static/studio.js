// darthand studio: the page. It shows the build's glTF package with three.js and poses it from JavaScript as
// darthand poses the model (rig.js): joint-node rotations from the joint angles, corrective blend-shape weights from
// the MANO rotations. The server (tools/darthand/studio/server.py) serves the package, thumbnails, accessories and
// backgrounds, and renders, frames and exports scenes. `window.studio` is the page's interface for its tests.
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { HDRLoader } from "three/addons/loaders/HDRLoader.js";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import * as R from "./rig.js";

const $ = (id) => document.getElementById(id);
const PI = Math.PI;
const OPENPOSE_BONES = [[0, 1], [1, 2], [2, 3], [3, 4], [0, 5], [5, 6], [6, 7], [7, 8], [0, 9], [9, 10], [10, 11],
  [11, 12], [0, 13], [13, 14], [14, 15], [15, 16], [0, 17], [17, 18], [18, 19], [19, 20]];
const FINGER_COLOURS = ["#ff5a5a", "#ffb14a", "#f5e04a", "#5ad65a", "#4aa8ff"];

const state = {
  side: null, angles: R.zeroAngles(), texture: null, skinTone: 0, accessory: "none", object: null,
  ambient: { color: [1, 1, 1], intensity: 0.25 }, key: { color: [1, 1, 1], intensity: 0.9, azimuth: -30, elevation: 35 },
  background: { kind: "none" }, renderSize: 512, poseList: [],
  environment: { id: null, rotation: 0, strength: 1, background: false, blur: 0 }, film: null, lastRequest: null,
};
const history = { undo: [], redo: [], committed: null };
const anim = { playing: false, phase: 0, from: null, to: null, speed: 0.5, last: 0 };
const metrics = { usable_ms: null, redraw_ms: [], draw_ms: [], texture_ms: [], render_ms: [], environment_ms: [] };
const pending = new Set();
let catalogue, environments, renderer, scene, camera, controls, ambient, key, pmrem;
let hand = null;                     // the shown side: {side, root, meshes, bones, rig, table, morph, variants, ...}
const hands = {};                    // side -> promise of its loaded hand
let accessory = null;                // {id, object, skinned}
let objects = null;                  // the server's /api/objects listing (null: the studio offers no objects)
let held = null;                     // the object shown: {id, grasp, object (a THREE.Group in the hand's model frame)}
const objectMeshes = {};             // object id -> promise of its mesh arrays
let drawRequested = false, inputTime = null;
const skinTone = { value: 0 };
const loader = new GLTFLoader();

// -------------------------------------------------------------------------------------------------- start-up

async function start() {
  [catalogue, { environments }] = await Promise.all([getJSON("/api/catalogue"), getJSON("/api/environments")]);
  const side = catalogue.sides[0];
  // the package, the rig and the first camera load while the panels are built
  const loading = loadHand(side);
  const framing = postJSON("/api/camera", { side, angles_deg: state.angles, view: "three_quarter", size: state.renderSize });
  loading.catch(() => {});
  framing.catch(() => {});
  setupThree();
  buildPanels();
  await showSide(side);
  setCamera(await framing);
  if (catalogue.default_texture) await selectTexture(catalogue.default_texture);
  commit();
  draw();
  metrics.usable_ms = performance.now();
  setStatus(`ready in ${(metrics.usable_ms / 1000).toFixed(2)} s`);
  requestAnimationFrame(loop);
}

function setupThree() {
  const canvas = $("view");
  renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
  renderer.setPixelRatio(1);
  renderer.setSize(canvas.width, canvas.height, false);
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.setClearColor(0x202326, 1);
  scene = new THREE.Scene();
  pmrem = new THREE.PMREMGenerator(renderer);
  camera = new THREE.PerspectiveCamera(30, 1, 0.005, 20);
  ambient = new THREE.AmbientLight(0xffffff, 1);
  key = new THREE.DirectionalLight(0xffffff, 1);
  scene.add(ambient, key, key.target);
}

// -------------------------------------------------------------------------------------------------- the hand

/** The side's package, rig and corrective table, loaded once (the promise is kept, so concurrent callers share it). */
function loadHand(side) {
  if (!hands[side]) hands[side] = fetchHand(side);
  return hands[side];
}

async function fetchHand(side) {
  const [gltf, rig] = await Promise.all([loader.loadAsync(`/gltf/${side}/${side}.gltf`), getJSON(`/api/rig/${side}`)]);
  const extras = gltf.parser.json.asset?.extras?.darthand || {};
  const meshes = [], bones = {};
  gltf.scene.traverse((o) => {
    if (o.isSkinnedMesh) { meshes.push(o); o.frustumCulled = false; }
    if (o.isBone) bones[o.name] = o;
  });
  const variants = (gltf.parser.json.extensions?.KHR_materials_variants?.variants || []).map((v) => v.name);
  const table = extras.blend_shapes?.shapes || [];
  const h = { side, gltf, root: gltf.scene, meshes, bones, rig, table, variants, materials: new Map(),
    unparsed: table.filter((s) => !/^pose_[a-z]+[0-9]_r[0-2][0-2]$/.test(s.channel)).length };
  for (const m of meshes) prepareSkin(m.material);
  return h;
}

async function showSide(side) {
  const h = await loadHand(side);
  if (hand) scene.remove(hand.root);
  hand = h;
  state.side = side;
  scene.add(h.root);
  $("side-label").textContent = `${side} hand`;
  $("mirror").textContent = `mirror to ${side === "right" ? "left" : "right"}`;
  $("mirror").disabled = catalogue.sides.length < 2;
  fillGestures();
  if (state.texture) await selectTexture(state.texture);
  if (state.accessory !== "none") await selectAccessory(state.accessory);
  if (state.object) await selectObject(state.object.id, state.object.grasp);     // the grasp refitted to this side
  applyPose();
  if (h.unparsed) setStatus(`${h.unparsed} corrective shapes are not per-entry channels: the live view shows them at 0`);
}

/** Pose the shown hand (and a glove) from state.angles: bone rotations and corrective weights. */
function applyPose() {
  if (!hand) return;
  const rotations = R.manoRotations(hand.rig, state.angles);
  const quats = R.nodeQuaternions(hand.rig, rotations);
  hand.rig.joints.forEach((name, i) => hand.bones[name]?.quaternion.fromArray(quats[i]));
  const weights = R.correctiveWeights(hand.rig, hand.table, rotations);
  for (const mesh of morphMeshes()) setMorphWeights(mesh, hand.table, weights);
  placeHeld(rotations[0]);
  requestDraw();
}

function morphMeshes() {
  const out = hand.meshes.slice();
  if (accessory?.skinned) out.push(...accessory.meshes);
  return out.filter((m) => m.morphTargetInfluences);
}

function setMorphWeights(mesh, table, weights) {
  const dict = mesh.morphTargetDictionary || {};
  const infl = mesh.morphTargetInfluences;
  for (let k = 0; k < table.length; k++) {
    const i = dict[table[k].name] ?? k;
    if (i < infl.length) infl[i] = weights[k];
  }
}

function setAngles(angles, { record = true } = {}) {
  state.angles = angles.map((a) => a.slice());
  syncSliders();
  applyPose();
  if (record) commit();
}

// -------------------------------------------------------------------------------------------------- materials

/** Skin-tone offset as the renderer applies it: added to the sRGB albedo, clamped, decoded (the texture unit has
 * already decoded the sRGB texel, so it is encoded again here). */
function prepareSkin(material) {
  if (!material || material.userData.skinTone) return;
  material.userData.skinTone = true;
  material.onBeforeCompile = (shader) => {
    shader.uniforms.skinToneOffset = skinTone;
    shader.fragmentShader = "uniform float skinToneOffset;\n" + shader.fragmentShader.replace("#include <map_fragment>", `
      #ifdef USE_MAP
        vec4 sampledDiffuseColor = texture2D( map, vMapUv );
        vec3 skinSrgb = clamp( sRGBTransferOETF( vec4( sampledDiffuseColor.rgb, 1.0 ) ).rgb + skinToneOffset, 0.0, 1.0 );
        sampledDiffuseColor.rgb = sRGBTransferEOTF( vec4( skinSrgb, 1.0 ) ).rgb;
        diffuseColor *= sampledDiffuseColor;
      #endif`);
  };
  material.customProgramCacheKey = () => "darthand-skin-tone";
}

async function selectTexture(id) {
  const t0 = performance.now();
  state.texture = id;
  markSelected("textures", id);
  const v = hand.variants.indexOf(id);
  if (v >= 0) {
    await track((async () => {
      for (const mesh of hand.meshes) {
        const mappings = mesh.userData.gltfExtensions?.KHR_materials_variants?.mappings || [];
        const mapping = mappings.find((m) => m.variants.includes(v));
        if (!mapping) continue;
        let material = hand.materials.get(mapping.material);
        if (!material) {
          material = await hand.gltf.parser.getDependency("material", mapping.material);
          prepareSkin(material);
          hand.materials.set(mapping.material, material);
        }
        mesh.material = material;
      }
    })());
  }
  requestDraw();
  metrics.texture_ms.push(performance.now() - t0);
}

// -------------------------------------------------------------------------------------------------- accessories

async function selectAccessory(id) {
  state.accessory = id;
  markSelected("accessories", id);
  if (accessory) { accessory.object.removeFromParent(); accessory = null; }
  if (id === "none") { applyPose(); return; }
  const side = state.side;
  const gltf = await track(loader.loadAsync(`/media/accessory/${side}/${id}.glb`));
  if (state.accessory !== id || state.side !== side) return;
  let node = null;
  gltf.scene.traverse((o) => { if (!node && o.userData?.darthand?.accessory === id) node = o; });
  if (!node) throw new Error(`accessory ${id}: no node in its glTF`);
  const meshes = [];
  node.traverse((o) => { if (o.isMesh) { meshes.push(o); o.frustumCulled = false; } });
  const skinned = meshes.some((m) => m.isSkinnedMesh);
  if (skinned) {
    // A glove: bind it to the hand's skeleton (same joints, same bind matrices) and drive its correctives.
    const handMesh = hand.meshes[0];
    for (const m of meshes) if (m.isSkinnedMesh) m.bind(handMesh.skeleton, handMesh.bindMatrix);
    node.removeFromParent();
    hand.root.add(node);
  } else {
    // A rigid accessory: its mesh sits in its joint's bone frame, so it goes under the hand's joint node as it is.
    const parent = node.parent;
    node.removeFromParent();
    hand.bones[parent.name].add(node);
  }
  accessory = { id, object: node, skinned, meshes };
  applyPose();
}

// -------------------------------------------------------------------------------------------------- objects

/** Hold object `id` in grasp `graspId` (its first grasp for the side when not given or not offered): the server
 * refits the grasp to this side's hand; its joint angles pose the hand (unless keepAngles) and its placement puts the
 * object in the hand's model frame. "none" (or an object without a grasp for the side) empties the hand. */
async function selectObject(id, graspId = null, { keepAngles = false } = {}) {
  const side = state.side;
  const entry = objects?.objects.find((o) => o.id === id);
  const grasps = entry?.grasps[side] || [];
  const grasp = grasps.find((g) => g.id === graspId) || grasps[0];
  if (held) { held.object.removeFromParent(); held = null; }
  markSelected("objects", grasp ? id : "none");
  fillGrasps(grasps, grasp?.id);
  if (!grasp) {
    const had = state.object !== null;
    state.object = null;
    if (had && !keepAngles) setAngles(R.zeroAngles());
    requestDraw();
    return;
  }
  state.object = { id, grasp: grasp.id };
  const [doc, mesh] = await Promise.all([postJSON("/api/grasp", { side, object: id, grasp: grasp.id }), objectMesh(id)]);
  if (state.object?.grasp !== grasp.id || state.side !== side) return;
  if (held) held.object.removeFromParent();
  const object = objectGroup(mesh);
  object.matrixAutoUpdate = false;
  scene.add(object);
  const graspRoot = R.manoRotations(hand.rig, doc.angles_deg)[0];
  held = { id, grasp: grasp.id, object, placement: doc.placement, pivot: doc.pivot, graspRoot };
  if (!keepAngles) setAngles(doc.angles_deg);
  placeHeld();
  setStatus(`${id}: ${doc.type} grasp${doc.ok ? "" : " (outside the catalogue's bounds)"}, ` +
    `penetration ${doc.penetration_max_mm.toFixed(2)} mm`);
  requestDraw();
}

/** Put the held object where the shown hand holds it: the grasp's placement carried by the root joint's rotation
 * since the grasp, about the root's rest centre (studio/objects.held_placement: the export places it the same).
 * root: the root joint's rotation under state.angles, when the caller has it. */
function placeHeld(root = R.manoRotations(hand.rig, state.angles)[0]) {
  if (!held) return;
  const D = R.mul(root, R.transpose(held.graspRoot));
  const c = held.pivot, P = held.placement;
  const Dc = D.map((row) => row[0] * c[0] + row[1] * c[1] + row[2] * c[2]);
  const motion = new THREE.Matrix4().set(...D[0], c[0] - Dc[0], ...D[1], c[1] - Dc[1], ...D[2], c[2] - Dc[2], 0, 0, 0, 1);
  held.object.matrix.multiplyMatrices(motion, new THREE.Matrix4().set(...P[0], ...P[1], ...P[2], ...P[3]));
  held.object.matrixWorldNeedsUpdate = true;
}

function objectMesh(id) {
  if (!objectMeshes[id]) objectMeshes[id] = track(getJSON(`/api/object/${encodeURIComponent(id)}`));
  return objectMeshes[id];
}

/** A THREE.Group of the object's drawn parts (object frame, metres), each in its base colour. */
function objectGroup(mesh) {
  const group = new THREE.Group();
  group.userData.darthand = { object: mesh.id };
  for (const p of mesh.parts) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.Float32BufferAttribute(p.positions, 3));
    geometry.setAttribute("normal", new THREE.Float32BufferAttribute(p.normals, 3));
    geometry.setIndex(p.indices);
    const material = new THREE.MeshStandardMaterial({ color: new THREE.Color().setRGB(...p.color),
      roughness: p.roughness, metalness: p.metallic });
    if (p.albedo) {
      // uvs in the renderer's convention (render/texture.py: v = 0 at the image's bottom row), as a TextureLoader
      // texture's default flipY reads them
      geometry.setAttribute("uv", new THREE.Float32BufferAttribute(p.uvs, 2));
      material.map = objectAlbedo(mesh.id);
    }
    group.add(new THREE.Mesh(geometry, material));
  }
  return group;
}

function objectAlbedo(id) {
  const texture = new THREE.TextureLoader().load(`/media/object/${encodeURIComponent(id)}/albedo.png`, requestDraw);
  texture.colorSpace = THREE.SRGBColorSpace;
  return texture;
}

function fillGrasps(grasps, selected) {
  const select = $("obj-grasp");
  select.replaceChildren(...grasps.map((g) => new Option(`${g.type} (approach ${g.approach})`, g.id)));
  if (selected) select.value = selected;
  select.disabled = !grasps.length;
}

async function buildObjects() {
  objects = await getJSON("/api/objects");
  $("object-panel").hidden = false;
  for (const c of objects.categories) $("obj-category").append(new Option(c, c));
  const grid = $("objects");
  const none = figure(null, "none", () => guarded(selectObject("none")));
  none.classList.add("selected");
  grid.append(none);
  for (const o of objects.objects) {
    const fig = figure(`/media/object/${encodeURIComponent(o.id)}.png`, o.id, () => guarded(selectObject(o.id)));
    fig.dataset.category = o.category;
    grid.append(fig);
  }
  $("obj-category").addEventListener("change", () => {
    const c = $("obj-category").value;
    for (const fig of grid.children) fig.hidden = Boolean(c) && fig.dataset.id !== "none" && fig.dataset.category !== c;
  });
  $("obj-grasp").addEventListener("change", (e) => state.object && guarded(selectObject(state.object.id, e.target.value)));
}

// -------------------------------------------------------------------------------------------------- lights

function updateLights() {
  const a = state.ambient, k = state.key, lit = state.environment.id === null;
  // darthand's intensities have pi folded in (schemas/lights.schema.json); three.js's Lambert term divides by pi.
  // An environment replaces these lights (lightsDoc sends none with it).
  ambient.color.setRGB(...a.color);
  ambient.intensity = lit ? a.intensity * PI : 0;
  key.color.setRGB(...k.color);
  key.intensity = lit ? k.intensity * PI : 0;
  const d = keyDirectionCamera();
  camera.updateMatrixWorld();
  // camera frame (OpenCV: x right, y down, z forward) -> three.js camera axes (x right, y up, z back) -> world
  const world = new THREE.Vector3(d[0], -d[1], -d[2]).applyQuaternion(camera.quaternion);
  key.target.position.copy(controls ? controls.target : new THREE.Vector3());
  key.position.copy(key.target.position).addScaledVector(world, -1);
  key.target.updateMatrixWorld();
}

/** The key light's travel direction in the camera frame, from azimuth (toward the image's right) and elevation. */
function keyDirectionCamera() {
  const az = state.key.azimuth * PI / 180, el = state.key.elevation * PI / 180;
  const toward = [Math.sin(az) * Math.cos(el), -Math.sin(el), -Math.cos(az) * Math.cos(el)];
  return toward.map((x) => -x);
}

function lightsDoc() {
  const r = (v) => v.map((x) => +x.toFixed(5));
  if (state.environment.id !== null) return { ambient: { color: [1, 1, 1], intensity: 0 }, lights: [], environment: environmentDoc() };
  return {
    ambient: { color: r(state.ambient.color), intensity: +state.ambient.intensity },
    lights: [{ type: "directional", direction: r(keyDirectionCamera()), color: r(state.key.color),
      intensity: +state.key.intensity, shadows: true, frame: "camera" }],
  };
}

// -------------------------------------------------------------------------------------------------- environment

const hdrLoader = new HDRLoader();
const environmentMaps = {};          // id -> promise of {equirect, pmrem}: the map and its prefiltered radiance

function loadEnvironment(id) {
  if (!environmentMaps[id]) {
    environmentMaps[id] = (async () => {
      const equirect = await hdrLoader.loadAsync(`/media/environment/${encodeURIComponent(id)}.hdr`);
      equirect.mapping = THREE.EquirectangularReflectionMapping;
      return { equirect, pmrem: pmrem.fromEquirectangular(equirect).texture };
    })();
    environmentMaps[id].catch(() => { delete environmentMaps[id]; });
  }
  return environmentMaps[id];
}

/** Light the live view with a map ("none": the Lights panel's lights). */
async function selectEnvironment(id) {
  const t0 = performance.now();
  const chosen = id === "none" ? null : id;
  if (chosen !== null) await track(loadEnvironment(chosen));      // a map that fails leaves the choice as it was
  state.environment.id = chosen;
  markSelected("environments", id);
  await updateEnvironment();
  draw();
  metrics.environment_ms.push(performance.now() - t0);
}

/** The environment in the live view, placed as issue 28's contract places it in frame "world": direction d is
 * looked up at d_E = (d.x, -d.z, d.y) turned by -rotation about E_z (= world +Y), the map's centre column along
 * -E_x. three.js looks d up with its centre column along +X and scene.*Rotation's Euler R as R^T d, so the two
 * agree for a rotation of (rotation - 180) degrees about Y. */
async function updateEnvironment() {
  const env = state.environment;
  const maps = env.id === null ? null : await track(loadEnvironment(env.id));
  scene.environment = maps ? maps.pmrem : null;
  scene.environmentIntensity = env.strength;
  scene.environmentRotation.set(0, (env.rotation - 180) * PI / 180, 0);
  scene.backgroundRotation.copy(scene.environmentRotation);
  await updateBackground();
}

/** The lights document's environment field (schemas/lights.schema.json): the studio's scenes use frame "world"
 * because its camera orbits the hand while the surroundings stay put. */
function environmentDoc() {
  const env = state.environment;
  return { map: env.id, rotation: +env.rotation, strength: +env.strength, frame: "world" };
}

// -------------------------------------------------------------------------------------------------- film

/** The Image settings panel as a film dict (render/film.Film's fields; exposure_ev left out: automatic), or null:
 * the clean image. */
function filmDoc() {
  if (!$("film-on").checked) return null;
  const film = {};
  if (!$("film-auto").checked) film.exposure_ev = +$("film-ev").value;
  const fields = { iso: "film-iso", defocus_px: "film-defocus", motion_blur_px: "film-motion", jpeg_quality: "film-jpeg" };
  for (const [name, id] of Object.entries(fields)) if (+$(id).value) film[name] = +$(id).value;
  return film;
}

function showFilm(film) {
  $("film-on").checked = !!film;
  if (!film) return;
  $("film-auto").checked = typeof film.exposure_ev !== "number";
  setRange("film-ev", film.exposure_ev ?? 0);
  $("film-iso").value = String(film.iso ?? 0);
  setRange("film-defocus", film.defocus_px ?? 0);
  setRange("film-motion", film.motion_blur_px ?? 0);
  $("film-jpeg").value = String(film.jpeg_quality ?? 0);
}

// -------------------------------------------------------------------------------------------------- background

const backgroundTextures = {};
async function updateBackground() {
  const bg = state.background, env = state.environment;
  scene.backgroundIntensity = 1;
  scene.backgroundBlurriness = 0;
  if (env.background && env.id !== null) {
    const maps = await track(loadEnvironment(env.id));
    // three.js blurs a PMREM background by GGX roughness r, a lobe about r^2 radians wide: r = sqrt(blur in radians)
    const roughness = Math.sqrt(env.blur * PI / 180);
    scene.background = roughness > 0 ? maps.pmrem : maps.equirect;
    scene.backgroundBlurriness = Math.min(1, roughness);
    scene.backgroundIntensity = env.strength;
  } else if (bg.kind === "color") scene.background = new THREE.Color().setRGB(...bg.color);
  else if (bg.kind === "builtin" || bg.kind === "image") {
    const url = `/media/background/${bg.kind}/${bg.kind === "builtin" ? bg.builtin : bg.image}.png`;
    if (!backgroundTextures[url]) {
      const tex = await track(new THREE.TextureLoader().loadAsync(url));
      tex.colorSpace = THREE.SRGBColorSpace;
      backgroundTextures[url] = tex;
    }
    scene.background = backgroundTextures[url];
  } else scene.background = null;
  requestDraw();
}

function backgroundDoc() {
  const bg = state.background;
  if (state.environment.background && state.environment.id !== null) return { environment: { blur: +state.environment.blur } };
  if (bg.kind === "color") return { color: bg.color.map((x) => +x.toFixed(5)) };
  if (bg.kind === "builtin") return { builtin: bg.builtin };
  if (bg.kind === "image") return { image: bg.image };
  return null;
}

// -------------------------------------------------------------------------------------------------- camera

async function setView(view) {
  const doc = await postJSON("/api/camera", { side: state.side, angles_deg: state.angles, view, size: state.renderSize,
    ...(state.accessory !== "none" ? { accessory: state.accessory } : {}), ...(state.object ? { object: state.object } : {}) });
  setCamera(doc);
}

/** Place the three.js camera where a darthand camera (K, R world -> OpenCV camera, t) is. */
function setCamera(doc) {
  const Rm = doc.R, t = doc.t;
  const centre = [0, 1, 2].map((j) => -(Rm[0][j] * t[0] + Rm[1][j] * t[1] + Rm[2][j] * t[2]));
  const x = new THREE.Vector3(...Rm[0]), y = new THREE.Vector3(...Rm[1]).negate(), z = new THREE.Vector3(...Rm[2]).negate();
  camera.position.fromArray(centre);
  camera.quaternion.setFromRotationMatrix(new THREE.Matrix4().makeBasis(x, y, z));
  camera.up.copy(y);
  camera.fov = 2 * Math.atan(0.5 * doc.height / doc.K[1][1]) * 180 / PI;
  camera.updateProjectionMatrix();
  if (controls) controls.dispose();
  controls = new OrbitControls(camera, renderer.domElement);     // made again: it keeps the camera's up from here
  controls.target.fromArray(doc.target);
  controls.enableDamping = false;
  controls.addEventListener("change", requestDraw);
  controls.update();
  requestDraw();
}

/** The live camera as a darthand camera document for a square image of `size` pixels. */
function cameraDoc(size) {
  camera.updateMatrixWorld();
  const e = camera.matrixWorldInverse.elements;      // column-major; rows: camera x, y, z axes (three.js)
  const s = [1, -1, -1];                             // three.js camera axes -> OpenCV's (y down, z forward)
  const Rm = [0, 1, 2].map((i) => [0, 1, 2].map((j) => s[i] * e[j * 4 + i]));
  const t = [0, 1, 2].map((i) => s[i] * e[12 + i]);
  const f = 0.5 * size / Math.tan(camera.fov * PI / 360);
  return { width: size, height: size, K: [[f, 0, size / 2], [0, f, size / 2], [0, 0, 1]], R: Rm, t };
}

// -------------------------------------------------------------------------------------------------- scene, render

function sceneDoc(extra = {}) {
  const doc = { side: state.side, angles_deg: state.angles, skin_tone_offset: +state.skinTone,
    accessory: state.accessory, camera: cameraDoc(state.renderSize), lights: lightsDoc(), background: backgroundDoc(),
    ...extra };
  if (state.texture) doc.texture = state.texture;
  if (state.object) doc.object = { ...state.object };
  const film = filmDoc();
  if (film) doc.film = film;
  return doc;
}

async function renderReference() {
  setStatus("rendering...");
  const t0 = performance.now();
  state.lastRequest = sceneDoc();
  const result = await postJSON("/api/render", state.lastRequest);
  await showRender(result);
  metrics.render_ms.push(performance.now() - t0);
  setStatus(`rendered ${result.size} px in ${result.seconds.toFixed(2)} s (round trip ${((performance.now() - t0) / 1000).toFixed(2)} s)`);
  return result;
}

async function showRender(result) {
  const image = await loadImage(`data:image/png;base64,${result.image}`);
  $("render-mask").src = `data:image/png;base64,${result.mask}`;
  const canvas = $("render-image"), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.drawImage(image, 0, 0, canvas.width, canvas.height);
  const labels = result.labels;
  if ($("show-keypoints").checked && labels.keypoints_2d) {
    const k = canvas.width / result.size, p = labels.keypoints_2d;
    ctx.lineWidth = 2;
    OPENPOSE_BONES.forEach(([a, b], n) => {
      ctx.strokeStyle = FINGER_COLOURS[Math.floor(n / 4)];
      ctx.beginPath(); ctx.moveTo(p[a][0] * k, p[a][1] * k); ctx.lineTo(p[b][0] * k, p[b][1] * k); ctx.stroke();
    });
    p.forEach(([u, v], i) => {
      ctx.fillStyle = labels.visibility?.[i] ? "#ffffff" : "#777777";
      ctx.beginPath(); ctx.arc(u * k, v * k, 3, 0, 2 * PI); ctx.fill();
    });
  }
  const shown = { ...labels };
  for (const big of ["keypoints_3d_world", "joints_3d_world"]) delete shown[big];
  $("render-labels").textContent = JSON.stringify(shown, null, 1);
  state.lastRender = result;
}

/** Load a saved scene: a studio scene (schemas/studio_scene.schema.json) or a scene export (its studio.scene). */
async function loadScene(doc) {
  const s = doc?.studio?.scene || doc;
  if (!s || !Array.isArray(s.angles_deg)) throw new Error("load scene: not a studio scene or scene export");
  if (s.side && s.side !== state.side && catalogue.sides.includes(s.side)) await showSide(s.side);
  if (s.texture) await selectTexture(s.texture);
  state.skinTone = skinTone.value = s.skin_tone_offset ?? 0;
  setRange("skin-tone", state.skinTone);
  await selectAccessory(s.accessory || "none");
  if (objects) await selectObject(s.object?.id || "none", s.object?.grasp, { keepAngles: true });
  setAngles(s.angles_deg);
  showLights(s.lights);
  showBackground(s.background);
  showFilm(s.film);
  state.film = filmDoc();
  if (s.camera) {
    state.renderSize = s.camera.width;
    $("render-size").value = String(s.camera.width);
    const centre = [0, 1, 2].map((j) => -(s.camera.R[0][j] * s.camera.t[0] + s.camera.R[1][j] * s.camera.t[1] + s.camera.R[2][j] * s.camera.t[2]));
    const distance = controls ? camera.position.distanceTo(controls.target) : 0.4;
    setCamera({ ...s.camera, target: centre.map((c, i) => c + distance * s.camera.R[2][i]) });
  }
  await updateEnvironment();
}

/** The Lights and Environment panels from a lights document (null: the default rig, panels left as they are). */
function showLights(lights) {
  if (!lights) return;
  const env = lights.environment, e = state.environment;
  Object.assign(e, { id: env ? env.map : null, rotation: env?.rotation ?? 0, strength: env?.strength ?? 1 });
  setRange("env-rotation", e.rotation);
  setRange("env-strength", e.strength);
  markSelected("environments", env ? env.map : "none");
  if (env) return;                                  // its ambient and lights are off: keep the panel's
  const setColour = (which, rgb) => { $(`${which}-color`).value = "#" + new THREE.Color().setRGB(...rgb).getHexString(); };
  state.ambient = { color: lights.ambient?.color ?? [1, 1, 1], intensity: lights.ambient?.intensity ?? 0 };
  setColour("ambient", state.ambient.color);
  setRange("ambient-intensity", state.ambient.intensity);
  const k = (lights.lights || []).find((l) => l.type === "directional" && l.frame === "camera");
  if (!k) return;
  const n = Math.hypot(...k.direction), toward = k.direction.map((x) => -x / n);      // keyDirectionCamera, inverted
  Object.assign(state.key, { color: k.color ?? [1, 1, 1], intensity: k.intensity ?? 1,
    elevation: Math.asin(-toward[1]) * 180 / PI, azimuth: Math.atan2(toward[0], -toward[2]) * 180 / PI });
  setColour("key", state.key.color);
  for (const f of ["intensity", "azimuth", "elevation"]) setRange(`key-${f}`, state.key[f]);
}

function showBackground(bg) {
  const e = state.environment;
  e.background = !!bg?.environment;
  $("env-background").checked = e.background;
  if (bg?.environment) { e.blur = bg.environment.blur ?? 0; setRange("env-blur", e.blur); return; }
  const kind = !bg ? "none" : bg.color ? "color" : bg.builtin !== undefined ? "builtin" : "image";
  document.querySelector(`input[name=bg][value=${kind}]`).checked = true;
  if (kind === "color") $("bg-color").value = "#" + new THREE.Color().setRGB(...bg.color).getHexString();
  if (kind === "builtin") $("bg-builtin").value = String(bg.builtin);
  if (kind === "image") $("bg-image").value = String(bg.image);
  state.background = kind === "none" ? { kind } : { kind, ...bg };
}

// -------------------------------------------------------------------------------------------------- exports

async function exportKind(kind, body) {
  const result = await postJSON(`/api/export/${kind}`, body);
  const blob = new Blob([JSON.stringify(result.document, null, 2)], { type: "application/json" });
  const name = result.path.split("/").pop();
  $("export-result").innerHTML = "";
  const a = Object.assign(document.createElement("a"), { href: URL.createObjectURL(blob), download: name,
    textContent: `download ${name}` });
  $("export-result").append(`written ${result.path} `, a);
  return result;
}

// -------------------------------------------------------------------------------------------------- undo, mirror

function snapshot() { return state.angles.map((a) => a.slice()); }

function commit() {
  const now = snapshot();
  if (history.committed && JSON.stringify(history.committed) === JSON.stringify(now)) return;
  if (history.committed) history.undo.push(history.committed);
  history.committed = now;
  history.redo = [];
  updateUndoButtons();
}

function undo() { travel(history.undo, history.redo); }
function redo() { travel(history.redo, history.undo); }

// Undo and redo: the current pose goes onto one stack, the pose popped from the other becomes current.
function travel(from, to) {
  if (!from.length) return;
  to.push(snapshot());
  history.committed = from.pop();
  setAngles(history.committed, { record: false });
  updateUndoButtons();
}

function updateUndoButtons() {
  $("undo").disabled = !history.undo.length;
  $("redo").disabled = !history.redo.length;
}

/** The other hand in the mirror-image pose: the anatomical angles are mirror-symmetric (model/anatomy.py), so
 * they carry over unchanged. */
async function mirror() {
  const other = state.side === "right" ? "left" : "right";
  if (!catalogue.sides.includes(other)) return;
  await showSide(other);
  await setView("three_quarter");
}

// -------------------------------------------------------------------------------------------------- animation

function startAnimation() {
  const g = hand.rig.gestures;
  anim.from = R.manoRotations(hand.rig, g[$("anim-from").value]);
  anim.to = R.manoRotations(hand.rig, g[$("anim-to").value]);
  anim.playing = true;
  anim.last = performance.now();
}

function animationPose(t) {
  if (!anim.from) {
    const g = hand.rig.gestures;
    anim.from = R.manoRotations(hand.rig, g[$("anim-from").value]);
    anim.to = R.manoRotations(hand.rig, g[$("anim-to").value]);
  }
  $("anim-t").value = t;
  $("anim-t").nextElementSibling.value = (+t).toFixed(2);
  setAngles(R.anglesOf(hand.rig, R.slerpRotations(anim.from, anim.to, t)), { record: false });
}

function loop(now) {
  if (anim.playing) {
    anim.phase = (anim.phase + (now - anim.last) / 1000 * anim.speed) % 2;
    anim.last = now;
    animationPose(1 - Math.abs(1 - anim.phase));            // there and back
  }
  if (drawRequested) draw();
  requestAnimationFrame(loop);
}

// -------------------------------------------------------------------------------------------------- drawing

function requestDraw() { drawRequested = true; }

function draw() {
  drawRequested = false;
  const t0 = performance.now();
  updateLights();
  renderer.render(scene, camera);
  if (inputTime !== null && window.studio.measure) {
    const gl = renderer.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));   // wait for the frame to be drawn
    const now = performance.now();
    metrics.redraw_ms.push(now - inputTime);      // input event to finished frame (includes waiting for the frame)
    metrics.draw_ms.push(now - t0);               // the draw itself
  }
  inputTime = null;
}

/** The live view's silhouette at the live camera: (size x size) 0/1 bytes, rows top to bottom, base64. */
function silhouette(size) {
  const target = new THREE.WebGLRenderTarget(size, size);
  const background = scene.background;
  scene.background = new THREE.Color(0, 0, 0);
  scene.overrideMaterial = new THREE.MeshBasicMaterial({ color: 0xffffff, side: THREE.DoubleSide });
  renderer.setRenderTarget(target);
  renderer.render(scene, camera);
  const pixels = new Uint8Array(4 * size * size);
  renderer.readRenderTargetPixels(target, 0, 0, size, size, pixels);
  renderer.setRenderTarget(null);
  scene.overrideMaterial = null;
  scene.background = background;
  target.dispose();
  const mask = new Uint8Array(size * size);
  for (let r = 0; r < size; r++) for (let c = 0; c < size; c++) {
    mask[r * size + c] = pixels[4 * ((size - 1 - r) * size + c)] > 127 ? 1 : 0;
  }
  requestDraw();
  return bytesToBase64(mask);
}

/** Vertex positions three.js computes for the hand primitive (morph targets, then skinning) and their model
 * vertex ids (_VERTEX_ID). */
function livePositions() {
  scene.updateMatrixWorld(true);
  const mesh = hand.meshes.find((m) => m.geometry.attributes._vertex_id && m.geometry.attributes.position.count) || hand.meshes[0];
  mesh.skeleton.update();
  const n = mesh.geometry.attributes.position.count, v = new THREE.Vector3(), out = new Array(3 * n);
  for (let i = 0; i < n; i++) {
    mesh.getVertexPosition(i, v).applyMatrix4(mesh.matrixWorld);
    out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
  }
  const ids = mesh.geometry.attributes._vertex_id;
  return { positions: out, ids: ids ? Array.from(ids.array) : null };
}

// -------------------------------------------------------------------------------------------------- panels

function buildPanels() {
  buildTextures();
  buildAccessories();
  if (catalogue.objects) guarded(buildObjects());
  buildLights();
  buildEnvironments();
  buildBackground();
  for (const view of catalogue.views) addButton($("views"), view, () => setView(view));
  $("render-size").addEventListener("change", (e) => { state.renderSize = +e.target.value; });
  buildSliders();
  $("undo").addEventListener("click", undo);
  $("redo").addEventListener("click", redo);
  $("mirror").addEventListener("click", () => guarded(mirror()));
  $("reset").addEventListener("click", () => setAngles(R.zeroAngles()));
  document.addEventListener("keydown", (e) => {
    if (!(e.ctrlKey || e.metaKey)) return;
    if (e.key === "z") { e.preventDefault(); undo(); }
    if (e.key === "y") { e.preventDefault(); redo(); }
  });
  $("anim-play").addEventListener("click", startAnimation);
  $("anim-pause").addEventListener("click", () => { anim.playing = false; commit(); });
  bindRange("anim-speed", (v) => { anim.speed = v; });
  bindRange("anim-t", (v) => { anim.playing = false; animationPose(v); }, () => commit());
  for (const id of ["anim-from", "anim-to"]) $(id).addEventListener("change", () => { anim.from = null; });
  $("export-pose").addEventListener("click", () => guarded(exportKind("pose", { side: state.side, angles_deg: state.angles })));
  $("add-pose").addEventListener("click", () => { state.poseList.push(snapshot()); $("pose-count").textContent = state.poseList.length; });
  $("export-poses").addEventListener("click", () => state.poseList.length && guarded(exportKind("poses", { poses: state.poseList })));
  $("export-scene").addEventListener("click", () => guarded(exportKind("scene", sceneDoc())));
  $("render").addEventListener("click", () => guarded(renderReference()));
  $("load-scene").addEventListener("change", (e) => e.target.files[0] && guarded(e.target.files[0].text().then((text) => loadScene(JSON.parse(text)))));
  $("show-keypoints").addEventListener("change", () => state.lastRender && showRender(state.lastRender));
}

function buildTextures() {
  const cats = [...new Set(catalogue.textures.map((t) => t.category))].sort();
  const tones = [...new Set(catalogue.textures.map((t) => t.tone))].sort();
  for (const c of cats) $("tex-category").append(new Option(c, c));
  for (const t of tones) $("tex-tone").append(new Option(t, t));
  const grid = $("textures");
  for (const t of catalogue.textures) {
    const fig = figure(`/media/texture/${catalogue.sides[0]}/${t.id}.png`, t.id, () => guarded(selectTexture(t.id)));
    fig.dataset.category = t.category;
    fig.dataset.tone = t.tone;
    grid.append(fig);
  }
  const filter = () => {
    const c = $("tex-category").value, tone = $("tex-tone").value;
    for (const fig of grid.children) fig.hidden = (c && fig.dataset.category !== c) || (tone && fig.dataset.tone !== tone);
  };
  $("tex-category").addEventListener("change", filter);
  $("tex-tone").addEventListener("change", filter);
  bindRange("skin-tone", (v) => { state.skinTone = v; skinTone.value = v; requestDraw(); });
}

function buildAccessories() {
  const grid = $("accessories");
  const none = figure(null, "none", () => guarded(selectAccessory("none")));
  none.classList.add("selected");
  grid.append(none);
  for (const a of catalogue.accessories) {
    grid.append(figure(`/media/accessory/${catalogue.sides[0]}/${a.id}.png`, a.id, () => guarded(selectAccessory(a.id))));
  }
}

function figure(src, id, onClick) {
  const fig = document.createElement("figure");
  fig.dataset.id = id;
  fig.title = id;
  const img = document.createElement(src ? "img" : "div");
  img.className = "thumb";
  if (src) Object.assign(img, { loading: "lazy", alt: id, src });
  fig.append(img, Object.assign(document.createElement("figcaption"), { textContent: id }));
  fig.addEventListener("click", onClick);
  return fig;
}

function markSelected(gridId, id) {
  for (const fig of $(gridId).children) fig.classList.toggle("selected", fig.dataset.id === id);
}

function buildLights() {
  for (const [which, target] of [["ambient", state.ambient], ["key", state.key]]) {
    const select = $(`${which}-palette`), input = $(`${which}-color`);
    select.append(new Option("white", "1,1,1"));
    for (const p of catalogue.palette) select.append(new Option(`${p.name} (${p.kelvin} K)`, p.rgb.join(",")));
    const setColour = (rgb) => { target.color = rgb; input.value = "#" + new THREE.Color().setRGB(...rgb).getHexString(); requestDraw(); };
    select.addEventListener("change", () => setColour(select.value.split(",").map(Number)));
    input.addEventListener("input", () => { const c = new THREE.Color(input.value); target.color = [c.r, c.g, c.b]; requestDraw(); });
    setColour(target.color);
    bindRange(`${which}-intensity`, (v) => { target.intensity = v; requestDraw(); });
  }
  bindRange("key-azimuth", (v) => { state.key.azimuth = v; requestDraw(); });
  bindRange("key-elevation", (v) => { state.key.elevation = v; requestDraw(); });
}

function buildEnvironments() {
  const grid = $("environments");
  const none = figure(null, "none", () => guarded(selectEnvironment("none")));
  none.classList.add("selected");
  grid.append(none);
  for (const env of environments) {
    const fig = figure(env.usable ? `/media/environment/${encodeURIComponent(env.id)}.png` : null, env.id,
      () => env.usable && guarded(selectEnvironment(env.id)));
    if (!env.usable) { fig.classList.add("unusable"); fig.title = `${env.id}: ${env.reason}`; }
    grid.append(fig);
  }
  const env = state.environment;
  bindRange("env-rotation", (v) => { env.rotation = v; guarded(updateEnvironment()); });
  bindRange("env-strength", (v) => { env.strength = v; guarded(updateEnvironment()); });
  bindRange("env-blur", (v) => { env.blur = v; guarded(updateBackground()); });
  $("env-background").addEventListener("change", (e) => { env.background = e.target.checked; guarded(updateBackground()); });
  for (const id of ["film-on", "film-auto", "film-iso", "film-jpeg"]) $(id).addEventListener("change", () => { state.film = filmDoc(); });
  bindRange("film-ev", () => { $("film-auto").checked = false; state.film = filmDoc(); });
  bindRange("film-defocus", () => { state.film = filmDoc(); });
  bindRange("film-motion", () => { state.film = filmDoc(); });
}

function buildBackground() {
  for (let k = 0; k < catalogue.backgrounds.builtin; k++) $("bg-builtin").append(new Option(`built-in ${k}`, k));
  catalogue.backgrounds.images.forEach((name, k) => $("bg-image").append(new Option(name, k)));
  const update = () => {
    const kind = document.querySelector("input[name=bg]:checked").value;
    const c = new THREE.Color($("bg-color").value);
    state.background = kind === "color" ? { kind, color: [c.r, c.g, c.b] }
      : kind === "builtin" ? { kind, builtin: +$("bg-builtin").value }
        : kind === "image" && catalogue.backgrounds.images.length ? { kind, image: +$("bg-image").value } : { kind: "none" };
    guarded(updateBackground());
  };
  for (const el of document.querySelectorAll("input[name=bg]")) el.addEventListener("change", update);
  for (const id of ["bg-color", "bg-builtin", "bg-image"]) $(id).addEventListener("input", update);
}

function buildSliders() {
  const box = $("sliders");
  const head = document.createElement("div");
  head.className = "joint";
  head.innerHTML = "<span></span><span class='axis-head'>twist</span><span class='axis-head'>spread</span><span class='axis-head'>bend</span>";
  box.append(head);
  for (let j = 0; j < R.NUM_JOINTS; j++) {
    const row = document.createElement("div");
    row.className = "joint";
    row.append(Object.assign(document.createElement("span"), { className: "joint-name" }));
    for (let a = 0; a < 3; a++) {
      const input = Object.assign(document.createElement("input"), { type: "range", step: "0.5", value: "0" });
      input.id = `slider-${j}-${a}`;
      input.dataset.joint = j;
      input.dataset.axis = a;
      input.addEventListener("input", () => {
        inputTime = performance.now();
        anim.playing = false;
        state.angles[j][a] = +input.value;
        input.title = `${input.value} deg`;
        applyPose();
      });
      input.addEventListener("change", commit);
      row.append(input);
    }
    box.append(row);
  }
}

/** Slider ranges, names and values for the shown hand's rig. */
function syncSliders() {
  const rig = hand.rig;
  document.querySelectorAll(".joint-name").forEach((el, j) => { el.textContent = rig.joints[j]; });
  for (let j = 0; j < R.NUM_JOINTS; j++) for (let a = 0; a < 3; a++) {
    const input = $(`slider-${j}-${a}`);
    input.min = rig.limits_deg[j][a][0];
    input.max = rig.limits_deg[j][a][1];
    input.value = state.angles[j][a];
    input.title = `${rig.joints[j]} ${rig.axes[a]} ${(+state.angles[j][a]).toFixed(1)} deg`;
  }
}

function fillGestures() {
  const box = $("gestures");
  box.innerHTML = "";
  const names = hand.rig.gesture_order;
  for (const name of names) addButton(box, name, () => { anim.playing = false; setAngles(hand.rig.gestures[name]); });
  for (const id of ["anim-from", "anim-to"]) {
    const select = $(id), keep = select.value;
    select.innerHTML = "";
    for (const name of names) select.append(new Option(name, name));
    select.value = names.includes(keep) ? keep : names[id === "anim-from" ? 0 : Math.min(2, names.length - 1)];
  }
  anim.from = null;
  syncSliders();
}

function addButton(parent, label, onClick) {
  const b = Object.assign(document.createElement("button"), { textContent: label });
  b.dataset.name = label;
  b.addEventListener("click", () => guarded(Promise.resolve(onClick())));
  parent.append(b);
  return b;
}

/** Set a range input and its output without firing its handlers. */
function setRange(id, value) {
  const input = $(id), out = input.nextElementSibling;
  input.value = value;
  if (out?.tagName === "OUTPUT") out.value = (+input.value).toFixed(2);
}

function bindRange(id, onInput, onChange) {
  const input = $(id), out = input.nextElementSibling;
  const show = () => { if (out?.tagName === "OUTPUT") out.value = (+input.value).toFixed(2); };
  input.addEventListener("input", () => { show(); onInput(+input.value); });
  if (onChange) input.addEventListener("change", onChange);
  show();
}

// -------------------------------------------------------------------------------------------------- plumbing

async function getJSON(url) {
  const r = await fetch(url);
  const doc = await r.json();
  if (!r.ok) throw new Error(doc.error || `${url}: HTTP ${r.status}`);
  return doc;
}

async function postJSON(url, body) {
  const r = await track(fetch(url, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) }));
  const doc = await r.json();
  if (!r.ok) throw new Error(doc.error || `${url}: HTTP ${r.status}`);
  return doc;
}

function track(promise) {
  pending.add(promise);
  const done = () => pending.delete(promise);
  promise.then(done, done);
  return promise;
}

async function idle() {
  while (pending.size) await Promise.allSettled([...pending]);
  draw();
}

/** Run a user action: tracked (idle() waits for it), its failure shown in the status line. */
function guarded(promise) {
  return track(promise).catch((e) => { setStatus(e.message, true); window.studio.errors.push(e.message); });
}

function setStatus(text, error = false) {
  $("status").textContent = text;
  $("status").classList.toggle("error", error);
}

function loadImage(src) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error("image did not decode"));
    img.src = src;
  });
}

function bytesToBase64(bytes) {
  let s = "";
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  return btoa(s);
}

function capture() {
  renderer.render(scene, camera);
  return renderer.domElement.toDataURL("image/png");
}

window.studio = {
  state, metrics, measure: false, errors: [], idle, capture, silhouette, livePositions, sceneDoc, cameraDoc,
  manoPose: () => R.axisAngles(R.manoRotations(hand.rig, state.angles)),
  selectTexture, selectAccessory, selectObject, objects: () => objects, setView, renderReference, mirror, undo, redo, selectEnvironment, loadScene,
  environments: () => environments,
};
window.studio.ready = start().catch((e) => { setStatus(`could not start: ${e.message}`, true); throw e; });
