#!/usr/bin/env python3
"""Jobs through a running voxeld's API, for the GPU check (bench/gpu/run.sh).

Per mesh and resolution: a `summary` voxelize job per method (warm-up, then
the best and worst of RUNS), then one job per output format at the default
method (run_ms, encode_ms, bytes); then a render and a Gregory job. Prints
markdown tables; standard library only (the GPU machine has no jq).

  jobs.py BASE_URL MESH_DIR [--res 512 1024] [--runs 3]
"""
import argparse
import json
import sys
import time
import urllib.error
import urllib.request


def call(method, url, body=None, ctype="application/json"):
    req = urllib.request.Request(url, data=body, method=method)
    if body is not None:
        req.add_header("Content-Type", ctype)
    try:
        with urllib.request.urlopen(req, timeout=900) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


class Api:
    def __init__(self, base):
        self.base = base.rstrip("/")

    def upload(self, path):
        with open(path, "rb") as f:
            st, b = call("POST", self.base + "/v1/meshes", f.read(), "model/obj")
        if st not in (200, 201):
            sys.exit(f"upload {path}: {st} {b[:300]!r}")
        return json.loads(b)["id"]

    def job(self, mesh, kind, params):
        body = json.dumps({"mesh": mesh, "kind": kind, "params": params}).encode()
        st, b = call("POST", self.base + "/v1/jobs", body)
        d = json.loads(b)
        if "id" not in d:
            return d
        while d.get("state") not in ("succeeded", "failed", "canceled"):
            st, b = call("GET", f"{self.base}/v1/jobs/{d['id']}?wait=60")
            d = json.loads(b)
        return d

    def result_bytes(self, jid):
        st, b = call("GET", f"{self.base}/v1/jobs/{jid}/result")
        return len(b) if st == 200 else -1


def ms(d, key):
    return (d.get("timings") or {}).get(key) or (d.get("stats") or {}).get(key)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("base")
    ap.add_argument("meshes")
    ap.add_argument("--res", type=int, nargs="+", default=[512, 1024])
    ap.add_argument("--runs", type=int, default=3)
    a = ap.parse_args()
    api = Api(a.base)
    st, info = call("GET", api.base + "/v1/info")
    gl = json.loads(info).get("gl", {})
    print(f"GL: {gl.get('renderer')} | {gl.get('version')} | device kind {gl.get('device_kind')}\n")
    methods = ["auto", "peel", "scan", "slice", "cpu"]
    formats = ["vdb:bool", "vdb:fog", "vdb:level_set", "binvox", "raw1", "vox", "npy"]
    print("| mesh | dims | method | run_ms best | worst | voxels | method run |")
    print("|---|---|---|---|---|---|---|")
    enc_rows = []
    for name in ("spot_triangulated.obj", "stanford-bunny.obj"):
        mid = api.upload(f"{a.meshes}/{name}")
        for r in a.res:
            base_ms = None
            for m in methods:
                p = {"resolution": r, "format": "summary", "method": m}
                api.job(mid, "voxelize", p)  # warm-up
                runs = [api.job(mid, "voxelize", p) for _ in range(a.runs)]
                ok = [d for d in runs if d.get("state") == "succeeded"]
                if not ok:
                    print(f"| {name} | {r} | {m} | failed: {json.dumps(runs[0].get('error'))} | | | |")
                    continue
                t = sorted(ms(d, "run_ms") for d in ok)
                s = ok[0].get("stats", {})
                dims = "x".join(str(x) for x in s.get("dims", []))
                if m == "auto":
                    base_ms = t[0]
                print(f"| {name} | {dims} | {m} | {t[0]:.1f} | {t[-1]:.1f} | {s.get('voxels_inside')} | {s.get('method')} |")
            for f in formats:
                p = {"resolution": r, "format": f.split(":")[0]}
                if f.startswith("vdb:"):
                    p["vdb_grid"] = f[4:]
                d = api.job(mid, "voxelize", p)
                if d.get("state") != "succeeded":
                    enc_rows.append(f"| {name} | {r} | {f} | failed: {json.dumps(d.get('error'))} | | | |")
                    continue
                e = ms(d, "encode_ms") or 0
                ratio = e / base_ms if base_ms else float("nan")
                enc_rows.append(f"| {name} | {r} | {f} | {ms(d, 'run_ms'):.0f} | {e:.0f} | {ratio:.2f} | {api.result_bytes(d['id'])} |")
    print("\n| mesh | res | format | job run_ms | encode_ms | encode / engine (auto) | bytes |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(enc_rows))
    print("\n| kind | mesh | params | run_ms best | worst |")
    print("|---|---|---|---|---|")
    other = [
        ("render", "spot_triangulated.obj", {"width": 2048, "height": 2048}),
        ("preview", "stanford-bunny.obj", {"width": 2048, "height": 2048}),
        ("gregory", "spot_control_mesh.obj", {}),
    ]
    for kind, name, p in other:
        mid = api.upload(f"{a.meshes}/{name}")
        api.job(mid, kind, p)
        runs = [api.job(mid, kind, p) for _ in range(a.runs)]
        ok = sorted(ms(d, "run_ms") for d in runs if d.get("state") == "succeeded")
        if not ok:
            print(f"| {kind} | {name} | {json.dumps(p)} | failed: {json.dumps(runs[0].get('error'))} | |")
            continue
        print(f"| {kind} | {name} | {json.dumps(p)} | {ok[0]:.1f} | {ok[-1]:.1f} |")
    return 0


if __name__ == "__main__":
    t0 = time.time()
    rc = main()
    print(f"\n(jobs.py: {time.time() - t0:.0f} s)")
    sys.exit(rc)
