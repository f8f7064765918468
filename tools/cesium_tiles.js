#!/usr/bin/env node
// Loads a 3D Tiles tileset in CesiumJS (npm `cesium`) in headless Chromium (npm `puppeteer-core`, the
// browser at $CHROMIUM or /usr/bin/chromium; WebGL by SwiftShader), globe, imagery and network off, from
// three camera distances. For each view, in a fresh page with the cache off: waits until the tileset's
// tilesLoaded, renders, saves a screenshot and counts the pixels that differ from the background; the
// local HTTP server counts the tile requests and bytes it served for that view.
//
// Usage: node tools/cesium_tiles.js TILES_DIR OUT_DIR [NAME:DISTANCE[:TX,TY,TZ|:dense] ...]
//   DISTANCE in units of the tileset's bounding-sphere radius (default near:0.08 district:0.4 whole:2.5),
//   T the target offset from the sphere's center, also in radii (tileset frame, Z up; default 0,0,0);
//   `dense`: the target is the center of the level-0 tile with the most triangles (tile extras).
// Prints one JSON object: {"views": [{name, distance, tiles_loaded, tiles, bytes, nonblank, screenshot}]}.
// Exit status: 0 done (the caller judges the figures), 2 bad usage or failure, 77 cesium, puppeteer-core or
// Chromium not installed (the output then starts with "skipped:"). Packages are looked up in
// $LODSTREAM_NPM_PREFIX/node_modules, then $HOME/.cache/lodstream-npm/node_modules (tools/install_tiles_tools.sh).
'use strict';

const fs = require('fs');
const http = require('http');
const path = require('path');

const { findModule } = require('./npm_modules');

const types = {'.js': 'text/javascript', '.css': 'text/css', '.json': 'application/json', '.glb': 'model/gltf-binary',
               '.html': 'text/html', '.png': 'image/png', '.wasm': 'application/wasm'};

const page_html = `<!doctype html><html><head><meta charset="utf-8">
<link rel="stylesheet" href="/cesium/Widgets/widgets.css">
<style>html,body,#c{margin:0;padding:0;width:100%;height:100%;overflow:hidden;background:#000}
.cesium-viewer-bottom{display:none}</style>
<script>window.CESIUM_BASE_URL = '/cesium/';</script><script src="/cesium/Cesium.js"></script></head>
<body><div id="c"></div><script>
async function view(distance, offset) {
  const viewer = new Cesium.Viewer('c', {globe: false, baseLayer: false, baseLayerPicker: false, geocoder: false,
    timeline: false, animation: false, skyBox: false, skyAtmosphere: false, sceneModePicker: false,
    navigationHelpButton: false, homeButton: false, fullscreenButton: false, infoBox: false,
    selectionIndicator: false, shadows: false, contextOptions: {webgl: {preserveDrawingBuffer: true}}});
  viewer.scene.backgroundColor = Cesium.Color.BLACK;
  viewer.scene.fog.enabled = false;
  const tileset = await Cesium.Cesium3DTileset.fromUrl('/tiles/tileset.json');
  viewer.scene.primitives.add(tileset);
  const s = tileset.boundingSphere;
  let center = s.center;
  if (offset === 'dense') {
    // The center of the finest level's tile with the most triangles (extras written by lodstream): a
    // place with buildings, where the sphere's center of a scene with outlying parts may be empty air.
    let best = null;
    const visit = (t) => {
      const e = t.extras;
      if (e && e.level === 0 && (!best || e.triangles > best.extras.triangles)) best = t;
      for (const c of t.children) visit(c);
    };
    visit(tileset.root);
    if (best) center = best.boundingSphere.center;
    offset = [0, 0, 0];
  }
  const target = Cesium.Cartesian3.add(center, new Cesium.Cartesian3(offset[0] * s.radius, offset[1] * s.radius,
                                       offset[2] * s.radius), new Cesium.Cartesian3());
  // A local frame at the target with the tileset's axes (Z up), not the globe's east-north-up there
  // (undefined near the Earth's center, where an untransformed tileset lies).
  viewer.camera.lookAtTransform(Cesium.Matrix4.fromTranslation(target),
                                new Cesium.HeadingPitchRange(0.6, -0.45, distance * s.radius));
  viewer.scene.light = new Cesium.DirectionalLight({direction: viewer.camera.directionWC});
  const t0 = performance.now();
  await new Promise((resolve) => {
    const poll = () => (tileset.tilesLoaded && performance.now() - t0 > 500) || performance.now() - t0 > 240000
                       ? resolve() : setTimeout(poll, 100);
    poll();
  });
  for (let i = 0; i < 3; ++i) { viewer.scene.requestRender(); viewer.render(); }
  const canvas = viewer.scene.canvas, ctx = document.createElement('canvas').getContext('2d');
  ctx.canvas.width = canvas.width; ctx.canvas.height = canvas.height;
  ctx.drawImage(canvas, 0, 0);
  const px = ctx.getImageData(0, 0, canvas.width, canvas.height).data;
  let lit = 0;
  for (let i = 0; i < px.length; i += 4) if (px[i] > 8 || px[i + 1] > 8 || px[i + 2] > 8) ++lit;
  return {tiles_loaded: tileset.tilesLoaded, nonblank: lit / (px.length / 4),
          seconds: (performance.now() - t0) / 1000, radius: s.radius};
}
</script></body></html>`;

