#!/usr/bin/env python3
"""End-to-end test of `lodstream serve` (issue 17) on the sample room, with an ephemeral port.

Usage: tests/serve_test.py LODSTREAM_CLI SOURCE_DIR

Checks: landing page, conformance, process descriptions; 401 without (or with a wrong) token; a job
submitted, polled to successful, its results fetched whole and with Range (206, Content-Range, 416 past the
end), its files byte-identical to the CLI's own run; 400 naming the bad field (type, enum, unknown input,
missing input, memory); paths outside the data root refused (.., absolute, a symlink out of the root,
traversal in a file URL); uploads (201, and 413 over the cap); bounded bodies and headers; an idle client
timed out; the report and grid processes; admission by --max-jobs and --memory; a job whose child is killed ends failed and the server lives; a server killed with kill -9 in
the middle of a job restarts and the job resumes to identical bytes; SIGTERM drains (exit 0, the job queued
again) and the job completes after the next start; DELETE cancels and dismisses. Standard library only.
"""
import http.client
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

CLI, SRC = sys.argv[1], sys.argv[2]
ROOM = os.path.join(SRC, "tests", "data", "sample-room.ply")
TOKEN = "t0k3n-for-the-serve-test-0123456789"
failures = []
passed = 0


def check(cond, what):
    global passed
    if cond:
        passed += 1
    else:
        failures.append(what)
        print("FAIL:", what, flush=True)


class Server:
    def __init__(self, tmp, *extra):
        self.tmp = tmp
        opts = {"--bind": "127.0.0.1:0", "--data-root": os.path.join(tmp, "data"), "--jobs-dir": os.path.join(tmp, "jobs"),
                "--token-file": os.path.join(tmp, "token"), "--max-jobs": "2", "--memory": "1G", "--job-threads": "1"}
        opts.update(zip(extra[::2], extra[1::2]))
        self.proc = subprocess.Popen([CLI, "serve", *[x for kv in opts.items() for x in kv]], stdout=subprocess.PIPE,
                                     stderr=open(os.path.join(tmp, "server.err"), "ab"))
        line = self.proc.stdout.readline().decode()
        if "listening on http://127.0.0.1:" not in line:
            raise RuntimeError("server did not start: " + line)
        self.port = int(line.split("http://127.0.0.1:")[1].split("/")[0])

    def request(self, method, path, body=None, headers=None, token=TOKEN):
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=30)
        h = dict(headers or {})
        if token:
            h["Authorization"] = "Bearer " + token
        if isinstance(body, (dict, list)):
            body = json.dumps(body).encode()
            h.setdefault("Content-Type", "application/json")
        conn.request(method, path, body=body, headers=h)
        r = conn.getresponse()
        data = r.read()
        conn.close()
        return r.status, dict((k.lower(), v) for k, v in r.getheaders()), data

    def json(self, method, path, body=None, **kw):
        status, headers, data = self.request(method, path, body, **kw)
        try:
            return status, headers, json.loads(data)
        except ValueError:
            return status, headers, None

    def children(self, job=""):
        """Pids of the server's children; with `job`, only that job's (its id is in their argv)."""
        kids = []
        for pid in os.listdir("/proc"):
            if pid.isdigit():
                try:
                    with open(f"/proc/{pid}/stat") as f:
                        stat = f.read()
                except OSError:
                    continue
                if int(stat.rsplit(")", 1)[1].split()[1]) == self.proc.pid:
                    try:
                        with open(f"/proc/{pid}/cmdline", "rb") as f:
                            argv = f.read()
                    except OSError:
                        continue
                    if job.encode() in argv:
                        kids.append(int(pid))
        return kids

    def stop(self, sig=signal.SIGTERM, timeout=60):
        self.proc.send_signal(sig)
        return self.proc.wait(timeout=timeout)


def submit(srv, inputs):
    status, headers, body = srv.json("POST", "/processes/simplify/execution", {"inputs": inputs})
    check(status == 201 and headers.get("location") == "/jobs/" + body["jobID"], f"submit: 201 with Location ({status})")
    return body["jobID"]


