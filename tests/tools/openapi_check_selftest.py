#!/usr/bin/env python3
"""Self-test of openapi_check.py: builds small response logs, runs the checker
on them (as a subprocess) and asserts it flags exactly the wrong records; runs
--lint on the real api/openapi.yaml and on a broken copy.

Usage: openapi_check_selftest.py [SPEC]   (default: api/openapi.yaml of this tree)
Exits non-zero on failure; ends with "openapi selftest: N passed, M failed".
"""

import json
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHECKER = os.path.join(HERE, "openapi_check.py")
SPEC = os.path.abspath(sys.argv[1]) if len(sys.argv) > 1 else \
    os.path.join(HERE, "..", "..", "api", "openapi.yaml")

MESH = "4f3c4172a4fe308cebc840da665171f534849b1fca101eaf635d68fb453393db"
JID = "01a200443ae27c41d09b5e3fa2c86d14"
PARAMS = {"azimuth": 30, "elevation": 20, "width": 64, "height": 48, "fov": 30,
          "color": [0.8, 0.8, 0.85], "background": [1, 1, 1, 1], "ambient": 0.2,
          "samples": 4}
JOB_OK = {
    "id": JID, "kind": "preview", "mesh": MESH, "params": PARAMS, "state": "succeeded",
    "progress": 1, "cancel_requested": False, "attempts": 1, "attempt": 1, "replica": "node-1:8080",
    "created": "2026-11-21T22:40:01.250Z", "started": "2026-11-21T22:40:01.254Z",
    "finished": "2026-11-21T22:40:01.291Z", "error": None,
    "timings": {"queue_ms": 4.1, "run_ms": 36.9, "total_ms": 41.0},
    "stats": {"triangles": 12, "width": 64, "height": 48, "pixels_covered": 900,
              "gpu_ms": 0.4, "upload_ms": 0.1, "samples": 4, "run_ms": 3.2},
    "outputs": {"image": "/v1/jobs/%s/result/image" % JID},
}
VPARAMS = {"resolution": 8, "voxel_size": None, "grid": None, "padding": 0, "method": "auto",
           "inside": "nonzero", "fill": "solid", "supersample": 1, "samples": "cube", "threshold": 4,
           "format": "summary", "vdb_grid": "fog", "bricks": None, "merge": True,
           "vdb_index_base": None}
VSTATS = {"method": "peel", "inside": "nonzero", "boundary_edges": 0, "dims": [8, 8, 8], "origin": [0, 0, 0], "voxel_size": 0.125,
          "triangles": 12, "voxels_inside": 512, "volume": 1, "layers": 2, "passes": 1, "slices": 0,
          "chunks": 1, "upload_ms": 0.1, "gpu_peel_ms": 0.2, "gpu_fill_ms": 0.1,
          "gpu_slice_ms": 0, "readback_ms": 0.1, "encode_ms": 0, "gl_ms": 1, "run_ms": 2}
VJOB_SUMMARY = dict(JOB_OK, kind="voxelize", params=VPARAMS, stats=VSTATS, outputs={})
VJOB_VDB = dict(VJOB_SUMMARY, params=dict(VPARAMS, format="vdb"),
                outputs={"voxels": "/v1/jobs/%s/result/voxels" % JID})
# a bricked voxelize still waiting: queued, nothing started or made
VJOB_QUEUED = dict(VJOB_SUMMARY, params=dict(VPARAMS, format="vdb", bricks={"size": 8}),
                   state="queued", progress=0, attempts=0, attempt=0, replica=None,
                   started=None, finished=None, stats={}, outputs={},
                   timings={"queue_ms": 5.0, "run_ms": None, "total_ms": None})
# merge false: a manifest and one .vdb per brick, no voxels
BRICK = {"offset": [0, 0, 0], "index_offset": [0, 0, 0], "dims": [8, 8, 8], "voxels_inside": 512,
         "ms": 1.5}
VJOB_MANIFEST = dict(VJOB_VDB, params=dict(VPARAMS, format="vdb", bricks={"size": 8}, merge=False),
                     stats=dict(VSTATS, brick_size=8, brick_grid=[1, 1, 1], bricks=[BRICK],
                                bricks_done=1),
                     outputs={n: "/v1/jobs/%s/result/%s" % (JID, n)
                              for n in ("manifest", "brick_0_0_0")})
