// The pages are self-contained (inline style and script, no external resource), so they work on a
// machine without network access, under the Content-Security-Policy the server sends with them. Every
// text that comes from a job (paths, messages) is set with textContent, never as HTML.
#include "server/page.h"

namespace lodstream::serve {

const std::string& jobs_page() {
  static const std::string page = R"HTML(<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>lodstream jobs</title>
<style>
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { font-size: 1.4em; margin: 0 0 .2em; }
form { display: flex; flex-wrap: wrap; gap: .6em 1.2em; align-items: end; padding: .8em; background: #f4f4f6; border-radius: 6px; }
label { display: flex; flex-direction: column; font-size: .85em; color: #555; }
input[type=text], input[type=number], select { font: inherit; padding: .25em .4em; }
button { font: inherit; padding: .3em 1em; cursor: pointer; }
table { border-collapse: collapse; width: 100%; margin-top: 1em; }
th, td { text-align: left; padding: .35em .6em; border-bottom: 1px solid #ddd; vertical-align: middle; }
th { font-size: .85em; color: #555; }
progress { width: 12em; height: 1em; vertical-align: middle; }
.pct { display: inline-block; width: 3.5em; text-align: right; font-variant-numeric: tabular-nums; }
.st-successful { color: #1a7f37; } .st-failed { color: #c62828; } .st-running { color: #0b5cad; } .st-dismissed { color: #888; }
.msg { color: #555; font-size: .9em; max-width: 30em; }
.links a { margin-right: .6em; }
#form-status { font-size: .9em; }
#form-status.error { color: #c62828; }
.id { font-family: ui-monospace, monospace; font-size: .85em; }
</style>
</head>
<body>
<h1>lodstream jobs</h1>
<p><a href="/processes">processes</a> · <a href="/jobs">jobs (JSON)</a> · <a href="/conformance">conformance</a> ·
OGC API – Processes</p>
<form id="submit-form">
  <label>process <select id="f-process"><option>simplify</option><option>grid</option></select></label>
  <label>input (path under the data root) <input type="text" id="f-input" size="28" placeholder="scene.ply"></label>
  <label>or upload a file <input type="file" id="f-file"></label>
  <label>levels <input type="number" id="f-levels" min="1" max="32" style="width:5em"></label>
  <label>memory <input type="text" id="f-memory" size="6" placeholder="512M"></label>
  <label><span><input type="checkbox" id="f-report" checked> error report</span></label>
  <button type="submit" id="f-submit">Submit</button>
  <span id="form-status"></span>
</form>
<table>
<thead><tr><th>job</th><th>process</th><th>input</th><th>status</th><th>progress</th><th>message</th><th>outputs</th><th></th></tr></thead>
<tbody id="jobs"></tbody>
</table>
<script>
"use strict";
const outputs = {};  // job id -> results document, fetched once when the job has succeeded

function el(tag, props, children) {
  const e = document.createElement(tag);
  Object.assign(e, props || {});
  for (const c of children || []) e.append(c);
  return e;
}

function link(href, text) { return el("a", {href: href, textContent: text}); }

function outputLinks(job) {
  const span = el("span", {className: "links"});
  const r = outputs[job.jobID];
  if (!r) return span;
  span.append(link("/jobs/" + job.jobID + "/results", "results"));
  if (r.report) span.append(link(r.report.href, "report.html"));
  if (r.glb) span.append(link(r.glb.href, "glb"));
  if (r.tiles) span.append(link(r.tiles.href, "tileset.json"));
  if (r.tiles || r.glb) span.append(link("/viewer?job=" + job.jobID, "viewer"));
  if (r.manifest) span.append(link(r.manifest.href, "manifest"));
  if (r.summary) span.append(link(r.summary.href, "summary"));
  return span;
}

function row(job) {
  const pct = job.progress || 0;
  const bar = el("progress", {max: 100, value: pct});
  const input = (job.inputs && (job.inputs.input || job.inputs.job)) || "";
  const stage = job.status === "running" && job.stage ? " " + job.stage : "";
  const dismiss = el("button", {textContent: job.status === "running" || job.status === "accepted" ? "cancel" : "dismiss",
                                type: "button"});
  dismiss.disabled = job.status === "dismissed";
  dismiss.onclick = () => fetch("/jobs/" + job.jobID, {method: "DELETE"}).then(refresh);
  const tr = el("tr", {}, [
    el("td", {className: "id", textContent: job.jobID.slice(0, 8), title: job.jobID}),
    el("td", {textContent: job.processID}),
    el("td", {textContent: input}),
    el("td", {className: "status st-" + job.status, textContent: job.status}),
    el("td", {}, [bar, el("span", {className: "pct", textContent: pct + " %"}), el("span", {textContent: stage})]),
    el("td", {className: "msg", textContent: job.message || ""}),
    el("td", {}, [outputLinks(job)]),
    el("td", {}, [dismiss])]);
  tr.dataset.job = job.jobID;
  tr.dataset.status = job.status;
  tr.dataset.progress = pct;
  return tr;
}

async function refresh() {
  try {
    const res = await fetch("/jobs", {headers: {Accept: "application/json"}});
    if (res.status === 401) { location.reload(); return; }
    const list = (await res.json()).jobs;
    for (const job of list)
      if (job.status === "successful" && !outputs[job.jobID]) {
        const r = await fetch("/jobs/" + job.jobID + "/results");
        if (r.ok) outputs[job.jobID] = await r.json();
      }
    document.getElementById("jobs").replaceChildren(...list.map(row));
  } catch (e) {
    document.getElementById("form-status").textContent = "cannot reach the server: " + e;
  }
}

async function submit(ev) {
  ev.preventDefault();
  const status = document.getElementById("form-status");
  status.className = "";
  status.textContent = "submitting…";
  const inputs = {};
  const file = document.getElementById("f-file").files[0];
  if (file) {
    status.textContent = "uploading " + file.name + "…";
    const up = await fetch("/uploads?name=" + encodeURIComponent(file.name), {method: "POST", body: file,
                           headers: {"Content-Type": "application/octet-stream"}});
    const body = await up.json();
    if (!up.ok) { status.className = "error"; status.textContent = body.detail || up.statusText; return; }
    inputs.input = body.input;
  } else {
    inputs.input = document.getElementById("f-input").value.trim();
  }
  const process = document.getElementById("f-process").value;
  const levels = document.getElementById("f-levels").value;
  const memory = document.getElementById("f-memory").value.trim();
  if (levels && process === "simplify") inputs.levels = Number(levels);
  if (memory) inputs.memory = memory;
  if (process === "simplify") inputs.report = document.getElementById("f-report").checked;
  const res = await fetch("/processes/" + process + "/execution", {method: "POST",
                          headers: {"Content-Type": "application/json"}, body: JSON.stringify({inputs: inputs})});
  const body = await res.json();
  if (res.status === 201) {
    status.textContent = "submitted job " + body.jobID.slice(0, 8);
    status.dataset.job = body.jobID;
  } else {
    status.className = "error";
    status.textContent = body.detail || res.statusText;
  }
  refresh();
}

document.getElementById("submit-form").addEventListener("submit", submit);
const params = new URLSearchParams(location.search);
if (params.get("input")) document.getElementById("f-input").value = params.get("input");
refresh();
setInterval(refresh, 1000);
</script>
</body>
</html>
)HTML";
  return page;
}

const std::string& login_page() {
  static const std::string page = R"HTML(<!DOCTYPE html>
<html lang="en">
<head><meta charset="utf-8"><title>lodstream: token needed</title>
<style>body { font: 14px/1.4 system-ui, sans-serif; margin: 2em; } input { font: inherit; width: 28em; }</style></head>
<body>
<h1>This lodstream server needs a token</h1>
<p>Paste the token from the server's <code>--token-file</code>. It is kept in a cookie for this site only.</p>
<form id="f"><input type="password" id="t" autocomplete="current-password" autofocus> <button>Continue</button></form>
<script>
document.getElementById("f").addEventListener("submit", ev => {
  ev.preventDefault();
  document.cookie = "lodstream_token=" + encodeURIComponent(document.getElementById("t").value) + "; path=/; SameSite=Strict";
  location.reload();
});
</script>
</body>
</html>
)HTML";
  return page;
}

// 3D Tiles 1.1 (OGC 22-025r4): a tile is refined while its screen-space error, geometricError x viewport
// height / (distance x 2 tan(fov / 2)), exceeds 16 pixels; REPLACE draws the children instead of the tile
// once all of them are loaded (the tile meanwhile), ADD draws both. glTF content is y-up and turned z-up
// (§ "glTF transforms"); tile transforms compose down the tree. Bounding volumes: box and sphere (region,
// geographic, is treated as always near).
const std::string& viewer_page() {
  static const std::string page = R"HTML(<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>lodstream viewer</title>
<style>
html, body { margin: 0; height: 100%; overflow: hidden; font: 13px system-ui, sans-serif; }
canvas { display: block; width: 100%; height: 100%; background: #e9edf2; }
#bar { position: absolute; top: 8px; left: 8px; background: rgba(255,255,255,.85); padding: 6px 10px; border-radius: 4px; }
</style>
</head>
<body>
<canvas id="c"></canvas>
<div id="bar"><a href="/">jobs</a> · <span id="viewer-status">loading…</span>
  <span id="lod-box" hidden> · level <input type="range" id="lod" min="0" max="0" value="0"> <span id="lod-name"></span></span></div>
<script>
"use strict";
const statusEl = document.getElementById("viewer-status");
const fail = msg => { statusEl.textContent = "error: " + msg; };
const job = new URLSearchParams(location.search).get("job") || "";
const canvas = document.getElementById("c");
const gl = canvas.getContext("webgl2", {antialias: true});

// 4x4 matrices, column-major as glTF and 3D Tiles store them.
const M = {
  ident: () => [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1],
  mul(a, b) { const r = new Array(16).fill(0);
    for (let c = 0; c < 4; c++) for (let rr = 0; rr < 4; rr++) for (let k = 0; k < 4; k++) r[c*4+rr] += a[k*4+rr] * b[c*4+k];
    return r; },
  point(m, p) { return [0,1,2].map(i => m[i]*p[0] + m[4+i]*p[1] + m[8+i]*p[2] + m[12+i]); },
  trs(t, q, s) { t = t || [0,0,0]; q = q || [0,0,0,1]; s = s || [1,1,1];
    const [x,y,z,w] = q;
    return [(1-2*(y*y+z*z))*s[0], 2*(x*y+z*w)*s[0], 2*(x*z-y*w)*s[0], 0,
            2*(x*y-z*w)*s[1], (1-2*(x*x+z*z))*s[1], 2*(y*z+x*w)*s[1], 0,
            2*(x*z+y*w)*s[2], 2*(y*z-x*w)*s[2], (1-2*(x*x+y*y))*s[2], 0, t[0], t[1], t[2], 1]; },
  perspective(fovy, aspect, near, far) { const f = 1 / Math.tan(fovy / 2), d = near - far;
    return [f/aspect,0,0,0, 0,f,0,0, 0,0,(far+near)/d,-1, 0,0,2*far*near/d,0]; },
  lookAt(eye, at, up) {
    const sub = (a, b) => a.map((v, i) => v - b[i]), norm = a => { const l = Math.hypot(...a) || 1; return a.map(v => v / l); };
    const cross = (a, b) => [a[1]*b[2]-a[2]*b[1], a[2]*b[0]-a[0]*b[2], a[0]*b[1]-a[1]*b[0]];
    const dot = (a, b) => a[0]*b[0] + a[1]*b[1] + a[2]*b[2];
    const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
    return [x[0],y[0],z[0],0, x[1],y[1],z[1],0, x[2],y[2],z[2],0, -dot(x,eye),-dot(y,eye),-dot(z,eye),1]; },
};
const Y_UP_TO_Z_UP = [1,0,0,0, 0,0,1,0, 0,-1,0,0, 0,0,0,1];

const vs = `#version 300 es
uniform mat4 mvp; uniform mat4 model; in vec3 pos; out vec3 wpos;
void main() { vec4 w = model * vec4(pos, 1.0); wpos = w.xyz; gl_Position = mvp * w; gl_PointSize = 3.0; }`;
const fs = `#version 300 es
precision highp float; uniform vec3 eye; uniform vec3 color; uniform int shaded; in vec3 wpos; out vec4 o;
void main() {
  if (shaded == 0) { o = vec4(color * 0.55, 1.0); return; }
  vec3 n = normalize(cross(dFdx(wpos), dFdy(wpos)));
  float l = abs(dot(n, normalize(eye - wpos)));
  o = vec4(color * (0.25 + 0.75 * l), 1.0); }`;
function program() {
  const p = gl.createProgram();
  for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    gl.attachShader(p, s);
  }
  gl.linkProgram(p);
  return p;
}

// A GLB as draw calls: [{model matrix, mode, count, vao, indexType}], with its bounds and triangle count.
function parseGlb(buf, sceneNodes) {
  const dv = new DataView(buf);
  if (dv.getUint32(0, true) !== 0x46546C67) throw new Error("not a GLB");
  let off = 12, json = null, bin = null;
  while (off < buf.byteLength) {
    const len = dv.getUint32(off, true), type = dv.getUint32(off + 4, true);
    if (type === 0x4E4F534A) json = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, off + 8, len)));
    if (type === 0x004E4942) bin = new Uint8Array(buf, off + 8, len);
    off += 8 + len;
  }
  const sizes = {SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4};
  const arrays = {5126: Float32Array, 5125: Uint32Array, 5123: Uint16Array, 5121: Uint8Array};
  const accessor = i => {
    const a = json.accessors[i], v = json.bufferViews[a.bufferView], T = arrays[a.componentType];
    if (!T || (v.byteStride && v.byteStride !== sizes[a.type] * T.BYTES_PER_ELEMENT)) throw new Error("unsupported accessor " + i);
    const start = bin.byteOffset + (v.byteOffset || 0) + (a.byteOffset || 0);
    return new T(bin.buffer.slice(start, start + a.count * sizes[a.type] * T.BYTES_PER_ELEMENT));
  };
  const draws = [], lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  let triangles = 0;
  const visit = (n, parent) => {
    const node = json.nodes[n];
    const m = M.mul(parent, node.matrix || M.trs(node.translation, node.rotation, node.scale));
    if (node.mesh !== undefined) for (const p of json.meshes[node.mesh].primitives) {
      if (p.attributes.POSITION === undefined || json.accessors[p.attributes.POSITION].componentType !== 5126) continue;
      const pos = accessor(p.attributes.POSITION);
      const vao = gl.createVertexArray(); gl.bindVertexArray(vao);
      const vb = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, vb); gl.bufferData(gl.ARRAY_BUFFER, pos, gl.STATIC_DRAW);
      gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      let count = pos.length / 3, indexType = 0;
      if (p.indices !== undefined) {
        const idx = accessor(p.indices);
        const ib = gl.createBuffer(); gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
        count = idx.length;
        indexType = idx instanceof Uint32Array ? gl.UNSIGNED_INT : idx instanceof Uint16Array ? gl.UNSIGNED_SHORT : gl.UNSIGNED_BYTE;
      }
      gl.bindVertexArray(null);
      const mode = p.mode === undefined ? 4 : p.mode;
      if (mode === 4) triangles += count / 3;
      draws.push({model: m, mode, count, vao, indexType});
      for (let i = 0; i < pos.length; i += 3) {
        const w = M.point(m, [pos[i], pos[i+1], pos[i+2]]);
        for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], w[k]); hi[k] = Math.max(hi[k], w[k]); }
      }
    }
    for (const c of node.children || []) visit(c, m);
  };
  const roots = sceneNodes ? sceneNodes(json) : json.scenes[json.scene || 0].nodes;
  for (const n of roots) visit(n, M.ident());
  return {json, draws, lo, hi, triangles};
}

