// topomech viewer: plays the frames of a run (view.json + view.bin, inlined in the page) in
// WebGL with three.js (vendored in web/three/, inlined in the page before this script: the
// global THREE). Orbit, pan and zoom are three.js's OrbitControls. The surface is drawn from
// each frame's recorded boundary faces (a cut shows both of its sides), colored by a field on
// one scale for the whole run; a click picks the nearest vertex of the triangle under the
// pointer and shows its row, its input point_id and its fields. The dart view draws the G-map
// as in the paper's Figure 1 — each dart a short segment from near its vertex towards the
// middle of its edge, shrunk towards its face's and volume's centres, and the alpha_i links
// between darts in four colors — as instanced line segments (one instance a dart or a link),
// over the surface drawn translucent. #state's data-* attributes and window.topomechViewer say
// what is shown (for tests and scripts).
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const meta = JSON.parse($("view-meta").textContent);
  const buffer = (function () {
    const s = atob($("view-bin").textContent.replace(/\s+/g, ""));
    const bytes = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
    return bytes.buffer;
  })();
  function arr(ref) {
    const n = ref.shape.reduce((a, b) => a * b, 1);
    if (ref.dtype === "f4") return new Float32Array(buffer, ref.offset, n);
    if (ref.dtype === "i4") return new Int32Array(buffer, ref.offset, n);
    throw new Error("unknown dtype " + ref.dtype);
  }
  const frames = meta.frames;
  const origin = meta.origin || [0, 0, 0];
  const topologies = meta.topologies.map((t) => ({
    vertices: t.vertices,
    nDarts: t.darts,
    faceOffsets: arr(t.face_offsets),
    faceIndices: arr(t.face_indices),
    edges: arr(t.edges),
    pointIds: t.point_id ? arr(t.point_id) : null,
    darts: t.dart_table
      ? {
          vertex: arr(t.dart_table.vertex),
          alpha: arr(t.dart_table.alpha),
          face: arr(t.dart_table.face),
          volume: arr(t.dart_table.volume),
        }
      : null,
  }));

  const VIRIDIS = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
    [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]];
  function cmap(t) {
    if (!isFinite(t)) return [160, 160, 160];
    const s = Math.min(Math.max(t, 0), 1) * (VIRIDIS.length - 1);
    const i = Math.min(Math.floor(s), VIRIDIS.length - 2), f = s - i;
    const a = VIRIDIS[i], b = VIRIDIS[i + 1];
    return [a[0] * (1 - f) + b[0] * f, a[1] * (1 - f) + b[1] * f, a[2] * (1 - f) + b[2] * f];
  }

  // ------------------------------------------------------------------ WebGL, or not
  const canvas = $("view");
  let renderer = null;
  try {
    renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    renderer = null;
  }
  if (!renderer) {
    $("state").dataset.webgl = "false";
    window.topomechViewer = { webgl: false };
    fallback2d();
    return;
  }

  // ------------------------------------------------------------------ controls and state
  const state = $("state");
  const note = $("note");
  const ui = { frame: 0, playing: false, field: meta.default_field, wire: false, darts: false, speed: 1 };
  const scrub = $("scrub");
  scrub.max = String(frames.length - 1);
  $("title").textContent = meta.name;
  const fieldSel = $("field");
  for (const [name, f] of Object.entries(meta.fields)) {
    const o = document.createElement("option");
    o.value = name; o.textContent = f.label;
    fieldSel.appendChild(o);
  }
  { const o = document.createElement("option"); o.value = "none"; o.textContent = "none"; fieldSel.appendChild(o); }
  fieldSel.value = ui.field;
  if (meta.events.length) {
    $("events").textContent = "topology: " + meta.events.map((e) =>
      `${e.kind} at t = ${(+e.time).toPrecision(3)} s (${e.unsewn} ${meta.dimension === 3 ? "faces" : "edges"})`).join(", ");
  }

  // what tests and scripts read (see the module docstring of topomech.viewer)
  const debug = {
    webgl: false, frame: 0, topology: -1, mode: "surface", darts: 0, links: [0, 0, 0, 0],
    mapDarts: 0, picked: null, renders: 0, info: null,
  };
  window.topomechViewer = debug;

  debug.webgl = true;
  state.dataset.webgl = "true";
  renderer.setPixelRatio(window.devicePixelRatio || 1);

  // ------------------------------------------------------------------ scene and camera
  const V3 = THREE.Vector3;
  const lo = new V3(...meta.bounds.min), hi = new V3(...meta.bounds.max);
  const centre = lo.clone().add(hi).multiplyScalar(0.5);
  const radius = Math.max(lo.distanceTo(hi) / 2, 1e-9 * Math.max(1, centre.length()), 1e-12);
  const sphere = new THREE.Sphere(centre.clone(), radius * 1.01);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xffffff);
  const camera = new THREE.PerspectiveCamera(35, 1, radius / 100, radius * 100);
  const up = new V3(...meta.up).normalize();
  camera.up.copy(up);
  {
    // the old 2D viewer's view: azimuth 35 deg, elevation 25 deg about the up direction
    let front = Math.abs(up.y) > 0.7 ? new V3(0, 0, 1) : new V3(0, -1, 0);
    front.addScaledVector(up, -front.dot(up)).normalize();
    const side = new V3().crossVectors(up, front);
    const a = 35 * Math.PI / 180, e = 25 * Math.PI / 180;
    const eye = front.multiplyScalar(Math.cos(e) * Math.cos(a)).addScaledVector(side, Math.cos(e) * Math.sin(a))
      .addScaledVector(up, Math.sin(e));
    const dist = radius / Math.sin((camera.fov / 2) * Math.PI / 180) * 1.08;
    camera.position.copy(centre).addScaledVector(eye, dist);
  }
  scene.add(camera);
  scene.add(new THREE.AmbientLight(0xffffff, 0.55));
  {
    // a light from above (the up direction, a little from the side), fixed in the scene
    const sky = new THREE.DirectionalLight(0xffffff, 1.3);
    const side = Math.abs(up.x) < 0.9 ? new V3(1, 0, 0) : new V3(0, 0, 1);
    sky.position.copy(centre).addScaledVector(up, 2 * radius).addScaledVector(side, 0.8 * radius);
    sky.target.position.copy(centre);
    scene.add(sky, sky.target);
  }
  const light = new THREE.DirectionalLight(0xffffff, 1.8);
  light.position.set(0.8, 1.0, 0.5);  // a head light, above the camera's right shoulder
  camera.add(light);
  camera.add(light.target);
  light.target.position.set(0, 0, -1);

  const controls = new THREE.OrbitControls(camera, canvas);
  controls.target.copy(centre);
  controls.enableDamping = false;
  controls.maxDistance = radius * 40;
  controls.update();
  controls.saveState();

  // ------------------------------------------------------------------ colors
  // the color map's entries in three.js's linear working space (vertex colors are linear)
  const LUT_N = 256;
  const LUT = new Float32Array(3 * (LUT_N + 1));
  {
    const c = new THREE.Color();
    for (let i = 0; i <= LUT_N; i++) {
      const rgb = i < LUT_N ? cmap(i / (LUT_N - 1)) : [190, 190, 190];
      c.setRGB(rgb[0] / 255, rgb[1] / 255, rgb[2] / 255, THREE.SRGBColorSpace);
      LUT[3 * i] = c.r; LUT[3 * i + 1] = c.g; LUT[3 * i + 2] = c.b;
    }
  }
  const NONE_ENTRY = LUT_N;  // the gray of "no field" and of values that are not finite

  // ------------------------------------------------------------------ the surface
  let topoIndex = -1, topo = null;
  let posAttr = null, colorAttr = null;
  let surface = null, outline = null, wire = null;
  const surfaceMaterial = new THREE.MeshPhongMaterial({
    vertexColors: true, flatShading: true, side: THREE.DoubleSide, shininess: 12,
    specular: 0x181818, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
  });
  const outlineMaterial = new THREE.LineBasicMaterial({ color: 0x222222, transparent: true, opacity: 0.35 });
  const wireMaterial = new THREE.LineBasicMaterial({ vertexColors: true });
  const OUTLINE_FACES = 20000;

  function useTopology(k) {
    if (k === topoIndex) return;
    for (const o of [surface, outline, wire]) {
      if (o) { scene.remove(o); o.geometry.dispose(); }
    }
    topoIndex = k; topo = topologies[k];
    const nv = topo.vertices;
    posAttr = new THREE.BufferAttribute(new Float32Array(3 * nv), 3).setUsage(THREE.DynamicDrawUsage);
    colorAttr = new THREE.BufferAttribute(new Float32Array(3 * nv), 3).setUsage(THREE.DynamicDrawUsage);
    const off = topo.faceOffsets, idx = topo.faceIndices, nf = off.length - 1;
    // the polygons as triangle fans; their sides (not the fans' diagonals) as the outline
    let nt = 0, ne = 0;
    for (let f = 0; f < nf; f++) { const n = off[f + 1] - off[f]; if (n >= 3) { nt += n - 2; ne += n; } }
    const tri = new Uint32Array(3 * nt), sides = new Uint32Array(2 * ne);
    let t = 0, s = 0;
    for (let f = 0; f < nf; f++) {
      const a = off[f], n = off[f + 1] - a;
      if (n < 3) continue;
      for (let j = 1; j + 1 < n; j++) { tri[t++] = idx[a]; tri[t++] = idx[a + j]; tri[t++] = idx[a + j + 1]; }
      for (let j = 0; j < n; j++) { sides[s++] = idx[a + j]; sides[s++] = idx[a + (j + 1) % n]; }
    }
    const geometry = (index) => {
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", posAttr);
      g.setAttribute("color", colorAttr);
      g.setIndex(new THREE.BufferAttribute(index, 1));
      g.boundingSphere = sphere.clone();  // every frame's bounds: never recomputed
      return g;
    };
    surface = new THREE.Mesh(geometry(tri), surfaceMaterial);
    outline = new THREE.LineSegments(geometry(sides), outlineMaterial);
    outline.visible = nf <= OUTLINE_FACES;
    const edges = topo.edges;
    wire = new THREE.LineSegments(geometry(new Uint32Array(edges.buffer, edges.byteOffset, edges.length)), wireMaterial);
    for (const o of [surface, outline, wire]) { o.frustumCulled = false; scene.add(o); }
  }

  function updateSurface(fr) {
    const P = arr(fr.positions);
    posAttr.array.set(P.subarray(0, posAttr.array.length));
    posAttr.needsUpdate = true;
    const fieldMeta = ui.field !== "none" ? meta.fields[ui.field] : null;
    const C = colorAttr.array, nv = C.length / 3;
    if (fieldMeta) {
      const values = arr(fr.fields[ui.field]);
      const lo = fieldMeta.min, span = fieldMeta.max - fieldMeta.min || 1;
      for (let i = 0; i < nv; i++) {
        const t = (values[i] - lo) / span;
        const e = isFinite(t) ? Math.round(Math.min(Math.max(t, 0), 1) * (LUT_N - 1)) : NONE_ENTRY;
        C[3 * i] = LUT[3 * e]; C[3 * i + 1] = LUT[3 * e + 1]; C[3 * i + 2] = LUT[3 * e + 2];
      }
    } else {
      const g = ui.wire ? 0.02 : LUT[3 * NONE_ENTRY];
      C.fill(g);
    }
    colorAttr.needsUpdate = true;
    legend(fieldMeta);
    return P;
  }

  // ------------------------------------------------------------------ the dart view
  // Instanced line segments: each dart and each alpha link is an item (the darts (d, e) it
  // joins, in a float texture), drawn by a vertex shader from a texture of the darts' points
  // (per dart a base point and a direction, computed per frame: the dart's points are
  // base + q * direction). Each instance draws CHUNK items, so that the draw call count stays
  // one per kind and no renderer pays a cost per item (software WebGL does per instance).
  const LINK_COLORS = [0xd62728, 0x1f5fd6, 0x2ca02c, 0x9a4dc9];
  // where on its dart (0: near the vertex, 1: near the edge's middle) each link attaches
  const ATTACH = [1.0, 0.0, 0.45, 0.7];
  const TEX_W = 4096, CHUNK = 2048;
  const ITEM_VS = `
    uniform highp sampler2D dartData;
    uniform highp sampler2D items;
    uniform int count;
    uniform float q0;
    uniform float q1;
    uniform float size;
    vec4 texel(highp sampler2D t, int i) { return texelFetch(t, ivec2(i % ${TEX_W}, i / ${TEX_W}), 0); }
    void main() {
      int item = gl_InstanceID * ${CHUNK} + gl_VertexID / VERTS;
      if (item >= count) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); return; }
      int end = gl_VertexID - VERTS * (gl_VertexID / VERTS);
      vec2 de = texel(items, item).rg;
      int d = int(end == 0 ? de.x : de.y);
      float q = end == 0 ? q0 : q1;
      vec3 p = texel(dartData, 2 * d).xyz + q * texel(dartData, 2 * d + 1).xyz;
      gl_Position = projectionMatrix * modelViewMatrix * vec4(p, 1.0);
      gl_PointSize = size;
    }`;
  const ITEM_FS = `
    uniform vec3 color;
    out vec4 fragColor;
    void main() { fragColor = vec4(color, 1.0); }`;
  const MARKER_VS = `
    uniform float size;
    void main() {
      gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
      gl_PointSize = size;
    }`;
  const MARKER_FS = `
    uniform vec3 color;
    void main() { gl_FragColor = vec4(color, 1.0); }`;
  // the color as given (sRGB): these shaders write it out without conversion
  const rgb = (hex) => new THREE.Color().setRGB((hex >> 16 & 255) / 255, (hex >> 8 & 255) / 255, (hex & 255) / 255);
  const dpr = window.devicePixelRatio || 1;
  function floatTexture(data, format) {
    const per = format === THREE.RGFormat ? 2 : 4;
    const t = new THREE.DataTexture(data, TEX_W, data.length / per / TEX_W, format, THREE.FloatType);
    t.needsUpdate = true;
    return t;
  }
  const texels = (n, per) => new Float32Array(per * TEX_W * Math.max(1, Math.ceil(n / TEX_W)));
  const bases = { 2: null, 1: null };  // the instance's vertices (their values unused)
  function itemObject(verts, itemsTex, count, dartTex, hex, q0, q1, size) {
    if (!bases[verts]) bases[verts] = new THREE.BufferAttribute(new Float32Array(3 * verts * CHUNK), 3);
    const g = new THREE.InstancedBufferGeometry();
    g.setAttribute("position", bases[verts]);
    g.instanceCount = Math.ceil(count / CHUNK);
    g.boundingSphere = sphere.clone();
    const m = new THREE.ShaderMaterial({
      glslVersion: THREE.GLSL3, defines: { VERTS: verts },
      uniforms: {
        dartData: { value: dartTex }, items: { value: itemsTex }, count: { value: count },
        q0: { value: q0 }, q1: { value: q1 }, size: { value: size * dpr }, color: { value: rgb(hex) },
      },
      vertexShader: ITEM_VS, fragmentShader: ITEM_FS,
    });
    const o = verts === 2 ? new THREE.LineSegments(g, m) : new THREE.Points(g, m);
    o.frustumCulled = false;
    o.renderOrder = 1;
    return o;
  }
  let dartTopology = null;  // the current topology's dart view: its textures and objects

  function buildDarts() {
    if (dartTopology) {
      for (const o of dartTopology.objects) { scene.remove(o); o.geometry.dispose(); o.material.dispose(); }
      for (const t of dartTopology.textures) t.dispose();
    }
    const D = topo.darts;
    const n = D.vertex.length, A = D.alpha;
    let nl = 0;
    for (let d = 0; d < n; d++) if (D.vertex[d] >= 0) nl++;
    const live = new Int32Array(nl), dartItems = texels(nl, 2);
    for (let d = 0, j = 0; d < n; d++) {
      if (D.vertex[d] < 0) continue;
      live[j] = d; dartItems[2 * j] = d; dartItems[2 * j + 1] = d; j++;
    }
    const counts = [0, 0, 0, 0], linkItems = [];
    for (let i = 0; i < 4; i++) {
      for (const d of live) { const e = A[i * n + d]; if (e > d && D.vertex[e] >= 0) counts[i]++; }
      const items = texels(counts[i], 2);
      let k = 0;
      for (const d of live) {
        const e = A[i * n + d];
        if (e > d && D.vertex[e] >= 0) { items[2 * k] = d; items[2 * k + 1] = e; k++; }
      }
      linkItems.push(items);
    }
    const data = texels(2 * n, 4);
    const dartTex = floatTexture(data, THREE.RGBAFormat);
    const dartsTex = floatTexture(dartItems, THREE.RGFormat);
    const linkTex = linkItems.map((items) => floatTexture(items, THREE.RGFormat));
    const objects = [
      itemObject(2, dartsTex, nl, dartTex, 0x111111, 0.12, 0.42, 1),
      itemObject(1, dartsTex, nl, dartTex, 0x111111, 0.12, 0.12, 3),
      ...linkTex.map((t, i) => {
        const q = 0.12 + 0.3 * ATTACH[i];
        return itemObject(2, t, counts[i], dartTex, LINK_COLORS[i], q, q, 1);
      }),
    ];
    ["darts", "dots", "alpha0", "alpha1", "alpha2", "alpha3"].forEach((k, i) => { objects[i].userData.kind = k; });
    for (const o of objects) scene.add(o);
    let nCentres = 0;
    for (const d of live) nCentres = Math.max(nCentres, D.face[d] + 1, D.volume[d] + 1);
    const fn = new Float64Array(nCentres), vn = new Float64Array(nCentres);
    for (const d of live) { fn[D.face[d]] += 1; vn[D.volume[d]] += 1; }
    dartTopology = {
      index: topoIndex, live, counts, data, dartTex, objects,
      textures: [dartTex, dartsTex, ...linkTex],
      fc: new Float64Array(3 * nCentres), vc: new Float64Array(3 * nCentres), fn, vn,
    };
  }

  // the darts' points of a frame: per dart, its base point and direction
  function updateDarts(P) {
    const T = dartTopology, D = topo.darts, A = D.alpha;
    const { live, data, fc, vc, fn, vn } = T;
    const three = meta.dimension === 3, kf = 0.78, kv = three ? 0.82 : 1.0;
    fc.fill(0); vc.fill(0);
    for (let j = 0; j < live.length; j++) {
      const d = live[j], v = 3 * D.vertex[d], f = 3 * D.face[d], o = 3 * D.volume[d];
      for (let c = 0; c < 3; c++) { fc[f + c] += P[v + c]; vc[o + c] += P[v + c]; }
    }
    // the point at q along dart d's edge (from its vertex to its alpha_0's), shrunk towards
    // its face's centre (by kf) then its volume's (by kv): affine in q
    for (let j = 0; j < live.length; j++) {
      const d = live[j], v = 3 * D.vertex[d], w = 3 * D.vertex[A[d]];
      const f = D.face[d], o = D.volume[d];
      for (let c = 0; c < 3; c++) {
        const cf = fc[3 * f + c] / fn[f], cv = vc[3 * o + c] / vn[o];
        const x = cf + kf * (P[v + c] - cf);
        data[8 * d + c] = three ? cv + kv * (x - cv) : x;
        data[8 * d + 4 + c] = kf * kv * (P[w + c] - P[v + c]);
      }
    }
    T.dartTex.needsUpdate = true;
  }

  function showDarts(P) {
    const D = topo.darts;
    $("dart-legend").style.display = ui.darts ? "block" : "none";
    if (!ui.darts || !D) {
      if (dartTopology) for (const o of dartTopology.objects) o.visible = false;
      if (ui.darts) {
        note.textContent = `dart view: this map has ${topo.nDarts} darts, more than the ${meta.dart_limit} a run records darts for`;
        $("dart-count").textContent = "not recorded";
      }
      return [0, [0, 0, 0, 0]];
    }
    note.textContent = "";
    if (!dartTopology || dartTopology.index !== topoIndex) buildDarts();
    for (const o of dartTopology.objects) o.visible = true;
    updateDarts(P);
    const drawn = dartTopology.live.length, counts = dartTopology.counts;
    $("dart-count").textContent = `${drawn} darts`;
    for (let i = 0; i < 4; i++) $("links" + i).textContent = `(${counts[i]} links)`;
    return [drawn, counts];
  }

  // ------------------------------------------------------------------ picking
  const raycaster = new THREE.Raycaster();
  let marker = null;
  {
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3), 3));
    g.boundingSphere = sphere.clone();
    marker = new THREE.Points(g, new THREE.ShaderMaterial({
      uniforms: { color: { value: rgb(0xff2d8a) }, size: { value: 9.0 * dpr } },
      vertexShader: MARKER_VS, fragmentShader: MARKER_FS,
    }));
    marker.visible = false; marker.frustumCulled = false; marker.renderOrder = 2;
    marker.material.depthTest = false;
    scene.add(marker);
  }
  const fmt = (x) => isFinite(x) ? (+x).toPrecision(5) : String(x);

  // the vertex under the client point (x, y): the nearest vertex of the picked triangle
  function pickAt(x, y) {
    const r = canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((x - r.left) / r.width) * 2 - 1, -((y - r.top) / r.height) * 2 + 1);
    raycaster.setFromCamera(ndc, camera);
    const hit = raycaster.intersectObject(surface, false)[0];
    if (!hit || !hit.face) { select(null); return null; }
    const { a, b, c } = hit.face, p = hit.point, P = posAttr.array;
    let best = a, bestD = Infinity;
    for (const v of [a, b, c]) {
      const d = (P[3 * v] - p.x) ** 2 + (P[3 * v + 1] - p.y) ** 2 + (P[3 * v + 2] - p.z) ** 2;
      if (d < bestD) { bestD = d; best = v; }
    }
    select(best, { triangle: [a, b, c], point: [p.x, p.y, p.z] });
    return debug.picked;
  }

  let pickedVertex = null, pickedHit = null;
  function select(v, hit) {
    pickedVertex = v; pickedHit = hit || null;
    showPick();
    draw();
  }

  function showPick() {
    const box = $("pick");
    if (pickedVertex === null || pickedVertex >= topo.vertices) {
      pickedVertex = null;
      box.style.display = "none"; marker.visible = false; debug.picked = null;
      return;
    }
    const fr = frames[ui.frame], v = pickedVertex, P = posAttr.array;
    const x = [P[3 * v], P[3 * v + 1], P[3 * v + 2]];
    marker.geometry.attributes.position.array.set(x);
    marker.geometry.attributes.position.needsUpdate = true;
    marker.visible = true;
    const pointId = topo.pointIds ? topo.pointIds[v] : null;
    const values = {};
    for (const [name] of Object.entries(meta.fields)) values[name] = arr(fr.fields[name])[v];
    debug.picked = Object.assign({ vertex: v, pointId, position: x, values }, pickedHit || {});
    const rows = [
      ["vertex", `${v}`],
      ["point_id", pointId === null ? "not recorded" : pointId < 0 ? `${pointId} (not an input point)` : `${pointId}`],
      ["position", x.map((c, i) => fmt(c + origin[i])).join(", ") + " m"],
    ];
    for (const [name, f] of Object.entries(meta.fields)) rows.push([f.label, `${fmt(values[name])} ${f.unit}`]);
    box.innerHTML = "";
    const table = document.createElement("table");
    for (const [k, val] of rows) {
      const tr = document.createElement("tr");
      const a = document.createElement("td"), b = document.createElement("td");
      a.textContent = k; b.textContent = val;
      tr.append(a, b); table.appendChild(tr);
    }
    box.appendChild(table);
    box.dataset.vertex = String(v);
    box.dataset.pointId = pointId === null ? "" : String(pointId);
    box.style.display = "block";
  }

  // the client coordinates of vertex v in the current frame (for tests and scripts)
  function project(v) {
    const P = posAttr.array, r = canvas.getBoundingClientRect();
    const p = new V3(P[3 * v], P[3 * v + 1], P[3 * v + 2]).project(camera);
    return { x: r.left + (p.x + 1) / 2 * r.width, y: r.top + (1 - p.y) / 2 * r.height, depth: p.z };
  }

  // ------------------------------------------------------------------ drawing
  function legend(fieldMeta) {
    $("field-legend").style.display = fieldMeta ? "" : "none";
    if (!fieldMeta) return;
    $("field-label").textContent = `${fieldMeta.label} (${fieldMeta.unit})`;
    $("field-max").textContent = (+fieldMeta.max).toPrecision(3);
    $("field-min").textContent = (+fieldMeta.min).toPrecision(3);
    const bar = $("colorbar"), c = bar.getContext("2d");
    for (let y = 0; y < bar.height; y++) {
      const rgb = cmap(1 - y / (bar.height - 1));
      c.fillStyle = `rgb(${rgb[0] | 0},${rgb[1] | 0},${rgb[2] | 0})`;
      c.fillRect(0, y, bar.width, 1);
    }
  }

  function resize() {
    const w = Math.max(1, canvas.clientWidth), h = Math.max(1, canvas.clientHeight);
    const size = renderer.getSize(new THREE.Vector2());
    if (size.x !== w || size.y !== h) {
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
    }
  }

  function render() {
    resize();
    renderer.render(scene, camera);
    const r = renderer.info.render;
    debug.info = { calls: r.calls, triangles: r.triangles, lines: r.lines, points: r.points };
    debug.renders += 1;
    debug.camera = { position: camera.position.toArray(), target: controls.target.toArray() };
  }
  let pending = false;
  function renderSoon() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; render(); });
  }

  // sets what the frame shows, then renders at once
  function draw() {
    const fr = frames[ui.frame];
    useTopology(fr.topology);
    const P = updateSurface(fr);
    const [drawn, counts] = showDarts(P);
    const mode = ui.darts ? "darts" : ui.wire ? "wireframe" : "surface";
    surface.visible = !ui.wire;
    outline.visible = !ui.wire && topo.faceOffsets.length - 1 <= OUTLINE_FACES;
    wire.visible = ui.wire;
    // the dart view keeps the surface, translucent, so that the darts inside show
    surfaceMaterial.transparent = ui.darts;
    surfaceMaterial.opacity = ui.darts ? 0.28 : 1.0;
    surfaceMaterial.depthWrite = !ui.darts;
    outlineMaterial.opacity = ui.darts ? 0.15 : 0.35;
    if (pickedVertex !== null) showPick();
    state.dataset.darts = String(drawn);
    state.dataset.links = counts.join(",");
    state.dataset.frame = String(ui.frame);
    state.dataset.mode = mode;
    state.dataset.topology = String(fr.topology);
    state.textContent = `frame ${ui.frame + 1} / ${frames.length} · t = ${(+fr.time).toPrecision(4)} s · step ${fr.step}`;
    // what the dart view's draw calls draw: per object, its items and instances
    const items = ui.darts && dartTopology && topo.darts
      ? dartTopology.objects.map((o) => ({
          kind: o.userData.kind, items: o.material.uniforms.count.value, instances: o.geometry.instanceCount,
        }))
      : [];
    Object.assign(debug, {
      frame: ui.frame, topology: fr.topology, mode, darts: drawn, links: counts.slice(),
      mapDarts: topo.nDarts, vertices: topo.vertices, items, surfaceVisible: surface.visible,
    });
    render();
  }

  function setFrame(k) {
    ui.frame = ((k % frames.length) + frames.length) % frames.length;
    scrub.value = String(ui.frame);
    draw();
  }
  function setPlaying(p) {
    ui.playing = p;
    $("play").textContent = p ? "Pause" : "Play";
    state.dataset.playing = String(p);
    if (p) { last = performance.now(); acc = 0; requestAnimationFrame(tick); }
  }
  // about 6 s for the whole run at 1x, as the GIF
  const frameMs = Math.min(200, Math.max(40, 6000 / Math.max(frames.length, 1)));
  let last = 0, acc = 0;
  function tick(now) {
    if (!ui.playing) return;
    acc += (now - last) * ui.speed; last = now;
    if (acc >= frameMs) { const n = Math.floor(acc / frameMs); acc -= n * frameMs; setFrame(ui.frame + n); }
    requestAnimationFrame(tick);
  }
  function resetView() { controls.reset(); render(); }
  $("play").addEventListener("click", () => setPlaying(!ui.playing));
  $("prev").addEventListener("click", () => { setPlaying(false); setFrame(ui.frame - 1); });
  $("next").addEventListener("click", () => { setPlaying(false); setFrame(ui.frame + 1); });
  $("reset").addEventListener("click", resetView);
  scrub.addEventListener("input", () => setFrame(+scrub.value));
  fieldSel.addEventListener("change", () => { ui.field = fieldSel.value; draw(); });
  $("wireframe").addEventListener("change", (e) => { ui.wire = e.target.checked; draw(); });
  $("darts").addEventListener("change", (e) => {
    ui.darts = e.target.checked;
    if (!ui.darts) note.textContent = "";
    draw();
  });
  $("speed").addEventListener("change", (e) => { ui.speed = +e.target.value; });
  document.addEventListener("keydown", (e) => {
    if (e.target.tagName === "SELECT" || e.target.tagName === "INPUT" && e.target.type !== "checkbox" && e.target.type !== "range") return;
    if (e.key === " ") { e.preventDefault(); setPlaying(!ui.playing); }
    else if (e.key === "ArrowLeft") { setPlaying(false); setFrame(ui.frame - 1); }
    else if (e.key === "ArrowRight") { setPlaying(false); setFrame(ui.frame + 1); }
    else if (e.key === "Escape") select(null);
  });
  controls.addEventListener("change", renderSoon);
  // a click (a press and release without moving) picks; a drag orbits
  let press = null;
  canvas.addEventListener("pointerdown", (e) => { press = e.button === 0 ? [e.clientX, e.clientY] : null; });
  canvas.addEventListener("pointerup", (e) => {
    if (press && Math.hypot(e.clientX - press[0], e.clientY - press[1]) < 4) pickAt(e.clientX, e.clientY);
    press = null;
  });
  canvas.addEventListener("dblclick", resetView);
  window.addEventListener("resize", () => render());

  // vertex v's position as drawn (relative to the origin, as recorded)
  const position = (v) => Array.from(posAttr.array.subarray(3 * v, 3 * v + 3));
  Object.assign(debug, { pick: pickAt, project, position, setFrame, render, resetView, chunk: CHUNK });
  setFrame(0);

  // ------------------------------------------------------------------ without WebGL
  // The 2D viewer this one replaced (Canvas 2D: orthographic, turned with the mouse, no
  // picking), kept for browsers that give the page no WebGL. Its code as it was.
  function fallback2d() {
    const old = $("view");
    if (!old.getContext("2d")) old.replaceWith(old.cloneNode(false));  // a canvas WebGL took
    $("reset").style.display = "none";
    // the links' dashes, as this viewer draws them
    const dashes = ["", "5 3", "2 3", "8 3 2 3"];
    $("dart-legend").querySelectorAll("line").forEach((l, i) => { if (i > 0 && dashes[i - 1]) l.setAttribute("stroke-dasharray", dashes[i - 1]); });
    $("hint").textContent = "2D view: this browser gives the page no WebGL (drag: turn · wheel: zoom; no picking)";
    legacy2d();
  }

  function legacy2d() {
    const $ = (id) => document.getElementById(id);
    const meta = JSON.parse($("view-meta").textContent);
    const buffer = (function () {
      const s = atob($("view-bin").textContent.replace(/\s+/g, ""));
      const bytes = new Uint8Array(s.length);
      for (let i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
      return bytes.buffer;
    })();
    function arr(ref) {
      const n = ref.shape.reduce((a, b) => a * b, 1);
      if (ref.dtype === "f4") return new Float32Array(buffer, ref.offset, n);
      if (ref.dtype === "i4") return new Int32Array(buffer, ref.offset, n);
      throw new Error("unknown dtype " + ref.dtype);
    }
    const frames = meta.frames;
    const topologies = meta.topologies.map((t) => ({
      vertices: t.vertices,
      nDarts: t.darts,
      faceOffsets: arr(t.face_offsets),
      faceIndices: arr(t.face_indices),
      edges: arr(t.edges),
      darts: t.dart_table
        ? {
            vertex: arr(t.dart_table.vertex),
            alpha: arr(t.dart_table.alpha),
            face: arr(t.dart_table.face),
            volume: arr(t.dart_table.volume),
          }
        : null,
    }));

    const VIRIDIS = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
      [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]];
    function cmap(t) {
      if (!isFinite(t)) return [160, 160, 160];
      const s = Math.min(Math.max(t, 0), 1) * (VIRIDIS.length - 1);
      const i = Math.min(Math.floor(s), VIRIDIS.length - 2), f = s - i;
      const a = VIRIDIS[i], b = VIRIDIS[i + 1];
      return [a[0] * (1 - f) + b[0] * f, a[1] * (1 - f) + b[1] * f, a[2] * (1 - f) + b[2] * f];
    }

    // ------------------------------------------------------------------ vectors and camera
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
    const AZ0 = 35, EL0 = 25;
    const cam = { az: AZ0, el: EL0, zoom: 1 };
    function basis() {
      const up = norm(meta.up);
      let front = Math.abs(up[1]) > 0.7 ? [0, 0, 1] : [0, -1, 0];
      const k = dot(front, up);
      front = norm([front[0] - k * up[0], front[1] - k * up[1], front[2] - k * up[2]]);
      const side = cross(up, front);
      const a = cam.az * Math.PI / 180, e = cam.el * Math.PI / 180;
      const eye = [0, 1, 2].map((i) => Math.cos(e) * (Math.cos(a) * front[i] + Math.sin(a) * side[i]) + Math.sin(e) * up[i]);
      const right = norm(cross(up, eye));
      return { right, up: cross(eye, right), eye };
    }
    function fit(b, w, h) {
      // the corners of the bounding box of every frame: nothing leaves the picture
      const lo = meta.bounds.min, hi = meta.bounds.max;
      let u0 = Infinity, u1 = -Infinity, v0 = Infinity, v1 = -Infinity;
      for (let c = 0; c < 8; c++) {
        const p = [c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]];
        const u = dot(p, b.right), v = dot(p, b.up);
        u0 = Math.min(u0, u); u1 = Math.max(u1, u); v0 = Math.min(v0, v); v1 = Math.max(v1, v);
      }
      const m = 0.08, cand = [];
      if (u1 > u0) cand.push(w * (1 - 2 * m) / (u1 - u0));
      if (v1 > v0) cand.push(h * (1 - 2 * m) / (v1 - v0));
      const scale = (cand.length ? Math.min(...cand) : 1) * cam.zoom;
      return { scale, cx: w / 2 - scale * (u0 + u1) / 2, cy: h / 2 + scale * (v0 + v1) / 2 };
    }

    // ------------------------------------------------------------------ state and controls
    const canvas = $("view"), ctx = canvas.getContext("2d");
    const state = $("state");
    const ui = { frame: 0, playing: false, field: meta.default_field, wire: false, darts: false, speed: 1 };
    const scrub = $("scrub");
    scrub.max = String(frames.length - 1);
    $("title").textContent = meta.name;
    const fieldSel = $("field");
    for (const [name, f] of Object.entries(meta.fields)) {
      const o = document.createElement("option");
      o.value = name; o.textContent = f.label;
      fieldSel.appendChild(o);
    }
    { const o = document.createElement("option"); o.value = "none"; o.textContent = "none"; fieldSel.appendChild(o); }
    fieldSel.value = ui.field;
    if (meta.events.length) {
      $("events").textContent = "topology: " + meta.events.map((e) =>
        `${e.kind} at t = ${(+e.time).toPrecision(3)} s (${e.unsewn} ${meta.dimension === 3 ? "faces" : "edges"})`).join(", ");
    }

    function setFrame(k) {
      ui.frame = ((k % frames.length) + frames.length) % frames.length;
      scrub.value = String(ui.frame);
      draw();
    }
    function setPlaying(p) {
      ui.playing = p;
      $("play").textContent = p ? "Pause" : "Play";
      state.dataset.playing = String(p);
      if (p) { last = performance.now(); acc = 0; requestAnimationFrame(tick); }
    }
    // about 6 s for the whole run at 1x, as the GIF
    const frameMs = Math.min(200, Math.max(40, 6000 / Math.max(frames.length, 1)));
    let last = 0, acc = 0;
    function tick(now) {
      if (!ui.playing) return;
      acc += (now - last) * ui.speed; last = now;
      if (acc >= frameMs) { const n = Math.floor(acc / frameMs); acc -= n * frameMs; setFrame(ui.frame + n); }
      requestAnimationFrame(tick);
    }
    $("play").addEventListener("click", () => setPlaying(!ui.playing));
    $("prev").addEventListener("click", () => { setPlaying(false); setFrame(ui.frame - 1); });
    $("next").addEventListener("click", () => { setPlaying(false); setFrame(ui.frame + 1); });
    scrub.addEventListener("input", () => setFrame(+scrub.value));
    fieldSel.addEventListener("change", () => { ui.field = fieldSel.value; draw(); });
    $("wireframe").addEventListener("change", (e) => { ui.wire = e.target.checked; draw(); });
    $("darts").addEventListener("change", (e) => { ui.darts = e.target.checked; draw(); });
    $("speed").addEventListener("change", (e) => { ui.speed = +e.target.value; });
    document.addEventListener("keydown", (e) => {
      if (e.target.tagName === "SELECT" || e.target.tagName === "INPUT" && e.target.type !== "checkbox" && e.target.type !== "range") return;
      if (e.key === " ") { e.preventDefault(); setPlaying(!ui.playing); }
      else if (e.key === "ArrowLeft") { setPlaying(false); setFrame(ui.frame - 1); }
      else if (e.key === "ArrowRight") { setPlaying(false); setFrame(ui.frame + 1); }
    });
    let drag = null;
    canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
    canvas.addEventListener("pointerup", () => { drag = null; });
    canvas.addEventListener("pointermove", (e) => {
      if (!drag) return;
      cam.az -= (e.clientX - drag[0]) * 0.4;
      cam.el = Math.max(-89, Math.min(89, cam.el + (e.clientY - drag[1]) * 0.4));
      drag = [e.clientX, e.clientY];
      draw();
    });
    canvas.addEventListener("wheel", (e) => { e.preventDefault(); cam.zoom *= Math.exp(-e.deltaY * 0.001); draw(); }, { passive: false });
    canvas.addEventListener("dblclick", () => { cam.az = AZ0; cam.el = EL0; cam.zoom = 1; draw(); });
    window.addEventListener("resize", () => draw());

    // ------------------------------------------------------------------ drawing
    function legend(fieldMeta) {
      $("field-legend").style.display = fieldMeta ? "" : "none";
      if (!fieldMeta) return;
      $("field-label").textContent = `${fieldMeta.label} (${fieldMeta.unit})`;
      $("field-max").textContent = (+fieldMeta.max).toPrecision(3);
      $("field-min").textContent = (+fieldMeta.min).toPrecision(3);
      const bar = $("colorbar"), c = bar.getContext("2d");
      for (let y = 0; y < bar.height; y++) {
        const rgb = cmap(1 - y / (bar.height - 1));
        c.fillStyle = `rgb(${rgb[0] | 0},${rgb[1] | 0},${rgb[2] | 0})`;
        c.fillRect(0, y, bar.width, 1);
      }
    }

    function draw() {
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
      if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, w, h);
      const fr = frames[ui.frame], topo = topologies[fr.topology];
      const P = arr(fr.positions);
      const nv = P.length / 3;
      const b = basis(), f = fit(b, w, h);
      const sx = new Float64Array(nv), sy = new Float64Array(nv), sz = new Float64Array(nv);
      for (let i = 0; i < nv; i++) {
        const p = [P[3 * i], P[3 * i + 1], P[3 * i + 2]];
        sx[i] = f.cx + f.scale * dot(p, b.right);
        sy[i] = f.cy - f.scale * dot(p, b.up);
        sz[i] = dot(p, b.eye);
      }
      const fieldMeta = ui.field !== "none" && !ui.darts ? meta.fields[ui.field] : null;
      legend(fieldMeta);
      let values = null, lo = 0, span = 1;
      if (fieldMeta) { values = arr(fr.fields[ui.field]); lo = fieldMeta.min; span = fieldMeta.max - fieldMeta.min || 1; }
      const tOf = (i) => values ? (values[i] - lo) / span : NaN;
      const lw = Math.max(1, dpr);
      let mode;
      if (ui.darts) { mode = "darts"; drawDarts(topo, P, sx, sy, lw, h); }
      else if (ui.wire) { mode = "wireframe"; drawEdges(topo, sx, sy, tOf, lw); }
      else { mode = "surface"; drawFaces(topo, P, sx, sy, sz, tOf, b, lw); }
      if (!ui.darts) { state.dataset.darts = "0"; state.dataset.links = "0,0,0,0"; }
      state.dataset.frame = String(ui.frame);
      state.dataset.mode = mode;
      state.dataset.topology = String(fr.topology);
      state.textContent = `frame ${ui.frame + 1} / ${frames.length} · t = ${(+fr.time).toPrecision(4)} s · step ${fr.step}`;
    }

    function drawFaces(topo, P, sx, sy, sz, tOf, b, lw) {
      const off = topo.faceOffsets, idx = topo.faceIndices, nf = off.length - 1;
      const light = norm([b.eye[0] + 0.5 * b.right[0] + 0.8 * b.up[0], b.eye[1] + 0.5 * b.right[1] + 0.8 * b.up[1], b.eye[2] + 0.5 * b.right[2] + 0.8 * b.up[2]]);
      const depth = new Float64Array(nf), order = new Uint32Array(nf);
      for (let k = 0; k < nf; k++) {
        let d = 0;
        for (let j = off[k]; j < off[k + 1]; j++) d += sz[idx[j]];
        depth[k] = d / (off[k + 1] - off[k]); order[k] = k;
      }
      order.sort((a, c) => depth[a] - depth[c]);
      const outline = nf <= 6000;
      ctx.lineWidth = 0.6 * lw; ctx.lineJoin = "round";
      for (const k of order) {
        const s = off[k], e = off[k + 1], n = e - s;
        if (n < 3) continue;
        // Newell's normal, the mean field value
        let cx = 0, cy = 0, cz = 0, t = 0;
        for (let j = s; j < e; j++) { const v = idx[j]; cx += P[3 * v]; cy += P[3 * v + 1]; cz += P[3 * v + 2]; t += tOf(v); }
        cx /= n; cy /= n; cz /= n; t /= n;
        let nx = 0, ny = 0, nz = 0;
        for (let j = 0; j < n; j++) {
          const a = idx[s + j], c = idx[s + (j + 1) % n];
          const ax = P[3 * a] - cx, ay = P[3 * a + 1] - cy, az = P[3 * a + 2] - cz;
          const bx = P[3 * c] - cx, by = P[3 * c + 1] - cy, bz = P[3 * c + 2] - cz;
          nx += ay * bz - az * by; ny += az * bx - ax * bz; nz += ax * by - ay * bx;
        }
        const l = Math.hypot(nx, ny, nz);
        if (!(l > 0) || !isFinite(sx[idx[s]])) continue;
        const shade = 0.35 + 0.65 * Math.abs((nx * light[0] + ny * light[1] + nz * light[2]) / l);
        const base = isFinite(t) ? cmap(t) : [190, 190, 190];
        const r = base[0] * shade | 0, g = base[1] * shade | 0, bl = base[2] * shade | 0;
        ctx.beginPath();
        ctx.moveTo(sx[idx[s]], sy[idx[s]]);
        for (let j = s + 1; j < e; j++) ctx.lineTo(sx[idx[j]], sy[idx[j]]);
        ctx.closePath();
        ctx.fillStyle = `rgb(${r},${g},${bl})`;
        ctx.fill();
        ctx.strokeStyle = outline ? `rgb(${r * 0.6 | 0},${g * 0.6 | 0},${bl * 0.6 | 0})` : ctx.fillStyle;
        ctx.stroke();
      }
    }

    function drawEdges(topo, sx, sy, tOf, lw) {
      const E = topo.edges;
      ctx.lineWidth = lw;
      for (let k = 0; k < E.length; k += 2) {
        const a = E[k], c = E[k + 1];
        const t = (tOf(a) + tOf(c)) / 2;
        const rgb = isFinite(t) ? cmap(t) : [40, 40, 40];
        ctx.strokeStyle = `rgb(${rgb[0] | 0},${rgb[1] | 0},${rgb[2] | 0})`;
        ctx.beginPath(); ctx.moveTo(sx[a], sy[a]); ctx.lineTo(sx[c], sy[c]); ctx.stroke();
      }
    }

    const LINKS = [
      { color: "#d62728", dash: [] },
      { color: "#1f5fd6", dash: [5, 3] },
      { color: "#2ca02c", dash: [2, 3] },
      { color: "#9a4dc9", dash: [8, 3, 2, 3] },
    ];
    // where on its dart (0: near the vertex, 1: near the edge's middle) each link attaches
    const ATTACH = [1.0, 0.0, 0.45, 0.7];

    function drawDarts(topo, P, sx, sy, lw, h) {
      const D = topo.darts;
      const note = $("note");
      $("dart-legend").style.display = "block";
      if (!D) {
        note.textContent = `dart view: this map has ${topo.nDarts} darts, more than the ${meta.dart_limit} a run records darts for`;
        state.dataset.darts = "0"; state.dataset.links = "0,0,0,0";
        $("dart-count").textContent = "not recorded";
        return;
      }
      note.textContent = "";
      const n = D.vertex.length, A = D.alpha;
      lw *= Math.min(1, Math.max(0.35, Math.sqrt(1500 / Math.max(topo.nDarts, 1))));
      // face and volume centres (means over their darts' vertices)
      const fc = new Float64Array(3 * n), fn = new Float64Array(n), vc = new Float64Array(3 * n), vn = new Float64Array(n);
      for (let d = 0; d < n; d++) {
        const v = D.vertex[d];
        if (v < 0) continue;
        const f = D.face[d], o = D.volume[d];
        for (let c = 0; c < 3; c++) { fc[3 * f + c] += P[3 * v + c]; vc[3 * o + c] += P[3 * v + c]; }
        fn[f] += 1; vn[o] += 1;
      }
      const three = meta.dimension === 3, kf = 0.78, kv = 0.82;
      const b = basis(), fitted = fit(b, canvas.width, canvas.height);
      // screen position of the point at parameter s along dart d (from its vertex to 45% of its
      // edge), shrunk towards the face and volume centres
      const pt = (d, s) => {
        const v = D.vertex[d], w = D.vertex[A[d]];
        const f = D.face[d], o = D.volume[d];
        const q = 0.12 + 0.3 * s;
        const out = [0, 0];
        const p = [0, 0, 0];
        for (let c = 0; c < 3; c++) {
          const x = P[3 * v + c] + q * (P[3 * w + c] - P[3 * v + c]);
          const cf = fc[3 * f + c] / fn[f];
          let y = cf + kf * (x - cf);
          if (three) { const cv = vc[3 * o + c] / vn[o]; y = cv + kv * (y - cv); }
          p[c] = y;
        }
        out[0] = fitted.cx + fitted.scale * dot(p, b.right);
        out[1] = fitted.cy - fitted.scale * dot(p, b.up);
        return out;
      };
      const counts = [0, 0, 0, 0];
      ctx.lineCap = "round";
      for (let i = 0; i < 4; i++) {
        ctx.beginPath();
        for (let d = 0; d < n; d++) {
          const e = A[i * n + d];
          if (D.vertex[d] < 0 || e === d || e < d) continue;
          counts[i]++;
          const p = pt(d, ATTACH[i]), q = pt(e, ATTACH[i]);
          ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]);
        }
        ctx.strokeStyle = LINKS[i].color;
        ctx.lineWidth = 1.4 * lw;
        ctx.setLineDash(LINKS[i].dash.map((x) => x * lw));
        ctx.stroke();
      }
      ctx.setLineDash([]);
      let drawn = 0;
      ctx.beginPath();
      const dots = [];
      for (let d = 0; d < n; d++) {
        if (D.vertex[d] < 0) continue;
        const p = pt(d, 0), q = pt(d, 1);
        ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]);
        dots.push(p);
        drawn++;
      }
      ctx.strokeStyle = "#111"; ctx.lineWidth = 1.6 * lw; ctx.stroke();
      ctx.fillStyle = "#111";
      const r = 1.8 * lw;
      for (const p of dots) ctx.fillRect(p[0] - r, p[1] - r, 2 * r, 2 * r);
      state.dataset.darts = String(drawn);
      state.dataset.links = counts.join(",");
      $("dart-count").textContent = `${drawn} darts`;
      for (let i = 0; i < 4; i++) $("links" + i).textContent = `(${counts[i]} links)`;
    }

    // the dart view is off for maps without recorded darts, and leaves no legend behind
    $("darts").addEventListener("change", () => { if (!ui.darts) { $("dart-legend").style.display = "none"; $("note").textContent = ""; } });
    setFrame(0);
  }
})();