def wait_status(srv, job, want, timeout=180):
    end = time.time() + timeout
    while time.time() < end:
        status, _, s = srv.json("GET", "/jobs/" + job)
        if status == 200 and s["status"] in want:
            return s
        time.sleep(0.1)
    raise RuntimeError(f"job {job} not {want} within {timeout} s: {s}")


def running_child(srv, job, min_progress=0, timeout=60):
    """The pid of the job's child once it has reached min_progress; None when the job ended first."""
    end = time.time() + timeout
    while time.time() < end:
        _, _, s = srv.json("GET", "/jobs/" + job)
        if s["status"] not in ("accepted", "running"):
            return None
        kids = srv.children(job)
        if s["status"] == "running" and kids and s["progress"] >= min_progress:
            return kids[0]
        time.sleep(0.02)
    return None


def level_files(out):
    return sorted(f for f in os.listdir(out) if f.startswith("lod") and (f.endswith(".ply") or f.endswith(".glb")))


def same_outputs(out, ref):
    names = level_files(ref)
    if names != level_files(out):
        return False
    return all(open(os.path.join(out, n), "rb").read() == open(os.path.join(ref, n), "rb").read() for n in names)


def main():
    tmp = tempfile.mkdtemp(prefix="lodstream-serve-test-")
    try:
        os.makedirs(os.path.join(tmp, "data"))
        shutil.copy(ROOM, os.path.join(tmp, "data", "room.ply"))
        shutil.copy(ROOM, os.path.join(tmp, "outside.ply"))
        shutil.copy(os.path.join(SRC, "tests", "data", "grids", "hill.asc"), os.path.join(tmp, "data", "hill.asc"))
        os.symlink(os.path.join(tmp, "outside.ply"), os.path.join(tmp, "data", "link-out.ply"))
        with open(os.path.join(tmp, "token"), "w") as f:
            f.write(TOKEN + "\n")
        ref = os.path.join(tmp, "ref")
        subprocess.run([CLI, "simplify", ROOM, "-o", ref, "--progress", "none"], check=True, stdout=subprocess.DEVNULL)
        run(tmp, ref)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"{passed} passed, {len(failures)} failed")
    return 1 if failures else 0