async function main() {
  const args = process.argv.slice(2);
  if (args.length < 2) {
    console.error('usage: node tools/cesium_tiles.js TILES_DIR OUT_DIR [NAME:DISTANCE[:TX,TY,TZ|:dense] ...]');
    return 2;
  }
  const [tiles, out] = args;
  const views = (args.length > 2 ? args.slice(2) : ['near:0.08', 'district:0.4', 'whole:2.5']).map((v) => {
    const [name, d, t] = v.split(':');
    return {name, distance: Number(d), offset: t === 'dense' ? t : t ? t.split(',').map(Number) : [0, 0, 0]};
  });
  const cesium = findModule('cesium'), puppeteerDir = findModule('puppeteer-core');
  const chromium = process.env.CHROMIUM || '/usr/bin/chromium';
  if (!cesium || !puppeteerDir || !fs.existsSync(chromium)) {
    console.log('skipped: ' + (!cesium ? 'npm package cesium' : !puppeteerDir ? 'npm package puppeteer-core' : chromium) +
                ' not found (run tools/install_tiles_tools.sh, or set LODSTREAM_NPM_PREFIX / CHROMIUM)');
    return 77;
  }
  const roots = {'/cesium/': path.join(cesium, 'Build', 'Cesium'), '/tiles/': path.resolve(tiles)};
  const counter = {tiles: 0, bytes: 0};
  const server = http.createServer((req, res) => {
    const url = decodeURIComponent(req.url.split('?')[0]);
    if (url === '/' || url === '/index.html') {
      res.writeHead(200, {'Content-Type': 'text/html'});
      return res.end(page_html);
    }
    for (const [prefix, dir] of Object.entries(roots)) {
      if (!url.startsWith(prefix)) continue;
      const file = path.join(dir, path.normalize(url.slice(prefix.length)));
      if (!file.startsWith(dir) || !fs.existsSync(file) || !fs.statSync(file).isFile()) break;
      const body = fs.readFileSync(file);
      if (prefix === '/tiles/') { counter.bytes += body.length; if (file.endsWith('.glb')) ++counter.tiles; }
      res.writeHead(200, {'Content-Type': types[path.extname(file)] || 'application/octet-stream'});
      return res.end(body);
    }
    res.writeHead(404);
    res.end();
  });
  await new Promise((r) => server.listen(0, '127.0.0.1', r));
  const base = `http://127.0.0.1:${server.address().port}/`;
  const puppeteer = require(puppeteerDir);
  const browser = await puppeteer.launch({executablePath: chromium, headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
           '--window-size=800,600'], defaultViewport: {width: 800, height: 600}});
  fs.mkdirSync(out, {recursive: true});
  const results = [];
  try {
    for (const v of views) {
      const page = await browser.newPage();
      await page.setCacheEnabled(false);
      // No network beyond the local server (Cesium asks for nothing else with globe, imagery and ion off).
      await page.setRequestInterception(true);
      page.on('request', (r) => (r.url().startsWith(base) || r.url().startsWith('data:') || r.url().startsWith('blob:')
                                 ? r.continue() : r.abort()));
      await page.goto(base, {waitUntil: 'load'});
      counter.tiles = 0; counter.bytes = 0;
      const r = await page.evaluate((d, o) => view(d, o), v.distance, v.offset);
      const shot = path.join(out, `cesium-${v.name}.png`);
      await page.screenshot({path: shot});
      results.push({name: v.name, distance: v.distance * r.radius, tiles_loaded: r.tiles_loaded, tiles: counter.tiles,
                    bytes: counter.bytes, nonblank: r.nonblank, seconds: r.seconds, screenshot: shot});
      await page.close();
    }
  } finally {
    await browser.close();
    server.close();
  }
  console.log(JSON.stringify({views: results}, null, 1));
  return 0;
}

main().then((code) => process.exit(code), (e) => { console.error(e && e.stack || e); process.exit(2); });