// Camera: orbit around a center; drag turns, wheel zooms.
const cam = {center: [0,0,0], radius: 1, yaw: 0.8, pitch: 0.5, up: [0,1,0], fovy: Math.PI / 4};
function eye() {
  const r = cam.radius, cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
  const d = cam.up[2] === 1 ? [cp*Math.cos(cam.yaw), cp*Math.sin(cam.yaw), sp] : [cp*Math.sin(cam.yaw), sp, cp*Math.cos(cam.yaw)];
  return cam.center.map((c, i) => c + r * d[i]);
}
function frame(lo, hi) {
  cam.center = lo.map((v, i) => (v + hi[i]) / 2);
  cam.radius = 1.2 * Math.hypot(hi[0]-lo[0], hi[1]-lo[1], hi[2]-lo[2]) || 1;
}
let dragging = null;
canvas.onmousedown = e => { dragging = [e.clientX, e.clientY]; };
window.onmouseup = () => { dragging = null; };
window.onmousemove = e => {
  if (!dragging) return;
  cam.yaw -= (e.clientX - dragging[0]) * 0.01;
  cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + (e.clientY - dragging[1]) * 0.01));
  dragging = [e.clientX, e.clientY]; redraw();
};
canvas.onwheel = e => { e.preventDefault(); cam.radius *= Math.exp(e.deltaY * 0.001); redraw(); };