def run(tmp, ref):
    srv = Server(tmp)
    jobs_dir = os.path.join(tmp, "jobs")

    # Discovery.
    status, _, landing = srv.json("GET", "/", headers={"Accept": "application/json"})
    check(status == 200 and any(l["href"] == "/processes" for l in landing["links"]), "landing page (JSON) links /processes")
    status, headers, page = srv.request("GET", "/", headers={"Accept": "text/html"})
    check(status == 200 and headers["content-type"].startswith("text/html") and b"submit-form" in page, "landing page (HTML)")
    status, _, conf = srv.json("GET", "/conformance")
    check(status == 200 and any(c.endswith("/conf/core") for c in conf["conformsTo"]), "conformance")
    status, _, procs = srv.json("GET", "/processes")
    check(status == 200 and [p["id"] for p in procs["processes"]] == ["simplify", "report", "grid"], "three processes")
    status, _, desc = srv.json("GET", "/processes/simplify")
    check(status == 200 and desc["inputs"]["levels"]["schema"]["type"] == "integer" and "glb" in desc["outputs"],
          "simplify described with JSON Schema")
    check(srv.json("GET", "/processes/nope")[0] == 404, "unknown process: 404")

    # Tokens.
    check(srv.request("GET", "/jobs", token=None)[0] == 401, "no token: 401")
    status, headers, _ = srv.request("GET", "/jobs", token=TOKEN[:-1] + "x")
    check(status == 401 and headers.get("www-authenticate", "").startswith("Bearer"), "wrong token: 401 with WWW-Authenticate")
    check(srv.request("GET", "/jobs", token=None, headers={"Cookie": "lodstream_token=" + TOKEN})[0] == 200, "token cookie: 200")

    # Validation: a 400 naming the field.
    for inputs, field in [({"input": "room.ply", "levels": "x"}, "inputs.levels"),
                          ({"input": "room.ply", "levels": 40}, "inputs.levels"),
                          ({"input": "room.ply", "clustering": "hexagonal"}, "inputs.clustering"),
                          ({"input": "room.ply", "cell_sizes": [0.1, -1]}, "inputs.cell_sizes[1]"),
                          ({"input": "room.ply", "bogus": 1}, "inputs.bogus"),
                          ({"levels": 2}, "inputs.input"),
                          ({"input": "room.ply", "memory": "2G"}, "inputs.memory"),
                          ({"input": "../outside.ply"}, "inputs.input"),
                          ({"input": os.path.join(tmp, "outside.ply")}, "inputs.input"),
                          ({"input": "link-out.ply"}, "inputs.input"),
                          ({"input": "upload:../../outside.ply"}, "inputs.input")]:
        status, _, body = srv.json("POST", "/processes/simplify/execution", {"inputs": inputs})
        check(status == 400 and body.get("field") == field and field in body.get("detail", ""),
              f"{inputs}: 400 naming {field} ({status} {body})")
    status, _, body = srv.json("POST", "/processes/simplify/execution", b"{not json")
    check(status == 400 and body.get("field") == "body", "malformed JSON: 400 naming the body")
    status, _, body = srv.json("POST", "/processes/simplify/execution", b'{"inputs": {"bogus": ' + b"[" * 300000 + b"]" * 300000 + b"}}")
    check(status == 400 and body.get("field") == "body", f"JSON nested 300,000 deep: 400 ({status})")
    status, _, _ = srv.request("POST", "/processes/simplify/execution", b"x" * (2 << 20))
    check(status == 413, f"a 2 MiB JSON body: 413 ({status})")
    status, _, _ = srv.request("GET", "/jobs", headers={f"X-Filler-{i}": "y" for i in range(100)})
    check(status == 431, f"100 header fields: 431 ({status})")
    status, _, _ = srv.request("GET", "/jobs", headers={"X-Big": "x" * 100000})
    check(status == 400, f"a 100 kB header line: 400 ({status})")

    # A job to the end; its files whole and by range.
    job = submit(srv, {"input": "room.ply", "report": False})
    s = wait_status(srv, job, ("successful", "failed"))
    check(s["status"] == "successful" and s["progress"] == 100, f"job successful at 100 % ({s})")
    status, _, res = srv.json("GET", f"/jobs/{job}/results")
    check(status == 200 and len(res["levels"]) >= 2 and res["glb"]["type"] == "model/gltf-binary", "results list levels and GLB")
    glb_ref = open(os.path.join(ref, "lods.glb"), "rb").read()
    status, headers, glb = srv.request("GET", res["glb"]["href"])
    check(status == 200 and glb == glb_ref and headers["content-type"] == "model/gltf-binary", "GLB whole, identical to the CLI's")
    status, headers, part = srv.request("GET", res["glb"]["href"], headers={"Range": "bytes=100-1123"})
    check(status == 206 and part == glb_ref[100:1124] and headers.get("content-range") == f"bytes 100-1123/{len(glb_ref)}",
          f"GLB range: 206 with Content-Range ({status} {headers.get('content-range')})")
    status, _, _ = srv.request("GET", res["glb"]["href"], headers={"Range": f"bytes={len(glb_ref) + 10}-"})
    check(status == 416, f"range past the end: 416 ({status})")
    check(same_outputs(os.path.join(jobs_dir, job, "out"), ref), "job's levels byte-identical to the CLI's")
    for path in (f"/jobs/{job}/files/../job.json", f"/jobs/{job}/files/%2e%2e/job.json", f"/jobs/{job}/files/../../../../etc/passwd",
                 f"/jobs/{job}/files/../../token", "/jobs/0123456789abcdef0123456789abcdef/files/lods.glb", "/jobs/../token"):
        check(srv.request("GET", path)[0] == 404, f"{path}: 404")
    check(srv.json("GET", "/jobs/0123456789abcdef0123456789abcdef")[0] == 404, "unknown job: 404")
    check(len(job) == 32 and job != submit(srv, {"input": "room.ply", "report": False}), "job ids: 128 random bits")

    # The report and grid processes.
    status, _, body = srv.json("POST", "/processes/report/execution", {"inputs": {"job": job, "views": 1, "samples": 2000}})
    check(status == 201, f"report job: 201 ({status} {body})")
    s = wait_status(srv, body["jobID"], ("successful", "failed"))
    res = srv.json("GET", f"/jobs/{body['jobID']}/results")[2]
    check(s["status"] == "successful" and res.get("report", {}).get("type", "").startswith("text/html") and "report_json" in res,
          f"report job: report.html and report.json ({s['message']})")
    status, _, body = srv.json("POST", "/processes/report/execution", {"inputs": {"job": "0" * 32}})
    check(status == 400 and body.get("field") == "inputs.job", "report of an unknown job: 400 naming inputs.job")
    status, _, body = srv.json("POST", "/processes/grid/execution", {"inputs": {"input": "hill.asc", "tolerance": 0.5}})
    check(status == 201, f"grid job: 201 ({status} {body})")
    s = wait_status(srv, body["jobID"], ("successful", "failed"))
    res = srv.json("GET", f"/jobs/{body['jobID']}/results")[2]
    check(s["status"] == "successful" and "summary" in res and res["glb"]["type"] == "model/gltf-binary",
          f"grid job: summary.json and grid.glb ({s['message']})")
    status, _, body = srv.json("POST", "/processes/grid/execution", {"inputs": {"input": "hill.asc", "divide": 3}})
    check(status == 400 and body.get("field") == "inputs.divide", "grid with divide 3: 400 naming inputs.divide")

    # Uploads.
    room = open(ROOM, "rb").read()
    status, _, up = srv.json("POST", "/uploads?name=room.ply", room, headers={"Content-Type": "application/octet-stream"})
    check(status == 201 and up["bytes"] == len(room), f"upload: 201 ({status})")
    status, _, body = srv.json("POST", "/uploads?name=../x.ply", b"ply")
    check(status == 400 and body.get("field") == "name", "upload with a path in its name: 400")
    up_job = submit(srv, {"input": up["input"], "report": False})
    up2 = json.loads(srv.request("POST", "/uploads?name=gone.ply", b"ply\n")[2])["input"]
    up2_id = up2.split(":")[1].split("/")[0]
    check(srv.request("DELETE", "/uploads/" + up2_id)[0] == 204 and not os.path.exists(os.path.join(jobs_dir, "uploads", up2_id)),
          "DELETE /uploads/ID: 204, removed")
    status, _, body = srv.json("POST", "/processes/simplify/execution", {"inputs": {"input": up2}})
    check(status == 400 and body.get("field") == "inputs.input", "a removed upload: 400 naming inputs.input")

    # DELETE: cancel and dismiss.
    status, _, s = srv.json("DELETE", "/jobs/" + up_job)
    check(status == 200 and s["status"] == "dismissed", "DELETE: dismissed")
    wait_status(srv, up_job, ("dismissed",))
    time.sleep(0.5)
    check(not os.path.exists(os.path.join(jobs_dir, up_job, "out")), "dismissed job's outputs removed")
    status, _, s = srv.json("DELETE", "/jobs/" + job)
    check(status == 200 and s["status"] == "dismissed" and srv.request("GET", f"/jobs/{job}/files/lods.glb")[0] == 404,
          "DELETE of a finished job: its files gone")

    # A crashing job: its child killed; the job fails, the server lives.
    crash = submit(srv, {"input": "room.ply", "report": False})
    pid = running_child(srv, crash)
    if pid is None:
        check(False, "crash: the job ended before its child could be killed")
    else:
        os.kill(pid, signal.SIGKILL)
        s = wait_status(srv, crash, ("successful", "failed"))
        check(s["status"] == "failed" and "signal 9" in s["message"], f"killed child: job failed naming the signal ({s['message']})")
    check(srv.json("GET", "/conformance")[0] == 200 and srv.proc.poll() is None, "server alive after a job's crash")

    # kill -9 of the server in the middle of a job: the restarted server resumes it to identical bytes. The
    # child is stopped first so that it is surely mid-job; it gets SIGTERM when its parent dies and acts on
    # it once continued.
    for _ in range(3):
        resumed = submit(srv, {"input": "room.ply", "report": False})
        pid = running_child(srv, resumed, min_progress=30)
        if pid is not None:
            os.kill(pid, signal.SIGSTOP)
            break
    check(pid is not None, "kill -9: a job caught running")
    srv.stop(signal.SIGKILL)
    if pid is not None:
        os.kill(pid, signal.SIGCONT)
    srv = Server(tmp, "--timeout", "2", "--max-upload", "1M")
    s = wait_status(srv, resumed, ("successful", "failed"))
    check(s["status"] == "successful" and s["runs"] == 2, f"after kill -9 and a restart: the job resumed and succeeded ({s})")
    check(same_outputs(os.path.join(jobs_dir, resumed, "out"), ref), "resumed job's levels byte-identical to the CLI's")
    log = open(os.path.join(jobs_dir, resumed, "log.txt")).read()
    check("reused from work directory" in log, "the resumed run reused finished stages of its work directory")

    # Limits of the restarted server: uploads over --max-upload, an idle client.
    status, _, _ = srv.request("POST", "/uploads?name=room.ply", room)
    check(status == 413, f"upload over --max-upload: 413 ({status})")
    sock = socket.create_connection(("127.0.0.1", srv.port))
    sock.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n")
    sock.settimeout(15)
    t0 = time.time()
    try:
        closed = sock.recv(1024) is not None
    except socket.timeout:
        closed = False
    check(closed and time.time() - t0 < 10, f"an idle client is dropped after --timeout ({time.time() - t0:.1f} s)")
    sock.close()

    # SIGTERM drains: the running job is stopped, queued again, and completes after the next start.
    drained = submit(srv, {"input": "room.ply", "report": False})
    pid = running_child(srv, drained, min_progress=10)
    if pid is not None:
        os.kill(pid, signal.SIGSTOP)
    code = None
    srv.proc.send_signal(signal.SIGTERM)
    if pid is not None:
        time.sleep(0.3)
        os.kill(pid, signal.SIGCONT)
    code = srv.proc.wait(timeout=60)
    check(code == 0, f"SIGTERM: the server drains and exits 0 ({code})")
    state = json.load(open(os.path.join(jobs_dir, drained, "job.json")))
    if pid is not None:
        check(state["status"] == "accepted" and "shutdown" in state["message"], f"drained job queued again ({state['status']})")
    srv = Server(tmp)
    s = wait_status(srv, drained, ("successful", "failed"))
    check(s["status"] == "successful" and same_outputs(os.path.join(jobs_dir, drained, "out"), ref),
          "drained job completes after the next start, identical bytes")
    check(srv.stop() == 0, "server exits 0")

    # Admission: at most --max-jobs children, and their --memory caps add up to at most the server's.
    srv = Server(tmp, "--max-jobs", "3")
    for memory, least, most in (("600M", 1, 1), ("300M", 2, 3)):
        ids = [submit(srv, {"input": "room.ply", "report": False, "memory": memory}) for _ in range(4)]
        peak, caps = 0, set()
        while True:
            listing = srv.json("GET", "/jobs")[2]["jobs"]
            mine = [j for j in listing if j["jobID"] in ids]
            peak = max(peak, sum(j["status"] == "running" for j in mine))
            for pid in srv.children():
                try:
                    argv = open(f"/proc/{pid}/cmdline", "rb").read().split(b"\0")
                    caps.add(int(argv[argv.index(b"--memory") + 1]))
                except (OSError, ValueError, IndexError):
                    pass
            if all(j["status"] in ("successful", "failed") for j in mine):
                break
            time.sleep(0.02)
        check(all(j["status"] == "successful" for j in mine) and least <= peak <= most,
              f"memory {memory}: {least} to {most} running at once (saw {peak})")
        check(caps <= {int(memory[:-1]) << 20}, f"memory {memory}: the children's --memory ({caps})")
    check(srv.stop() == 0, "last server exits 0")


if __name__ == "__main__":
    sys.exit(main())
