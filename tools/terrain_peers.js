#!/usr/bin/env node
// The two terrain meshers users pick today, run on a Terrain-RGB tile for tools/bench_grid.sh:
//   - Martini (npm @mapbox/martini): right-triangulated irregular network (RTIN; Evans, Kirkpatrick and
//     Townsend, "Right-Triangulated Irregular Networks", Algorithmica 2001). Needs a (2^k+1)² grid: the
//     512² tile is padded to 513² by repeating its last row and column, as Martini's README does.
//   - Delatin (npm delatin, github.com/mapbox/delatin): greedy Delaunay refinement (Garland and Heckbert,
//     "Fast Polygonal Approximation of Terrains and Height Fields", 1995), run until its max error <= e.
// Heights: -10000 + (R·65536 + G·256 + B) / 10 metres (Mapbox Terrain-RGB), decoded with npm pngjs.
//
// Usage: node tools/terrain_peers.js TILE.png [--errors 1,5,20] [--runs 3]
// Prints one JSON object per line and per (tool, max error):
//   {tool, max_error, triangles, vertices, seconds, measured_max_error, runs}
// seconds: median over the runs of everything it takes to mesh the tile from its heights (Martini: new
// Martini(513), its per-size precompute, + createTile + getMesh; Delatin: constructor + run), as lodstream's
// time is (its subdivide + index stages); Martini's also without the constructor as seconds_reused (an
// application meshing many tiles of one size builds it once). PNG decoding is excluded for all and reported
// once as {tool: "decode", seconds}. Each run is in this one process, so the median is of JIT-warm runs.
// measured_max_error: the largest |height - mesh| over every sample of the 512² tile, the mesh interpolated
// linearly on its triangles (the same vertical error both tools bound), checked here independently.
// Martini's own threshold does not bound that error (see below), so Martini runs twice per e: "martini"
// with getMesh(e) as users call it, and "martini-bounded" with the threshold that keeps the measured error
// within e.
// Exit status: 0, 2 bad usage or unreadable tile, 77 packages missing (the output starts with "skipped:").
// Packages are looked up in $LODSTREAM_NPM_PREFIX/node_modules, then $HOME/.cache/lodstream-npm/node_modules
// (tools/bench_grid.sh installs them there).
'use strict';

const fs = require('fs');
const path = require('path');
const { pathToFileURL } = require('url');

const { findModule } = require('./npm_modules');

// delatin is an ES module only; Martini and pngjs are CommonJS.
async function load(name) {
  const dir = findModule(name);
  if (!dir) return null;
  const pkg = JSON.parse(fs.readFileSync(path.join(dir, 'package.json'), 'utf8'));
  if (pkg.type === 'module') {
    const mod = await import(pathToFileURL(path.join(dir, pkg.module || pkg.main || 'index.js')).href);
    return mod.default || mod;
  }
  return require(dir);
}

function median(values) {
  const s = [...values].sort((a, b) => a - b);
  const n = s.length;
  return n % 2 ? s[(n - 1) / 2] : (s[n / 2 - 1] + s[n / 2]) / 2;
}

function seconds(t0) { return Number(process.hrtime.bigint() - t0) / 1e9; }