let prog, scene = null, drawnTriangles = 0;
const colors = [[0.36,0.55,0.82], [0.85,0.55,0.3], [0.45,0.7,0.4], [0.75,0.4,0.6], [0.6,0.6,0.3], [0.4,0.65,0.7]];

function drawList(list, viewProj, e) {
  gl.useProgram(prog);
  gl.uniform3fv(gl.getUniformLocation(prog, "eye"), e);
  for (const [d, color] of list) {
    gl.uniformMatrix4fv(gl.getUniformLocation(prog, "mvp"), false, M.mul(viewProj, d.model));
    gl.uniformMatrix4fv(gl.getUniformLocation(prog, "model"), false, d.model);
    gl.uniform3fv(gl.getUniformLocation(prog, "color"), color);
    gl.uniform1i(gl.getUniformLocation(prog, "shaded"), d.mode === 4 ? 1 : 0);
    gl.bindVertexArray(d.vao);
    if (d.indexType) gl.drawElements(d.mode, d.count, d.indexType, 0); else gl.drawArrays(d.mode, 0, d.count);
  }
  gl.bindVertexArray(null);
}

function redraw() {
  if (!scene) return;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  gl.viewport(0, 0, w, h);
  gl.clearColor(0.914, 0.929, 0.949, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT); gl.enable(gl.DEPTH_TEST);
  const e = eye();
  const viewProj = M.mul(M.perspective(cam.fovy, w / h, cam.radius * 0.01, cam.radius * 10), M.lookAt(e, cam.center, cam.up));
  const list = scene.select(e, h);
  drawList(list, viewProj, e);
  drawnTriangles = list.reduce((n, [d]) => n + (d.mode === 4 ? d.count / 3 : 0), 0);
  statusEl.textContent = `ok: ${Math.round(drawnTriangles)} triangles drawn` + (scene.describe ? ", " + scene.describe() : "");
}