MESH_OK = {
    "id": MESH, "format": "obj", "bytes": 412, "vertices": 8, "triangles": 12,
    "faces": {"total": 6, "triangles": 0, "quads": 6, "ngons": 0},
    "bbox": {"min": [-1, -1, -1], "max": [1, 1, 1]}, "boundary_edges": 0,
    "nonmanifold_edges": 0, "degenerate_triangles": 0, "texcoords": 0, "normals": 6,
    "created": "2026-11-21T22:39:58.001Z",
}
METRICS = "".join("# HELP %s x\n# TYPE %s %s\n" % (n, n, t) for n, t in [
    ("voxeld_http_requests_total", "counter"),
    ("voxeld_http_request_duration_seconds", "histogram"),
    ("voxeld_job_duration_seconds", "histogram"), ("voxeld_jobs_total", "counter"),
    ("voxeld_queue_depth", "gauge"), ("voxeld_queue_capacity", "gauge"),
    ("voxeld_jobs_running", "gauge"), ("voxeld_http_bytes_received_total", "counter"),
    ("voxeld_http_bytes_sent_total", "counter"), ("voxeld_meshes", "gauge"),
    ("voxeld_results_bytes", "gauge"), ("voxeld_info", "gauge"), ("voxeld_ready", "gauge"),
    ("voxeld_jobs_failed_total", "counter"), ("voxeld_job_queue_wait_seconds", "histogram"),
    ("voxeld_results_evicted_total", "counter"), ("voxeld_gl_context_losses_total", "counter"),
    ("voxeld_kept_memory_bytes", "gauge"), ("voxeld_data_dir_free_bytes", "gauge"),
    ("voxeld_data_dir_min_free_bytes", "gauge"),
    ("process_cpu_seconds_total", "counter"), ("process_resident_memory_bytes", "gauge"),
    ("process_virtual_memory_bytes", "gauge"), ("process_open_fds", "gauge"),
    ("process_max_fds", "gauge"),
    ("process_start_time_seconds", "gauge")]) + "voxeld_ready 1\n"
PNG = b"\x89PNG\r\n\x1a\n" + b"\0" * 32


def err(code, message="x"):
    return {"error": {"code": code, "message": message}}


def job_post(status, request, body, headers=None):
    """A POST /v1/jobs record whose request body is `request` (JSON)."""
    return dict(method="POST", path="/v1/jobs?wait=5", status=status,
                content_type="application/json", _request=request,
                headers=headers if headers is not None else {}), body


JOB_LOC = {"location": "/v1/jobs/" + JID}


