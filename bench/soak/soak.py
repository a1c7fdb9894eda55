#!/usr/bin/env python3
"""Soak test: 16 clients against a voxeld this script starts, for a set time.

Each client loops over a weighted mix: small GETs (/livez, /v1/info, a mesh,
a job, lists), uploads (new small meshes every time, and repeats of a known
one), job submissions (small previews and voxel grids) and result downloads.
Every 1,000 requests it samples the daemon's RSS and open fds
(/proc/PID/status, /proc/PID/fd) and prints them; at the end it prints the
statuses seen, the 5xx count, RSS and fd growth per 1,000 requests, the
meshes stored, and the growth per stored mesh (the in-memory mesh index).

    bench/soak/run.sh [build dir] [minutes]      (default build/, 2 minutes)
    python3 bench/soak/soak.py --voxeld build/voxeld --minutes 5 --clients 16
Exit status 1 when any 5xx was seen or the daemon died.
"""
import argparse
import collections
import http.client
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time


def box_obj(x, y, z):
    v = [(0, 0, 0), (x, 0, 0), (x, y, 0), (0, y, 0), (0, 0, z), (x, 0, z), (x, y, z), (0, y, z)]
    f = [(1, 4, 3, 2), (5, 6, 7, 8), (1, 2, 6, 5), (2, 3, 7, 6), (3, 4, 8, 7), (4, 1, 5, 8)]
    return ("".join(f"v {a:.6f} {b:.6f} {c:.6f}\n" for a, b, c in v) +
            "".join("f " + " ".join(map(str, q)) + "\n" for q in f)).encode()


def proc_sample(pid):
    rss = 0
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) * 1024
    return rss, len(os.listdir(f"/proc/{pid}/fd"))