// Largest |z - mesh| over the samples (x, y) of a w × h grid with 0 <= x < w, 0 <= y < h, the mesh given
// by vertex grid coordinates xy (pairs) and triangle indices; z holds heights with row stride `stride`.
// Every sample must lie in some triangle (both meshes cover the grid's rectangle); an uncovered sample
// counts as an infinite error.
function measuredMaxError(z, stride, w, h, xy, tris) {
  const err = new Float64Array(w * h).fill(Infinity);
  for (let t = 0; t < tris.length; t += 3) {
    const a = tris[t], b = tris[t + 1], c = tris[t + 2];
    const ax = xy[2 * a], ay = xy[2 * a + 1], bx = xy[2 * b], by = xy[2 * b + 1], cx = xy[2 * c], cy = xy[2 * c + 1];
    const za = z[ay * stride + ax], zb = z[by * stride + bx], zc = z[cy * stride + cx];
    const det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
    if (det === 0) continue;
    const x0 = Math.max(0, Math.min(ax, bx, cx)), x1 = Math.min(w - 1, Math.max(ax, bx, cx));
    const y0 = Math.max(0, Math.min(ay, by, cy)), y1 = Math.min(h - 1, Math.max(ay, by, cy));
    for (let y = y0; y <= y1; y++) {
      for (let x = x0; x <= x1; x++) {
        // Barycentric coordinates; integer vertex coordinates make the inside test exact.
        const l1 = (x - ax) * (cy - ay) - (cx - ax) * (y - ay);
        const l2 = (bx - ax) * (y - ay) - (x - ax) * (by - ay);
        const inside = det > 0 ? l1 >= 0 && l2 >= 0 && l1 + l2 <= det : l1 <= 0 && l2 <= 0 && l1 + l2 >= det;
        if (!inside) continue;
        const zm = za + ((zb - za) * l1 + (zc - za) * l2) / det;
        const e = Math.abs(z[y * stride + x] - zm);
        const k = y * w + x;
        // A sample on a shared edge gets the same value from both sides; keep the first finite one.
        if (err[k] === Infinity) err[k] = e;
      }
    }
  }
  let worst = 0;
  for (let k = 0; k < err.length; k++) if (err[k] > worst) worst = err[k];
  return worst;
}

