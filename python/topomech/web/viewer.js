// topomech viewer: plays the frames of a run (view.json + view.bin, inlined in the page) on a
// Canvas 2D. Surfaces are shaded polygons drawn far to near (orthographic camera, both sides
// lit), colored by a field on one scale for the whole run. The dart view draws the G-map as
// in the paper's Figure 1: each dart a short segment from near its vertex towards the middle
// of its edge, shrunk towards its face's and volume's centres, and the alpha_i links between
// darts in four styles. #state's data-* attributes say what is shown (for tests and scripts).
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
})();