# (name, record, body, should_fail). body: dict/list -> JSON, str/bytes -> raw,
# None -> no body_file.
CASES = [
    ("livez ok", dict(method="GET", path="/livez", status=200,
                      content_type="application/json"), {"status": "ok"}, False),
    ("livez missing field", dict(method="GET", path="/livez", status=200,
                                 content_type="application/json"), {"stat": "ok"}, True),
    ("mesh 404 error", dict(method="GET", path="/v1/meshes/" + MESH, status=404,
                            content_type="application/json"), err("mesh_not_found"), False),
    ("unknown status", dict(method="GET", path="/v1/info", status=418,
                            content_type="application/json"), err("teapot"), True),
    ("405 on known path", dict(method="POST", path="/livez", status=405,
                               content_type="application/json", headers={"allow": "GET"}),
     err("method_not_allowed"), False),
    ("405 with a wrong Allow", dict(method="PUT", path="/v1/meshes/" + MESH, status=405,
                                    content_type="application/json",
                                    headers={"allow": "GET"}),
     err("method_not_allowed"), True),
    ("501 for an unknown method", dict(method="PROPFIND", path="/v1/meshes", status=501,
                                       content_type="application/json"),
     err("not_implemented"), False),
    ("405 for an unknown method", dict(method="PROPFIND", path="/v1/meshes", status=405,
                                       content_type="application/json",
                                       headers={"allow": "GET, HEAD, POST, OPTIONS"}),
     err("method_not_allowed"), True),
    ("501 with another code", dict(method="FOO", path="/nope", status=501,
                                   content_type="application/json"), err("not_found"), True),
    ("414 on any path", dict(method="GET", path="/v1/meshes?limit=1", status=414,
                             content_type="application/json"), err("uri_too_long"), False),
    ("431 with another code", dict(method="GET", path="/v1/info", status=431,
                                   content_type="application/json"), err("not_found"), True),
    ("a trailing slash names nothing", dict(method="GET", path="/v1/meshes/", status=404,
                                            content_type="application/json"),
     err("not_found"), False),
    ("OPTIONS 204 with Allow", dict(method="OPTIONS", path="/v1/jobs", status=204,
                                    headers={"allow": "GET, HEAD, POST, OPTIONS"}), None, False),
    ("412 on a result", dict(method="GET", path="/v1/jobs/%s/result" % JID, status=412,
                             content_type="application/json"), err("precondition_failed"), False),
    ("unknown path 404", dict(method="GET", path="/nope?x=1", status=404,
                              content_type="application/json"), err("not_found"), False),
    ("unknown path 200", dict(method="GET", path="/nope", status=200,
                              content_type="application/json"), {}, True),
    ("201 without Location", dict(method="POST", path="/v1/meshes", status=201,
                                  content_type="application/json", headers={}), MESH_OK, True),
    ("201 with Location", dict(method="POST", path="/v1/meshes", status=201,
                               content_type="application/json",
                               headers={"location": "/v1/meshes/" + MESH}), MESH_OK, False),
    ("job ok, with wait", dict(method="GET", path="/v1/jobs/%s?wait=2" % JID, status=200,
                               content_type="application/json; charset=utf-8"), JOB_OK, False),
    ("queued job with progress", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                      content_type="application/json"),
     dict(VJOB_QUEUED, progress=0.3), True),
    ("queued parent counting its children", dict(method="GET", path="/v1/jobs/" + JID,
                                                 status=200, content_type="application/json"),
     dict(VJOB_QUEUED, progress=0.3375, child_jobs=8), False),
    ("queued parent over 1", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                  content_type="application/json"),
     dict(VJOB_QUEUED, progress=1.5, child_jobs=8), True),
    ("job params not normalised", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                       content_type="application/json"),
     dict(JOB_OK, params={"width": 64}), True),
    ("voxelize summary job without outputs", dict(method="GET", path="/v1/jobs/" + JID,
                                                  status=200, content_type="application/json"),
     VJOB_SUMMARY, False),
    ("voxelize vdb job with its output", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                              content_type="application/json"), VJOB_VDB, False),
    ("voxelize vdb job without its output", dict(method="GET", path="/v1/jobs/" + JID,
                                                 status=200, content_type="application/json"),
     dict(VJOB_VDB, outputs={}), True),
    ("voxelize manifest job with its bricks", dict(method="GET", path="/v1/jobs/" + JID,
                                                   status=200, content_type="application/json"),
     VJOB_MANIFEST, False),
    ("voxelize manifest job with voxels too", dict(method="GET", path="/v1/jobs/" + JID,
                                                   status=200, content_type="application/json"),
     dict(VJOB_MANIFEST, outputs=dict(VJOB_MANIFEST["outputs"],
                                      voxels="/v1/jobs/%s/result/voxels" % JID)), True),
    ("voxelize manifest job without bricks", dict(method="GET", path="/v1/jobs/" + JID,
                                                  status=200, content_type="application/json"),
     dict(VJOB_MANIFEST, outputs={"manifest": "/v1/jobs/%s/result/manifest" % JID}), True),
    ("voxelize merged job with a brick output", dict(method="GET", path="/v1/jobs/" + JID,
                                                     status=200, content_type="application/json"),
     dict(VJOB_VDB, outputs=dict(VJOB_VDB["outputs"],
                                 brick_0_0_0="/v1/jobs/%s/result/brick_0_0_0" % JID)), True),
    ("voxelize brick stats without dims", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                               content_type="application/json"),
     dict(VJOB_MANIFEST, stats=dict(VJOB_MANIFEST["stats"], bricks=[{"offset": [0, 0, 0]}])),
     True),
    ("voxelize stats with a wrong method", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                                content_type="application/json"),
     dict(VJOB_SUMMARY, stats=dict(VSTATS, method="magic")), True),
    ("job stats with an object value", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                            content_type="application/json"),
     dict(VJOB_SUMMARY, stats=dict(VSTATS, dims={"x": 8})), True),
    ("voxel result", dict(method="GET", path="/v1/jobs/%s/result/voxels" % JID, status=200,
                          content_type="application/x-binvox",
                          headers={"etag": '"abc"', "content-length": "10",
                                   "cache-control": "private, max-age=86400, immutable",
                                   "accept-ranges": "bytes",
                                   "content-disposition":
                                       'attachment; filename="%s-voxels.binvox"' % JID}),
     b"#binvox 1\n", False),
    ("job list", dict(method="GET", path="/v1/jobs?limit=5&state=succeeded", status=200,
                      content_type="application/json"), {"items": [JOB_OK], "next": None}, False),
    ("result 304", dict(method="GET", path="/v1/jobs/%s/result" % JID, status=304,
                        content_type="", headers={"etag": '"abc"',
                                                  "cache-control": "private, immutable"}),
     b"", False),
    ("result png", dict(method="GET", path="/v1/jobs/%s/result/image" % JID, status=200,
                        content_type="image/png",
                        headers={"etag": '"abc"', "content-length": str(len(PNG)),
                                 "cache-control": "private, max-age=86400, immutable",
                                 "accept-ranges": "bytes",
                                 "content-disposition":
                                     'attachment; filename="%s-image.png"' % JID}), PNG, False),
    ("result without ETag", dict(method="GET", path="/v1/jobs/%s/result" % JID, status=200,
                                 content_type="image/png",
                                 headers={"content-length": str(len(PNG)),
                                          "content-disposition":
                                              'attachment; filename="%s-image.png"' % JID}),
     PNG, True),
    ("429 Retry-After", dict(method="POST", path="/v1/jobs", status=429,
                             content_type="application/json", headers={"retry-after": "2"}),
     err("queue_full"), False),
    ("wrong error code", dict(method="POST", path="/v1/jobs", status=429,
                              content_type="application/json", headers={"retry-after": "2"}),
     err("busy"), True),
    ("metrics", dict(method="GET", path="/metrics", status=200,
                     content_type="text/plain; version=0.0.4; charset=utf-8"), METRICS, False),
    ("metrics missing a family", dict(method="GET", path="/metrics", status=200,
                                      content_type="text/plain; version=0.0.4"),
     METRICS.replace("voxeld_ready", "voxeld_down"), True),
    ("metrics with a family not in the spec", dict(method="GET", path="/metrics", status=200,
                                                   content_type="text/plain; version=0.0.4"),
     METRICS + "# HELP voxeld_new x\n# TYPE voxeld_new gauge\nvoxeld_new 1\n", True),
    ("cluster metrics: all their families", dict(method="GET", path="/metrics", status=200,
                                                 content_type="text/plain; version=0.0.4"),
     METRICS + "".join("# TYPE voxeld_cluster_%s %s\n" % (n, t) for n, t in [
         ("jobs", "gauge"), ("claims_total", "counter"), ("lease_losses_total", "counter"),
         ("stale_completions_total", "counter"), ("retries_total", "counter"),
         ("requeued_expired_total", "counter")]), False),
    ("cluster metrics missing one", dict(method="GET", path="/metrics", status=200,
                                         content_type="text/plain; version=0.0.4"),
     METRICS + "# TYPE voxeld_cluster_jobs gauge\n", True),
    ("wrong content type", dict(method="GET", path="/v1/meshes?limit=5", status=200,
                                content_type="text/html"), "<html></html>", True),
    ("body on 204", dict(method="DELETE", path="/v1/meshes/" + MESH, status=204,
                         content_type=""), "x", True),
    ("204 ok", dict(method="DELETE", path="/v1/meshes/" + MESH, status=204,
                    content_type=""), b"", False),
    ("no body file", dict(method="GET", path="/v1/meshes/" + MESH, status=200,
                          content_type="application/json"), None, False),
    ("readyz 503", dict(method="GET", path="/readyz", status=503,
                        content_type="application/json"),
     {"status": "not_ready", "reason": "the GL context is not up",
      "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": False, "gpu": True, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "local", "ok": True}}, False),
    ("readyz 503 without a reason", dict(method="GET", path="/readyz", status=503,
                                         content_type="application/json"),
     {"status": "not_ready", "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": False, "gpu": True, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "local", "ok": True}}, True),
    ("readyz 200 with a refused software renderer",
     dict(method="GET", path="/readyz", status=200, content_type="application/json"),
     {"status": "ready", "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": True, "gpu": False, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "local", "ok": True}}, True),
    ("readyz 200 with a reason", dict(method="GET", path="/readyz", status=200,
                                      content_type="application/json"),
     {"status": "ready", "reason": "x", "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": True, "gpu": True, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "local", "ok": True}}, True),
    ("readyz 503 for an unreachable blob store", dict(method="GET", path="/readyz", status=503,
                                                      content_type="application/json"),
     {"status": "not_ready", "reason": "the blob store (--blob-store) cannot be reached",
      "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": True, "gpu": True, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "s3", "ok": False}}, False),
    ("readyz without blob_store", dict(method="GET", path="/readyz", status=503,
                                       content_type="application/json"),
     {"status": "not_ready", "reason": "x", "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": False, "gpu": True, "data_dir": True, "journal": True, "disk_space": True}}, True),
    ("accepted preview request", *job_post(202, {"mesh": MESH, "kind": "preview",
                                                 "params": {"width": 64}}, JOB_OK, JOB_LOC),
     False),
    ("accepted request without params", *job_post(202, {"mesh": MESH, "kind": "preview"},
                                                  JOB_OK, JOB_LOC), False),
    ("accepted preview request with voxelize params",
     *job_post(202, {"mesh": MESH, "kind": "preview", "params": {"resolution": 128}}, JOB_OK,
               JOB_LOC), True),
    ("accepted request of an unknown kind",
     *job_post(202, {"mesh": MESH, "kind": "teleport"}, JOB_OK, JOB_LOC), True),
    ("rejected request with wrong-kind params",
     *job_post(422, {"mesh": MESH, "kind": "preview", "params": {"resolution": 128}},
               err("invalid_params")), False),
    ("voxelize job with preview params", dict(method="GET", path="/v1/jobs/" + JID, status=200,
                                              content_type="application/json"),
     dict(VJOB_SUMMARY, params=PARAMS), True),
    ("unknown path 404 with another code", dict(method="GET", path="/v2/x", status=404,
                                                content_type="application/json"),
     err("mesh_not_found"), True),
    ("readyz 200 with a failed check", dict(method="GET", path="/readyz", status=200,
                                            content_type="application/json"),
     {"status": "ready", "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": False, "gpu": True, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "local", "ok": True}}, True),
    ("readyz 200 with the blob store unreachable", dict(method="GET", path="/readyz", status=200,
                                                        content_type="application/json"),
     {"status": "ready", "queue": {"depth": 0, "capacity": 64, "full": False},
      "checks": {"gl": True, "gpu": True, "data_dir": True, "journal": True, "disk_space": True},
      "blob_store": {"backend": "s3", "ok": False}}, True),
]