class Soak:
    def __init__(self, port, pid, seconds, clients, seed):
        self.port, self.pid, self.deadline = port, pid, time.time() + seconds
        self.clients = clients
        self.lock = threading.Lock()
        self.statuses = collections.Counter()
        self.by_op = collections.Counter()
        self.n = 0
        self.samples = []  # (requests, rss, fds, meshes)
        self.meshes, self.jobs, self.done_jobs = [], [], []
        self.new_meshes = 0
        self.rng = random.Random(seed)
        self.errors = []

    def request(self, conn, method, path, body=None, ctype=None):
        headers = {"Content-Type": ctype} if ctype else {}
        conn.request(method, path, body=body, headers=headers)
        resp = conn.getresponse()
        data = resp.read()
        return resp.status, data

    def record(self, op, status):
        with self.lock:
            self.statuses[status] += 1
            self.by_op[(op, status)] += 1
            self.n += 1
            n = self.n
        if n % 1000 == 0:
            rss, fds = proc_sample(self.pid)
            with self.lock:
                self.samples.append((n, rss, fds, len(self.meshes)))
            print(f"soak: {n:7d} requests  rss {rss / 2**20:7.1f} MiB  fds {fds:4d}  meshes {len(self.meshes)}",
                  flush=True)

    def client(self, idx):
        rng = random.Random(self.rng.random() + idx)
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=60)
        known = box_obj(3, 2, 1)
        while time.time() < self.deadline:
            r = rng.random()
            try:
                if r < 0.45:
                    with self.lock:
                        m = rng.choice(self.meshes) if self.meshes else None
                        j = rng.choice(self.jobs) if self.jobs else None
                    path = rng.choice(["/livez", "/v1/info", "/readyz", "/v1/meshes?limit=20", "/v1/jobs?limit=20"]
                                      + ([f"/v1/meshes/{m}"] if m else []) + ([f"/v1/jobs/{j}"] if j else []))
                    st, _ = self.request(conn, "GET", path)
                    # /readyz is 503 by design while the queue is full
                    self.record("readyz" if path == "/readyz" else "get", st)
                elif r < 0.65:
                    body = known if rng.random() < 0.3 else box_obj(*(rng.uniform(0.5, 4) for _ in range(3)))
                    st, data = self.request(conn, "POST", "/v1/meshes", body, "model/obj")
                    self.record("upload", st)
                    if st in (200, 201):
                        mid = json.loads(data)["id"]
                        with self.lock:
                            if st == 201:
                                self.new_meshes += 1
                                self.meshes.append(mid)
                            elif mid not in self.meshes:
                                self.meshes.append(mid)
                elif r < 0.80:
                    with self.lock:
                        m = rng.choice(self.meshes) if self.meshes else None
                    if not m:
                        continue
                    if rng.random() < 0.5:
                        spec = {"mesh": m, "kind": "preview", "params": {"width": 48, "height": 48}}
                    else:
                        spec = {"mesh": m, "kind": "voxelize", "params": {"resolution": 24, "format": "raw8"}}
                    st, data = self.request(conn, "POST", "/v1/jobs", json.dumps(spec), "application/json")
                    self.record("job", st)
                    if st == 202:
                        with self.lock:
                            self.jobs.append(json.loads(data)["id"])
                else:
                    with self.lock:
                        j = rng.choice(self.jobs) if self.jobs else None
                    if not j:
                        continue
                    st, _ = self.request(conn, "GET", f"/v1/jobs/{j}/result")
                    self.record("download", st)
            except (OSError, http.client.HTTPException) as e:
                with self.lock:
                    self.errors.append(repr(e))
                    self.statuses["conn_error"] += 1
                conn.close()
                conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=60)
                if self.pid and not os.path.exists(f"/proc/{self.pid}"):
                    return
        conn.close()

    def run(self):
        rss0, fds0 = proc_sample(self.pid)
        self.samples.append((0, rss0, fds0, 0))
        threads = [threading.Thread(target=self.client, args=(i,)) for i in range(self.clients)]
        t0 = time.time()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.time() - t0
        alive = os.path.exists(f"/proc/{self.pid}")
        rss1, fds1 = proc_sample(self.pid) if alive else (0, 0)
        # Growth per 1,000 requests from the second half (after warm-up).
        half = [s for s in self.samples if s[0] >= self.n / 2] or self.samples[-1:]
        first, last = half[0], self.samples[-1]
        dn = max(1, last[0] - first[0])
        fivexx = sum(c for (op, s), c in self.by_op.items() if s >= 500 and not (op == "readyz" and s == 503))
        print(f"soak: {self.n} requests in {wall:.0f} s ({self.n / wall:.0f}/s), {self.clients} clients")
        print("soak: statuses " + ", ".join(f"{k}: {v}" for k, v in sorted(self.statuses.items(), key=str)))
        for (op, st), c in sorted(self.by_op.items(), key=str):
            print(f"soak:   {op:8s} {st}: {c}")
        print(f"soak: 5xx (not counting /readyz 503 while the queue is full) {fivexx}, connection errors {self.statuses['conn_error']}")
        print(f"soak: rss {rss0 / 2**20:.1f} -> {rss1 / 2**20:.1f} MiB; fds {fds0} -> {fds1}")
        print(f"soak: second half: rss {(last[1] - first[1]) / dn * 1000 / 1024:+.1f} KiB and fds "
              f"{(last[2] - first[2]) / dn * 1000:+.2f} per 1,000 requests")
        dm = last[3] - first[3]
        if dm > 0:
            print(f"soak: meshes stored {len(self.meshes)} ({self.new_meshes} new); "
                  f"rss {(last[1] - first[1]) / dm / 1024:+.2f} KiB per new mesh in the second half")
        return 0 if alive and fivexx == 0 else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--voxeld", default="build/voxeld")
    ap.add_argument("--minutes", type=float, default=2)
    ap.add_argument("--clients", type=int, default=16)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="voxeld-soak.")
    log = open(os.path.join(tmp, "voxeld.log"), "w")
    proc = subprocess.Popen([a.voxeld, "--listen", "127.0.0.1:0", "--data-dir", os.path.join(tmp, "data"),
                             "--max-connections-per-ip", "256", "--max-queued-jobs", "1000",
                             "--log-level", "info"], stderr=log)
    port = None
    for _ in range(600):
        m = re.search(r"event=voxeld.ready port=(\d+)", open(log.name).read())
        if m:
            port = int(m.group(1))
            break
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    if not port:
        print("soak: voxeld did not start; log in " + log.name)
        return 1
    try:
        rc = Soak(port, proc.pid, a.minutes * 60, a.clients, a.seed).run()
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    if rc == 0:
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        print("soak: kept " + tmp)
    return rc


if __name__ == "__main__":
    sys.exit(main())