async function main() {
  const args = process.argv.slice(2);
  let tile = null;
  let errors = [1, 5, 20];
  let runs = 3;
  for (let i = 0; i < args.length; i++) {
    if (args[i] === '--errors') errors = args[++i].split(',').map(Number);
    else if (args[i] === '--runs') runs = Number(args[++i]);
    else if (!tile && !args[i].startsWith('--')) tile = args[i];
    else { console.error(`terrain_peers: unknown argument ${args[i]}`); process.exit(2); }
  }
  if (!tile || !(runs >= 1) || errors.some((e) => !(e >= 0))) {
    console.error('usage: node tools/terrain_peers.js TILE.png [--errors 1,5,20] [--runs 3]');
    process.exit(2);
  }
  const [Martini, Delatin, pngjs] = await Promise.all([load('@mapbox/martini'), load('delatin'), load('pngjs')]);
  if (!Martini || !Delatin || !pngjs) {
    console.log('skipped: npm packages @mapbox/martini, delatin and pngjs are not installed ' +
                '(tools/bench_grid.sh installs them into ~/.cache/lodstream-npm)');
    process.exit(77);
  }

  let bytes;
  try { bytes = fs.readFileSync(tile); } catch (e) { console.error(`terrain_peers: ${tile}: ${e.message}`); process.exit(2); }
  const t0 = process.hrtime.bigint();
  const png = pngjs.PNG.sync.read(bytes);  // always RGBA, 8 bits per channel
  const w = png.width, h = png.height;
  const heights = new Float32Array(w * h);
  for (let k = 0; k < w * h; k++) {
    const r = png.data[4 * k], g = png.data[4 * k + 1], b = png.data[4 * k + 2];
    heights[k] = (r * 65536 + g * 256 + b) / 10 - 10000;
  }
  console.log(JSON.stringify({ tool: 'decode', width: w, height: h, seconds: seconds(t0) }));

  // Martini's grid: the smallest 2^k + 1 >= max(w, h) + 1, the tile in its top-left corner, the rest filled
  // by repeating the last column and row (for a 512 tile: exactly the README's 513 backfill).
  let size = 2;
  while (size + 1 < Math.max(w, h) + 1) size *= 2;
  const gridSize = size + 1;
  const padded = new Float32Array(gridSize * gridSize);
  for (let y = 0; y < gridSize; y++) {
    for (let x = 0; x < gridSize; x++) padded[y * gridSize + x] = heights[Math.min(y, h - 1) * w + Math.min(x, w - 1)];
  }
  const martini = new Martini(gridSize);  // untimed: for the threshold search of martini-bounded
  // One timed run: {mesh, seconds (constructor included), seconds_reused (without it)}.
  const martiniRun = (threshold) => {
    const t = process.hrtime.bigint();
    const m = new Martini(gridSize);
    const t1 = process.hrtime.bigint();
    const mesh = m.createTile(padded).getMesh(threshold);
    return { mesh, seconds: seconds(t), seconds_reused: seconds(t1) };
  };
  const martiniRuns = (threshold) => {
    const all = [];
    for (let r = 0; r < runs; r++) all.push(martiniRun(threshold));
    return { mesh: all[all.length - 1].mesh, seconds: median(all.map((x) => x.seconds)),
             seconds_reused: median(all.map((x) => x.seconds_reused)) };
  };

  for (const maxError of errors) {
    const { mesh, seconds: secs, seconds_reused } = martiniRuns(maxError);
    // Martini's vertices are grid coordinates (x, y) in a Uint16Array; measured on the 513² grid it meshes.
    const measured = measuredMaxError(padded, gridSize, gridSize, gridSize, mesh.vertices, mesh.triangles);
    console.log(JSON.stringify({
      tool: 'martini', max_error: maxError, triangles: mesh.triangles.length / 3, vertices: mesh.vertices.length / 2,
      seconds: secs, seconds_reused, measured_max_error: measured, runs, grid: `${gridSize}x${gridSize}`,
    }));
  }

  // Martini's error is the RTIN one: a vertex's deviation from the midpoint of the hypotenuse that omits
  // it, accumulated up the hierarchy; the final mesh can be off by more than maxError between vertices.
  // "martini-bounded" is Martini with the largest threshold whose measured max error is <= e, found by a
  // binary search over the tile's distinct error values (the search is not timed: a user would need it too,
  // but it is a wrapper around Martini, not Martini).
  const tileForSearch = martini.createTile(padded);
  const thresholds = Float64Array.from(new Set(tileForSearch.errors)).sort();
  const measureAt = (threshold) => {
    const m = tileForSearch.getMesh(threshold);
    return measuredMaxError(padded, gridSize, gridSize, gridSize, m.vertices, m.triangles);
  };
  for (const maxError of errors) {
    // Invariant: measureAt(thresholds[lo]) <= maxError (threshold 0 keeps every vertex: error 0).
    let lo = 0, hi = thresholds.length - 1;
    if (measureAt(thresholds[hi]) <= maxError) lo = hi;
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (measureAt(thresholds[mid]) <= maxError) lo = mid; else hi = mid;
    }
    const threshold = thresholds[lo];
    const { mesh, seconds: secs, seconds_reused } = martiniRuns(threshold);
    const measured = measuredMaxError(padded, gridSize, gridSize, gridSize, mesh.vertices, mesh.triangles);
    console.log(JSON.stringify({
      tool: 'martini-bounded', max_error: maxError, threshold, triangles: mesh.triangles.length / 3,
      vertices: mesh.vertices.length / 2, seconds: secs, seconds_reused, measured_max_error: measured, runs,
      grid: `${gridSize}x${gridSize}`,
    }));
  }

  for (const maxError of errors) {
    const times = [];
    let tin = null;
    for (let r = 0; r < runs; r++) {
      const t = process.hrtime.bigint();
      tin = new Delatin(heights, w, h);
      tin.run(maxError);
      times.push(seconds(t));
    }
    const measured = measuredMaxError(heights, w, w, h, tin.coords, tin.triangles);
    console.log(JSON.stringify({
      tool: 'delatin', max_error: maxError, triangles: tin.triangles.length / 3, vertices: tin.coords.length / 2,
      seconds: median(times), measured_max_error: measured, runs, grid: `${w}x${h}`,
    }));
  }
}

main().catch((e) => { console.error(`terrain_peers: ${e.stack || e}`); process.exit(2); });