passed = failed = 0


def expect(name, cond, detail=""):
    global passed, failed
    if cond:
        passed += 1
    else:
        failed += 1
        print("FAIL: %s%s" % (name, (": " + detail) if detail else ""))


def write_log(tmp, name, cases):
    log = os.path.join(tmp, name)
    with open(log, "w") as f:
        for i, (_, rec, body, _) in enumerate(cases):
            rec = dict(rec)
            if "_request" in rec:  # a JSON request body
                rf = os.path.join(tmp, "%s.%d.request" % (name, i))
                with open(rf, "w") as r:
                    json.dump(rec.pop("_request"), r)
                rec["request_body_file"] = rf
                rec["request_content_type"] = "application/json; charset=utf-8"
            if body is not None:
                bf = os.path.join(tmp, "%s.%d.body" % (name, i))
                data = body if isinstance(body, bytes) else \
                    body.encode() if isinstance(body, str) else json.dumps(body).encode()
                with open(bf, "wb") as b:
                    b.write(data)
                rec["body_file"] = os.path.basename(bf) if i % 2 else bf  # both forms
            f.write(json.dumps(rec) + "\n")
    return log


def run(*args):
    p = subprocess.run([sys.executable, CHECKER] + list(args), capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def main():
    with tempfile.TemporaryDirectory() as tmp:
        # 1. Mixed log: exactly the wrong records are flagged.
        log = write_log(tmp, "mixed.jsonl", CASES)
        rc, out = run(SPEC, log)
        flagged = {int(m) for m in re.findall(r"mixed\.jsonl:(\d+): ", out)}
        for i, (name, _, _, bad) in enumerate(CASES, 1):
            expect("%s is %s" % (name, "flagged" if bad else "accepted"),
                   (i in flagged) == bad,
                   "\n".join(l for l in out.splitlines() if ":%d: " % i in l))
        def said(case, text):
            i = next(n for n, c in enumerate(CASES, 1) if c[0] == case)
            return any(":%d: " % i in l and text in l for l in out.splitlines())

        expect("a wrong-kind request names the field the kind's branch rejects",
               said("accepted preview request with voxelize params",
                    "accepted request body $[\"params\"]: Additional properties are not allowed "
                    "('resolution' was unexpected)"), out)
        expect("an unknown kind is named as a bad discriminator value",
               said("accepted request of an unknown kind",
                    '$["kind"]: "teleport" is not a value of the discriminator kind'), out)
        expect("a job's wrong-kind params are named by the kind's branch",
               said("voxelize job with preview params", 'body $["params"]: Additional properties'),
               out)
        nbad = sum(1 for c in CASES if c[3])
        expect("mixed log exits 1", rc == 1, "rc=%d" % rc)
        m = re.search(r"^openapi: (\d+) responses checked, (\d+) failures, (\d+)/(\d+) "
                      r"operations exercised$", out, re.M)
        expect("summary line", m is not None, out[-300:])
        if m:
            expect("summary counts records", int(m.group(1)) == len(CASES), m.group(0))
            expect("summary counts failures", int(m.group(2)) >= nbad, m.group(0))

        # 2. Only good records: exit 0; --require-all-paths lists the rest.
        good = [c for c in CASES if not c[3]]
        log = write_log(tmp, "good.jsonl", good)
        rc, out = run(SPEC, log)
        expect("good log exits 0", rc == 0, out)
        rc, out = run(SPEC, log, "--require-all-paths")
        expect("--require-all-paths fails on a partial log", rc == 1, out)
        expect("--require-all-paths names an unexercised operation",
               "operation GET /v1/info was never exercised" in out, out)
        expect("--require-all-paths does not name exercised ones",
               "GET /livez was never" not in out, out)

        # 3. Bad log lines are failures, not crashes.
        bad_log = os.path.join(tmp, "bad.jsonl")
        with open(bad_log, "w") as f:
            f.write("not json\n{\"method\": \"GET\"}\n")
        rc, out = run(SPEC, bad_log)
        expect("malformed log lines fail", rc == 1 and out.count("bad log record") == 2, out)

        # 4. Lint: the real spec passes, a broken copy does not.
        rc, out = run(SPEC, "--lint")
        expect("lint of api/openapi.yaml", rc == 0, out)
        with open(SPEC) as f:
            text = f.read()
        broken = (text.replace("openapi: 3.1.0", "openapi: 3.0.3", 1)
                  .replace("operationId: getMesh\n", "operationId: getJob\n", 1)
                  .replace("/v1/jobs/{jid}/result/{name}:", "/v1/jobs/{jid}/result/{nom}:", 1)
                  .replace("$ref: '#/components/schemas/Rgba'",
                           "$ref: '#/components/schemas/Nope'", 1))
        bspec = os.path.join(tmp, "broken.yaml")
        with open(bspec, "w") as f:
            f.write(broken)
        rc, out = run(bspec, "--lint")
        expect("lint of a broken spec fails", rc != 0, out)
        expect("lint reports the unresolved $ref", "Nope does not resolve" in out, out)
        fixed_ref = broken.replace("#/components/schemas/Nope", "#/components/schemas/Rgba")
        with open(bspec, "w") as f:
            f.write(fixed_ref)
        rc, out = run(bspec, "--lint")
        expect("lint reports the version", "expected 3.1.x" in out, out)
        expect("lint reports a duplicate operationId", "operationId getJob is also used" in out,
               out)
        expect("lint reports an undeclared path parameter", "{nom} is not declared" in out, out)

        # 5. Lint: request examples are checked against the branch their kind
        # picks; JobRequest's discriminator must map exactly the x-kinds.
        wrong = text.replace("params: {resolution: 128, format: vdb}", "params: {width: 128}", 1)
        expect("the spec has the voxelize request example", wrong != text)
        wrong = wrong.replace("          catmull-clark: '#/components/schemas/CatmullClarkJobRequest'\n",
                              "", 1)
        expect("the spec maps catmull-clark in JobRequest", "CatmullClarkJobRequest'\n" in text)
        with open(bspec, "w") as f:
            f.write(wrong)
        rc, out = run(bspec, "--lint")
        expect("lint of a spec with a wrong-kind example fails", rc == 1, out)
        expect("lint names the example's field the kind rejects",
               "examples.voxelize: example does not match its schema: $[\"params\"]: "
               "Additional properties are not allowed ('width' was unexpected)" in out, out)
        expect("lint reports a kind missing from the discriminator mapping",
               "schema JobRequest discriminator: maps the kinds" in out, out)

    print("openapi selftest: %d passed, %d failed" % (passed, failed))
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
