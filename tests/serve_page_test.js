#!/usr/bin/env node
// The job server's web page in headless Chromium (issue 17.4), driven over the DevTools protocol.
//
// Usage: node tests/serve_page_test.js LODSTREAM_CLI SOURCE_DIR [SCREENSHOT.png]
// (node 20 has WebSocket behind --experimental-websocket: the script runs itself again with it.)
//
// Starts `lodstream serve` with a token on an ephemeral port and Chromium; the page first asks for the
// token (401 page), then the jobs page submits a simplify job through its form and the test watches the
// job's progress bar until it shows 100 %, with the percentages it saw rising; a job with a report must
// show a report.html link that opens. Takes a screenshot (a PNG that is not one flat colour). Prints
// "skipped: ..." and exits 0 when Chromium or node's WebSocket is missing. No package beyond node.
"use strict";
const {spawn} = require("child_process");
const fs = require("fs");
const os = require("os");
const path = require("path");
const zlib = require("zlib");

const [cli, src, shotArg] = process.argv.slice(2);
const chromiumBin = process.env.CHROMIUM || "/usr/bin/chromium";
const TOKEN = "page-test-token-0123456789abcdef";
let failures = 0, passed = 0;

function check(cond, what) {
  if (cond) passed++;
  else { failures++; console.log("FAIL: " + what); }
}
const sleep = ms => new Promise(r => setTimeout(r, ms));

async function until(fn, what, timeoutMs) {
  const end = Date.now() + timeoutMs;
  for (;;) {
    const v = await fn();
    if (v) return v;
    if (Date.now() > end) throw new Error("timed out waiting for " + what);
    await sleep(100);
  }
}

function firstLine(stream) {
  return new Promise((resolve, reject) => {
    let buf = "";
    stream.on("data", d => {
      buf += d;
      const nl = buf.indexOf("\n");
      if (nl >= 0) resolve(buf.slice(0, nl));
    });
    stream.on("end", () => reject(new Error("no output: " + buf)));
  });
}

