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

}  // namespace lodstream::serve
