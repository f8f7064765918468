#!/usr/bin/env python3
"""Load on `lodstream serve`: JOBS simplify jobs submitted at once while CLIENTS clients poll their status.

Prints the status latency (p50, p99, max over every poll), the polls answered and failed, the most jobs
seen running at once, the jobs' wall time, and the server's own CPU time and memory (/proc of the server
process: its threads only, not the job children). Run as a benchmark (figures) or with --check as the
load test (ctest serve_load): every job succeeds, every poll is answered 200, no more than --max-jobs
run at once, and every poll is answered within --max-latency seconds.

    tools/bench_serve.py build/lodstream tests/data/sample-room.ply [--jobs 8] [--clients 200]
                         [--interval 1] [--max-jobs 2] [--connections keep-alive|new] [--report] [--check]
"""
import argparse
import http.client
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time


def proc_figures(pid):
    """(cpu seconds of the process's own threads, VmRSS bytes, VmHWM bytes)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    cpu = (int(fields[11]) + int(fields[12])) / ticks  # utime, stime (fields 14, 15)
    rss = hwm = 0
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) * 1024
            elif line.startswith("VmHWM:"):
                hwm = int(line.split()[1]) * 1024
    return cpu, rss, hwm


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("cli")
    ap.add_argument("scene")
    ap.add_argument("--jobs", type=int, default=8)
    ap.add_argument("--clients", type=int, default=200)
    ap.add_argument("--interval", type=float, default=1.0, help="seconds between a client's polls")
    ap.add_argument("--max-jobs", type=int, default=2)
    ap.add_argument("--connections", choices=("keep-alive", "new"), default="keep-alive")
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--report", action="store_true", help="each job also runs lodstream report (longer jobs)")
    ap.add_argument("--timeout", type=float, default=600, help="give up after this many seconds")
    ap.add_argument("--max-latency", type=float, default=10.0, help="--check: slowest poll allowed (s)")
    ap.add_argument("--check", action="store_true")
    a = ap.parse_args()

    tmp = tempfile.mkdtemp(prefix="lodstream-bench-serve-")
    server = None
    try:
        data = os.path.join(tmp, "data")
        os.makedirs(data)
        name = os.path.basename(a.scene)
        try:  # inside the data root: a symlink out of it would be refused
            os.link(a.scene, os.path.join(data, name))
        except OSError:
            shutil.copyfile(a.scene, os.path.join(data, name))
        server = subprocess.Popen([a.cli, "serve", "--bind", "127.0.0.1:0", "--data-root", data, "--jobs-dir",
                                   os.path.join(tmp, "jobs"), "--max-jobs", str(a.max_jobs), "--memory", f"{a.max_jobs}G",
                                   "--job-threads", "1"], stdout=subprocess.PIPE, stderr=open(os.path.join(tmp, "err"), "wb"))
        line = server.stdout.readline().decode()
        port = int(line.split("http://127.0.0.1:")[1].split("/")[0])

        def call(conn, method, path, body=None):
            headers = {"Content-Type": "application/json"} if body is not None else {}
            conn.request(method, path, body=None if body is None else json.dumps(body), headers=headers)
            r = conn.getresponse()
            return r.status, r.read()

        # Submitted at once: one thread per job, released together.
        ids = [None] * a.jobs
        go = threading.Barrier(a.jobs)

        def submit(i):
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
            go.wait()
            status, body = call(conn, "POST", "/processes/simplify/execution",
                                {"inputs": {"input": name, "levels": a.levels, "report": a.report, "memory": "256M"}})
            if status != 201:
                print(f"bench_serve: submit answered {status}: {body[:200]!r}", file=sys.stderr)
            else:
                ids[i] = json.loads(body)["jobID"]
            conn.close()

        cpu0, _, _ = proc_figures(server.pid)
        t0 = time.time()
        threads = [threading.Thread(target=submit, args=(i,)) for i in range(a.jobs)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        if None in ids:
            print(f"bench_serve: only {sum(i is not None for i in ids)} of {a.jobs} jobs were accepted", file=sys.stderr)
            return 1

        lock = threading.Lock()
        latencies, failures, states = [], [0], {}
        stop = threading.Event()

        def poll(k):
            conn = None
            n = 0
            while not stop.is_set():
                job = ids[(k + n) % a.jobs]
                n += 1
                if conn is None:
                    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
                t = time.time()
                try:
                    status, body = call(conn, "GET", "/jobs/" + job)
                    ok = status == 200
                    if ok:
                        st = json.loads(body)["status"]
                except (OSError, http.client.HTTPException, ValueError):
                    ok = False
                dt = time.time() - t
                with lock:
                    if ok:
                        latencies.append(dt)
                        states[job] = st
                    else:
                        failures[0] += 1
                if not ok or a.connections == "new":
                    conn.close()
                    conn = None
                stop.wait(max(0.0, a.interval - dt))
            if conn is not None:
                conn.close()

        pollers = [threading.Thread(target=poll, args=(k,), daemon=True) for k in range(a.clients)]
        for t in pollers:
            t.start()

        # The server's own figures, and the most jobs running at once (from the jobs' own records).
        most_running, rss_max = 0, 0
        jobs_dir = os.path.join(tmp, "jobs")
        while time.time() - t0 < a.timeout:
            with lock:
                done = len(states) == a.jobs and all(s in ("successful", "failed", "dismissed") for s in states.values())
            running = 0
            for job in ids:
                try:
                    with open(os.path.join(jobs_dir, job, "job.json")) as f:
                        running += json.load(f).get("status") == "running"
                except (OSError, ValueError):
                    pass
            most_running = max(most_running, running)
            rss_max = max(rss_max, proc_figures(server.pid)[1])
            if done:
                break
            time.sleep(0.2)
        wall = time.time() - t0
        stop.set()
        for t in pollers:
            t.join(timeout=70)
        cpu1, rss, hwm = proc_figures(server.pid)

        lat = sorted(latencies)
        p = lambda q: lat[min(len(lat) - 1, int(q * len(lat)))] if lat else float("nan")
        succeeded = sum(s == "successful" for s in states.values())
        print(f"bench_serve: {a.jobs} jobs ({name}, {a.levels} levels, --max-jobs {a.max_jobs}), {a.clients} clients polling "
              f"every {a.interval:g} s on {a.connections} connections; load {os.getloadavg()[0]:.1f}")
        print(f"  jobs: {succeeded}/{a.jobs} successful, all done in {wall:.1f} s, at most {most_running} running at once")
        print(f"  status polls: {len(lat)} answered, {failures[0]} failed; latency p50 {1000 * p(0.5):.1f} ms, "
              f"p99 {1000 * p(0.99):.1f} ms, max {1000 * (lat[-1] if lat else float('nan')):.1f} ms")
        print(f"  server process (jobs excluded): CPU {cpu1 - cpu0:.2f} s ({100 * (cpu1 - cpu0) / wall:.1f} % of one core), "
              f"RSS {rss_max / 2**20:.1f} MiB at most while polled, VmHWM {hwm / 2**20:.1f} MiB")
        if a.check:
            problems = []
            if succeeded != a.jobs:
                problems.append(f"{a.jobs - succeeded} jobs did not succeed")
            if failures[0]:
                problems.append(f"{failures[0]} polls failed")
            if most_running > a.max_jobs:
                problems.append(f"{most_running} jobs ran at once (--max-jobs {a.max_jobs})")
            if not lat or lat[-1] > a.max_latency:
                problems.append(f"slowest poll {lat[-1] if lat else float('nan'):.1f} s (allowed {a.max_latency:g} s)")
            if wall >= a.timeout:
                problems.append(f"not done within {a.timeout:g} s")
            if problems:
                print("bench_serve: FAILED: " + "; ".join(problems))
                return 1
            print("bench_serve: load test passed")
        return 0
    finally:
        if server is not None:
            server.terminate()
            try:
                server.wait(timeout=60)
            except subprocess.TimeoutExpired:
                server.kill()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