// Whether a PNG's decoded rows hold more than one colour (filters undone only as far as needed: any
// row filter of a flat image leaves a constant row, so a flat image has every row equal after filter 0/1/2
// differencing too; comparing the raw filtered bytes of rows beyond their filter byte is enough here).
function pngNotFlat(buf) {
  let pos = 8, idat = [];
  while (pos < buf.length) {
    const len = buf.readUInt32BE(pos), type = buf.toString("latin1", pos + 4, pos + 8);
    if (type === "IDAT") idat.push(buf.subarray(pos + 8, pos + 8 + len));
    pos += 12 + len;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const values = new Set();
  for (let i = 0; i < raw.length && values.size < 3; i += 997) values.add(raw[i]);
  return values.size >= 3;
}

async function main() {
  if (!fs.existsSync(chromiumBin)) { console.log("skipped: no Chromium at " + chromiumBin); return 0; }
  if (typeof WebSocket === "undefined") {
    if (process.env.LODSTREAM_PAGE_TEST_REEXEC) { console.log("skipped: node has no WebSocket"); return 0; }
    const r = require("child_process").spawnSync(process.execPath, ["--experimental-websocket", "--no-warnings", ...process.argv.slice(1)],
                                                 {stdio: "inherit", env: {...process.env, LODSTREAM_PAGE_TEST_REEXEC: "1"}});
    if (r.status === 9) { console.log("skipped: node has no WebSocket (needs node 20.10 or later)"); return 0; }
    return r.status === null ? 1 : r.status;
  }
  const tmp = fs.mkdtempSync(path.join(os.tmpdir(), "lodstream-serve-page-"));
  const procs = [];
  try {
    fs.mkdirSync(path.join(tmp, "data"));
    fs.copyFileSync(path.join(src, "tests", "data", "sample-room.ply"), path.join(tmp, "data", "room.ply"));
    fs.writeFileSync(path.join(tmp, "token"), TOKEN + "\n");
    const server = spawn(cli, ["serve", "--bind", "127.0.0.1:0", "--data-root", path.join(tmp, "data"), "--jobs-dir",
                               path.join(tmp, "jobs"), "--token-file", path.join(tmp, "token"), "--max-jobs", "2",
                               "--memory", "1G", "--job-threads", "1"], {stdio: ["ignore", "pipe", "inherit"]});
    procs.push(server);
    const port = Number((await firstLine(server.stdout)).match(/127\.0\.0\.1:(\d+)/)[1]);
    const base = `http://127.0.0.1:${port}`;

    const profile = path.join(tmp, "profile");
    const chromium = spawn(chromiumBin, ["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-proxy-server",
                                         "--remote-debugging-port=0", "--user-data-dir=" + profile,
                                         "--window-size=1400,900", "about:blank"], {stdio: "ignore"});
    procs.push(chromium);
    const portFile = path.join(profile, "DevToolsActivePort");
    await until(() => fs.existsSync(portFile) && fs.readFileSync(portFile, "utf8").includes("\n"), "Chromium", 60000);
    const devPort = fs.readFileSync(portFile, "utf8").split("\n")[0];
    const targets = await (await fetch(`http://127.0.0.1:${devPort}/json/list`)).json();
    const ws = new WebSocket(targets.find(t => t.type === "page").webSocketDebuggerUrl);
    await new Promise((resolve, reject) => { ws.onopen = resolve; ws.onerror = reject; });
    let nextId = 1;
    const pending = new Map();
    ws.onmessage = ev => {
      const m = JSON.parse(ev.data);
      if (m.id && pending.has(m.id)) { pending.get(m.id)(m); pending.delete(m.id); }
    };
    const send = (method, params) => new Promise(resolve => {
      const id = nextId++;
      pending.set(id, resolve);
      ws.send(JSON.stringify({id, method, params: params || {}}));
    });
    const evaluate = async expression => {
      const r = await send("Runtime.evaluate", {expression, returnByValue: true, awaitPromise: true});
      if (r.result.exceptionDetails) throw new Error("page script: " + JSON.stringify(r.result.exceptionDetails));
      return r.result.result.value;
    };
    const api = async (method, p, body) => {
      const r = await fetch(base + p, {method, headers: {Authorization: "Bearer " + TOKEN, "Content-Type": "application/json"},
                                       body: body ? JSON.stringify(body) : undefined});
      return [r.status, await r.json()];
    };
    await send("Page.enable");

    // The token page, then the jobs page.
    await send("Page.navigate", {url: base + "/"});
    await until(() => evaluate("document.readyState === 'complete' && !!document.getElementById('t')"), "the token page", 90000);
    check(true, "token page first");
    await evaluate(`document.getElementById('t').value = ${JSON.stringify(TOKEN)}; document.getElementById('f').requestSubmit(); true`);
    await until(() => evaluate("document.readyState === 'complete' && !!document.getElementById('submit-form')"), "the jobs page", 90000);
    check(true, "jobs page after the token");

    // A job with a report, through the API: its row must link report.html.
    const [st, reported] = await api("POST", "/processes/simplify/execution",
                                     {inputs: {input: "room.ply", report: true, views: 1, samples: 2000}});
    check(st === 201, "API submit: 201");

    // A job through the form; watch its bar to 100 %.
    await evaluate(`(() => {
      document.getElementById('f-input').value = 'room.ply';
      document.getElementById('f-levels').value = '3';
      document.getElementById('f-report').checked = false;
      document.getElementById('submit-form').requestSubmit();
      return true; })()`);
    const job = await until(() => evaluate("document.getElementById('form-status').dataset.job || ''"), "the form's job", 30000);
    const seen = [];
    const row = `document.querySelector('tr[data-job="${job}"]')`;
    await until(async () => {
      const r = await evaluate(`(() => { const r = ${row}; return r && {status: r.dataset.status,
        bar: r.querySelector('progress').value, text: r.querySelector('.pct').textContent}; })()`);
      if (r) seen.push(r);
      return r && (r.status === "successful" || r.status === "failed");
    }, "the form's job to end", 180000);
    const last = seen[seen.length - 1];
    check(last.status === "successful" && last.bar === 100 && last.text === "100 %",
          "progress bar at 100 %: " + JSON.stringify(last));
    const bars = seen.map(s => s.bar);
    check(bars.every((b, i) => i === 0 || b >= bars[i - 1]), "progress never goes back: " + bars.join(","));
    const [, js] = await api("GET", "/jobs/" + job);
    check(js.inputs.levels === 3 && js.inputs.report === false, "the form sent its inputs: " + JSON.stringify(js.inputs));
    await until(() => evaluate(`!!(${row} && ${row}.querySelector('a[href$="lods.glb"]'))`), "the GLB link", 10000);
    check(true, "GLB link in the row");

    const reportHref = await until(() => evaluate(`(() => { const r = document.querySelector('tr[data-job="${reported.jobID}"]');
      const a = r && r.querySelector('a[href$="report.html"]'); return a ? a.getAttribute('href') : ''; })()`),
      "the report.html link", 240000);
    check(reportHref === `/jobs/${reported.jobID}/files/report.html`, "report.html linked: " + reportHref);

    // A bad input: the form shows the server's message naming the field.
    await evaluate(`(() => { document.getElementById('f-input').value = '../etc/passwd';
      document.getElementById('submit-form').requestSubmit(); return true; })()`);
    const err = await until(() => evaluate(`(() => { const s = document.getElementById('form-status');
      return s.className === 'error' ? s.textContent : ''; })()`), "the form's error", 30000);
    check(err.includes("inputs.input"), "form error names the field: " + err);

    const shot = await send("Page.captureScreenshot", {format: "png"});
    const png = Buffer.from(shot.result.data, "base64");
    if (shotArg) fs.writeFileSync(shotArg, png);
    check(png.length > 5000 && pngNotFlat(png), "screenshot is a picture (" + png.length + " bytes)");

    // The viewer: lods.glb (this job has no tiles), then a tileset. The tileset is written here by hand, a
    // stand-in for the `--tiles` output (a root and one child, both pointing at lods.glb), to exercise the
    // viewer's traversal, REPLACE refinement and content fetches.
    check(await evaluate(`!!${row}.querySelector('a[href="/viewer?job=${job}"]')`), "viewer link in the row");
    const viewerStatus = async (what, done) => {
      await send("Page.navigate", {url: `${base}/viewer?job=${job}`});
      return until(() => evaluate(`(() => { const e = document.getElementById('viewer-status');
        const t = e ? e.textContent : ''; return t; })()`).then(t => (t.startsWith("error") || done.test(t)) && t), what, 60000);
    };
    const glbStatus = await viewerStatus("the GLB viewer", /^ok/);
    check(/^ok: [1-9]\d* triangles drawn, level 1 of/.test(glbStatus), "viewer draws lods.glb: " + glbStatus);
    const view = Buffer.from((await send("Page.captureScreenshot", {format: "png"})).result.data, "base64");
    if (shotArg) fs.writeFileSync(shotArg.replace(/\.png$/, "") + "-viewer.png", view);
    check(pngNotFlat(view), "viewer screenshot is a picture");
    const sphere = [3.6, -1, 2.8, 5];
    fs.mkdirSync(path.join(tmp, "jobs", job, "out", "tiles"));
    fs.writeFileSync(path.join(tmp, "jobs", job, "out", "tiles", "tileset.json"), JSON.stringify({
      asset: {version: "1.1"}, geometricError: 100,
      root: {boundingVolume: {sphere}, geometricError: 50, refine: "REPLACE", content: {uri: "../lods.glb"},
             children: [{boundingVolume: {sphere}, geometricError: 0, content: {uri: "../lods.glb"}}]}}));
    const tilesStatus = await viewerStatus("the tiles viewer", /2 of 2 tiles loaded/);
    check(/^ok: [1-9]\d* triangles drawn, 2 of 2 tiles loaded/.test(tilesStatus), "viewer draws the tileset: " + tilesStatus);

    // The report opens in the browser (the cookie carries the token).
    await send("Page.navigate", {url: base + reportHref});
    const title = await until(() => evaluate("document.readyState === 'complete' ? document.title : ''"), "report.html", 30000);
    check(/report/i.test(title), "report.html opens: " + title);
    ws.close();
  } finally {
    for (const p of procs) p.kill("SIGTERM");
    await sleep(500);
    fs.rmSync(tmp, {recursive: true, force: true});
  }
  console.log(`${passed} passed, ${failures} failed`);
  return failures ? 1 : 0;
}

main().then(code => process.exit(code), e => { console.log("FAIL: " + e.message); console.log(`${passed} passed, ${failures + 1} failed`); process.exit(1); });