async function fetchOk(url, kind) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(url + ": HTTP " + r.status);
  return kind === "json" ? r.json() : r.arrayBuffer();
}

// lods.glb: one level at a time, chosen with the slider (node 0 and its MSFT_lod ids, finest first).
async function glbScene(href) {
  const buf = await fetchOk(href);
  const first = parseGlb(buf, json => [0]);
  const ids = (first.json.nodes[0].extensions && first.json.nodes[0].extensions.MSFT_lod || {}).ids || [];
  const nodes = [0, ...ids];
  const levels = nodes.map((n, i) => i === 0 ? first : parseGlb(buf, () => [n]));
  frame(first.lo, first.hi);
  cam.up = [0, 1, 0];
  const slider = document.getElementById("lod");
  slider.max = nodes.length - 1; slider.value = Math.min(1, nodes.length - 1);
  document.getElementById("lod-box").hidden = false;
  slider.oninput = redraw;
  return {
    select() { const l = Number(slider.value); document.getElementById("lod-name").textContent = first.json.nodes[nodes[l]].name || l;
               return levels[l].draws.map(d => [d, colors[l % colors.length]]); },
    describe() { return `level ${slider.value} of ${nodes.length}`; }
  };
}

// A tileset: tiles loaded as the camera needs them.
async function tilesetScene(href) {
  const base = new URL(href, location.href);
  const root = await fetchOk(base.href, "json");
  let loaded = 0, requested = 0;
  const prepare = (tile, parentTransform, url, depth) => {
    tile.world = M.mul(parentTransform, tile.transform || M.ident());
    tile.url = url; tile.depth = depth;
    for (const c of tile.children || []) prepare(c, tile.world, url, depth + 1);
  };
  prepare(root.root, M.ident(), base, 0);
  const bounds = tile => {
    const bv = tile.boundingVolume;
    if (bv.box) { const b = bv.box, c = [b[0], b[1], b[2]];
      const r = Math.hypot(b[3]+b[6]+b[9], b[4]+b[7]+b[10], b[5]+b[8]+b[11]);
      return {center: M.point(tile.world, c), radius: Math.max(r, Math.hypot(b[3],b[4],b[5]) + Math.hypot(b[6],b[7],b[8]) + Math.hypot(b[9],b[10],b[11]))}; }
    if (bv.sphere) return {center: M.point(tile.world, bv.sphere.slice(0, 3)), radius: bv.sphere[3]};
    return null;
  };
  const rb = bounds(root.root);
  if (rb) { frame(rb.center.map(v => v - rb.radius / 2), rb.center.map(v => v + rb.radius / 2)); cam.radius = 2.2 * rb.radius; }
  cam.up = [0, 0, 1];
  const load = tile => {
    if (tile.state || !tile.content) return;
    tile.state = "loading"; requested++;
    const uri = new URL(tile.content.uri || tile.content.url, tile.url);
    if (uri.pathname.endsWith(".json")) {
      fetchOk(uri.href, "json").then(ext => { prepare(ext.root, tile.world, uri, tile.depth + 1);
        tile.children = (tile.children || []).concat([ext.root]); tile.state = "ready"; tile.draws = []; loaded++; redraw(); })
        .catch(e => { tile.state = "failed"; fail(e.message); });
      return;
    }
    fetchOk(uri.href).then(buf => { const g = parseGlb(buf);
      tile.draws = g.draws.map(d => ({...d, model: M.mul(M.mul(tile.world, Y_UP_TO_Z_UP), d.model)}));
      tile.state = "ready"; loaded++; redraw(); })
      .catch(e => { tile.state = "failed"; fail(e.message); });
  };
  const ready = t => !t.content || t.state === "ready";
  return {
    select(e, height) {
      const out = [];
      const walk = (tile, refine) => {
        refine = tile.refine || refine;
        const b = bounds(tile);
        const dist = b ? Math.max(1e-9, Math.hypot(...b.center.map((v, i) => v - e[i])) - b.radius) : 1e-9;
        const sse = tile.geometricError * height / (dist * 2 * Math.tan(cam.fovy / 2));
        const kids = tile.children || [];
        const refineIt = kids.length > 0 && sse > 16;
        const own = () => { load(tile); if (tile.state === "ready") for (const d of tile.draws) out.push([d, colors[tile.depth % colors.length]]); };
        if (!refineIt) return own();
        if (refine === "ADD") { own(); for (const c of kids) walk(c, refine); return; }
        for (const c of kids) load(c);
        if (kids.every(ready)) for (const c of kids) walk(c, refine); else own();
      };
      walk(root.root, root.root.refine || "REPLACE");
      return out;
    },
    describe() { return `${loaded} of ${requested} tiles loaded`; }
  };
}

async function main() {
  if (!gl) return fail("this browser has no WebGL 2");
  if (!/^[0-9a-f]{32}$/.test(job)) return fail("give ?job=ID");
  prog = program();
  const res = await fetchOk("/jobs/" + job + "/results", "json");
  if (res.tiles) scene = await tilesetScene(res.tiles.href);
  else if (res.glb) scene = await glbScene(res.glb.href);
  else return fail("the job has neither tiles nor lods.glb");
  document.title = "lodstream viewer: " + job.slice(0, 8) + (res.tiles ? " (3D Tiles)" : " (lods.glb)");
  window.onresize = redraw;
  redraw();
}
main().catch(e => fail(e.message));
</script>
</body>
</html>
)HTML";
  return page;
}

}  // namespace lodstream::serve
