// shtools view: draws a bake served by `shtools view` (plain WebGL 2, no library).
// The server computes every display colour (the export's tone mapping); this page
// only uploads them and draws the triangles, with an orbit camera.
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("view");
const gl = canvas.getContext("webgl2", { antialias: true, preserveDrawingBuffer: true });

// ------------------------------------------------------------------ small matrix algebra
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1,
          0, 0, 2 * far * near * nf, 0];
}
function lookAt(eye, target, up) {
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const norm = (a) => { const l = Math.hypot(...a) || 1; return a.map((x) => x / l); };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                           a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const z = norm(sub(eye, target)), x = norm(cross(up, z)), y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
          -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}
function multiply(a, b) {  // column-major a * b
  const out = new Array(16).fill(0);
  for (let c = 0; c < 4; c++)
    for (let r = 0; r < 4; r++)
      for (let k = 0; k < 4; k++) out[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
  return out;
}

// ------------------------------------------------------------------ shaders
function program(vs, fs) {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}
// baked colours are already sRGB-encoded display values: drawn as they are
const meshProgram = gl && program(`#version 300 es
  layout(location = 0) in vec3 position;
  layout(location = 1) in vec3 color;
  uniform mat4 viewProj;
  out vec3 vColor;
  void main() { vColor = color; gl_Position = viewProj * vec4(position, 1.0); }`,
`#version 300 es
  precision mediump float;
  in vec3 vColor;
  out vec4 outColor;
  void main() { outColor = vec4(vColor, 1.0); }`);
const sphereProgram = gl && program(`#version 300 es
  layout(location = 0) in vec3 position;
  uniform mat4 viewProj;
  uniform vec4 sphere;
  void main() { gl_Position = viewProj * vec4(sphere.xyz + sphere.w * position, 1.0); }`,
`#version 300 es
  precision mediump float;
  out vec4 outColor;
  void main() { outColor = vec4(0.3, 0.95, 1.0, 0.55); }`);

// a unit sphere as lines: 6 latitudes and 12 meridians
function sphereLines() {
  const pts = [], seg = 32;
  const push = (a, b) => pts.push(...a, ...b);
  for (let i = 1; i < 7; i++) {
    const th = Math.PI * i / 7, y = Math.cos(th), r = Math.sin(th);
    for (let k = 0; k < seg; k++) {
      const a = 2 * Math.PI * k / seg, b = 2 * Math.PI * (k + 1) / seg;
      push([r * Math.cos(a), y, r * Math.sin(a)], [r * Math.cos(b), y, r * Math.sin(b)]);
    }
  }
  for (let m = 0; m < 12; m++) {
    const ph = Math.PI * m / 6;
    for (let k = 0; k < seg / 2; k++) {
      const a = Math.PI * k / (seg / 2), b = Math.PI * (k + 1) / (seg / 2);
      push([Math.sin(a) * Math.cos(ph), Math.cos(a), Math.sin(a) * Math.sin(ph)],
           [Math.sin(b) * Math.cos(ph), Math.cos(b), Math.sin(b) * Math.sin(ph)]);
    }
  }
  return new Float32Array(pts);
}

// ------------------------------------------------------------------ state
const state = {
  bake: null, frame: 0, quantity: "radiance", exposure: 0, playing: false,
  visible: [], spheres: false, sphereData: new Float32Array(0),
  yaw: 0.6, pitch: 0.45, distance: 1, center: [0, 0, 0], pending: false, lastTick: 0,
};
let vao, positionBuffer, colorBuffer, indexBuffer, sphereVao, sphereCount;
const colorCache = new Map();

async function fetchBytes(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: ${r.status} ${await r.text()}`);
  return r.arrayBuffer();
}

function draw() {
  if (!state.bake) return;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== w * devicePixelRatio || canvas.height !== h * devicePixelRatio) {
    canvas.width = w * devicePixelRatio;
    canvas.height = h * devicePixelRatio;
  }
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.114, 0.122, 0.133, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST);
  const c = state.center, d = state.distance;
  const eye = [c[0] + d * Math.cos(state.pitch) * Math.sin(state.yaw),
               c[1] + d * Math.sin(state.pitch),
               c[2] + d * Math.cos(state.pitch) * Math.cos(state.yaw)];
  const proj = perspective(Math.PI / 4, canvas.width / canvas.height, d * 0.01, d * 20);
  const viewProj = multiply(proj, lookAt(eye, c, [0, 1, 0]));
  gl.useProgram(meshProgram);
  gl.uniformMatrix4fv(gl.getUniformLocation(meshProgram, "viewProj"), false, viewProj);
  gl.bindVertexArray(vao);
  state.bake.objects.forEach((o, i) => {
    if (state.visible[i] && o.faces > 0)
      gl.drawElements(gl.TRIANGLES, 3 * o.faces, gl.UNSIGNED_INT, 12 * o.first_face);
  });
  if (state.spheres && state.sphereData.length) {
    gl.useProgram(sphereProgram);
    gl.uniformMatrix4fv(gl.getUniformLocation(sphereProgram, "viewProj"), false, viewProj);
    const loc = gl.getUniformLocation(sphereProgram, "sphere");
    gl.enable(gl.BLEND);
    gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
    gl.bindVertexArray(sphereVao);
    for (let s = 0; s < state.sphereData.length; s += 4) {
      gl.uniform4f(loc, state.sphereData[s], state.sphereData[s + 1], state.sphereData[s + 2],
                   state.sphereData[s + 3]);
      gl.drawArrays(gl.LINES, 0, sphereCount);
    }
    gl.disable(gl.BLEND);
  }
  gl.bindVertexArray(null);
}

async function loadFrame() {
  const b = state.bake, t = state.frame;
  const key = `${t}|${state.quantity}|${state.exposure}`;
  state.pending = true;
  try {
    let colors = colorCache.get(key);
    if (!colors) {
      colors = await fetchBytes(`api/colors.bin?frame=${t}&quantity=${state.quantity}` +
                                `&exposure=${state.exposure}`);
      if (colorCache.size > 4 * b.frames.length) colorCache.clear();
      colorCache.set(key, colors);
    }
    gl.bindBuffer(gl.ARRAY_BUFFER, colorBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Uint8Array(colors), gl.DYNAMIC_DRAW);
    if (b.moving) {
      gl.bindBuffer(gl.ARRAY_BUFFER, positionBuffer);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(await fetchBytes(
        `api/positions.bin?frame=${t}`)), gl.DYNAMIC_DRAW);
    }
    if (state.spheres)
      state.sphereData = new Float32Array(await fetchBytes(`api/spheres.bin?frame=${t}`));
    $("frame-label").textContent =
      `frame ${b.frames[t]} (${b.times[t].toFixed(2)} s) of ${b.frames.length} @ ${b.fps} fps`;
    $("status").textContent = `${b.vertices.toLocaleString()} vertices`;
    draw();
    document.body.dataset.ready = "1";  // a frame is on screen (the browser test waits)
  } catch (err) {
    $("status").textContent = String(err);
  } finally {
    state.pending = false;
  }
}

function tick(now) {
  if (state.playing && !state.pending && now - state.lastTick >= 1000 / state.bake.fps) {
    state.lastTick = now;
    state.frame = (state.frame + 1) % state.bake.frames.length;
    $("frame").value = state.frame;
    loadFrame();
  }
  requestAnimationFrame(tick);
}

function controls() {
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.button !== 0 || e.shiftKey };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {  // move the orbit centre in the view plane
      const s = state.distance / canvas.clientHeight, cy = Math.cos(state.yaw);
      const sy = Math.sin(state.yaw);
      state.center[0] -= s * dx * cy;
      state.center[2] += s * dx * sy;
      state.center[1] += s * dy;
    } else {
      state.yaw -= dx * 0.008;
      state.pitch = Math.max(-1.55, Math.min(1.55, state.pitch + dy * 0.008));
    }
    draw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    state.distance *= Math.exp(e.deltaY * 0.001);
    draw();
  }, { passive: false });
  window.addEventListener("resize", draw);
  $("frame").addEventListener("input", (e) => { state.frame = +e.target.value; loadFrame(); });
  $("play").addEventListener("click", () => {
    state.playing = !state.playing;
    $("play").textContent = state.playing ? "pause" : "play";
  });
  $("quantity").addEventListener("change", (e) => { state.quantity = e.target.value; loadFrame(); });
  $("exposure").addEventListener("input", (e) => {
    state.exposure = +e.target.value;
    $("exposure-label").textContent = state.exposure.toFixed(2);
    loadFrame();
  });
  $("spheres").addEventListener("change", (e) => { state.spheres = e.target.checked; loadFrame(); });
}

async function main() {
  if (!gl) { $("status").textContent = "this browser has no WebGL 2"; return; }
  const b = await (await fetch("api/bake.json")).json();
  state.bake = b;
  document.title = `shtools view — ${b.name}`;
  $("title").textContent = b.name;
  $("frame").max = b.frames.length - 1;
  for (const q of b.quantities) $("quantity").add(new Option(q, q));
  b.objects.forEach((o, i) => {
    state.visible.push(true);
    const label = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox"; box.checked = true;
    box.addEventListener("change", () => { state.visible[i] = box.checked; draw(); });
    label.append(box, ` ${o.name}`);
    $("objects").append(label);
  });
  $("spheres-row").hidden = !b.spheres;
  state.center = b.center.slice();
  state.distance = 2.4 * b.radius;
  // the starting view from the address: ?frame=T&quantity=Q&exposure=E&spheres=1&yaw=&pitch=&zoom=&ui=0
  const opts = new URLSearchParams(location.search);
  if (opts.has("frame")) state.frame = Math.max(0, Math.min(b.frames.length - 1, +opts.get("frame") || 0));
  if (b.quantities.includes(opts.get("quantity"))) state.quantity = opts.get("quantity");
  if (opts.has("exposure")) state.exposure = +opts.get("exposure") || 0;
  if (opts.has("yaw")) state.yaw = +opts.get("yaw") || 0;
  if (opts.has("pitch")) state.pitch = +opts.get("pitch") || 0;
  if (opts.has("zoom")) state.distance /= +opts.get("zoom") || 1;
  state.spheres = b.spheres && opts.get("spheres") === "1";
  if (opts.get("ui") === "0") $("panel").hidden = true;
  $("frame").value = state.frame;
  $("quantity").value = state.quantity;
  $("exposure").value = state.exposure;
  $("exposure-label").textContent = state.exposure.toFixed(2);
  $("spheres").checked = state.spheres;

  vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  positionBuffer = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, positionBuffer);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(await fetchBytes("api/positions.bin?frame=0")),
                gl.DYNAMIC_DRAW);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  colorBuffer = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, colorBuffer);
  gl.enableVertexAttribArray(1);
  gl.vertexAttribPointer(1, 3, gl.UNSIGNED_BYTE, true, 0, 0);
  indexBuffer = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indexBuffer);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(await fetchBytes("api/faces.bin")),
                gl.STATIC_DRAW);
  gl.bindVertexArray(null);

  sphereVao = gl.createVertexArray();
  gl.bindVertexArray(sphereVao);
  const lines = sphereLines();
  sphereCount = lines.length / 3;
  gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
  gl.bufferData(gl.ARRAY_BUFFER, lines, gl.STATIC_DRAW);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);

  controls();
  await loadFrame();
  requestAnimationFrame(tick);
}

main().catch((err) => { $("status").textContent = String(err); });
