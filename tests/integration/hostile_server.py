#!/usr/bin/env python3
"""A voxeld stand-in that answers one thing wrong, for the clients' tests
(test_voxelctl.sh, test_python_client.sh):

    hostile_server.py PORTFILE LOG MODE

Every request's method, path, Authorization and Idempotency-Key go to
LOG, a line each. It
takes uploads and jobs and says each job succeeded; MODE breaks one answer:
  badid     the job's id is "../../x" (a path, not 32 hex digits)
  dotname   the result is named ".profile" by Content-Disposition
  gzip      the result comes with Content-Encoding: gzip, not asked for
  progress  the event stream says progress 1e20, then succeeded
  redirect  the result is a 302 to /steal on this server
  partial   the result is a 206 of its last 4 bytes, not asked for
  html      the upload's 201 is an HTML page, not a Mesh
  esc       the job's 422 message holds terminal escapes (clear, retitle),
            and so do the job and mesh lists' fields and a job's error
  nullerr   the job ends failed with "error": null
  shape     lists whose items are not jobs or meshes, a job and an event
            that are {}
  slow      the result comes at 100 KB/s (2 MB: 20 s)
  atonce    no event stream (503), and ?wait answered at once (as with
            --request-timeout 0): running for 3 s, then succeeded
  cut       the first job submission is closed unanswered (taken, its
            answer lost); a later one with the same Idempotency-Key is
            answered that job (200), one without a key or with another
            a new job (202, another id)
  cutbody   the same, the first answer cut in its body (a 202 head, then
            part of the job)
The port goes into PORTFILE (whole, by a rename) once it listens."""
import gzip
import http.server
import json
import os
import sys
import time

portfile, log, mode = sys.argv[1], sys.argv[2], sys.argv[3]
MESH = "ab" * 32
JID = "../../x" if mode == "badid" else "cd" * 16
BODY = b"#binvox 1\ndim 1 1 1\ntranslate 0 0 0\nscale 1\ndata\n\x01\x01"


ESC = "\x1b[2J\x1b]0;pwned\x07\u009b2J"  # C0 escapes, then a C1 CSI (U+009B)


def job(state="succeeded", progress=1.0):
    if mode == "nullerr" and state == "succeeded":
        return {"id": JID, "kind": "voxelize", "state": "failed", "progress": 1.0, "mesh": MESH,
                "error": None, "created": "2026-01-01T00:00:00Z", "outputs": {}}
    j = {"id": JID, "kind": "voxelize", "state": state, "progress": progress, "mesh": MESH,
         "params": {"format": "binvox"}, "created": "2026-01-01T00:00:00Z",
         "outputs": {"voxels": "/v1/jobs/%s/result/voxels" % JID}}
    if mode == "esc":
        j.update(kind="voxelize" + ESC, created=ESC, outputs={"v" + ESC: "/x" + ESC},
                 error={"code": "c" + ESC, "message": "m" + ESC})
    return j


def lists(path):
    """The job or mesh list page (or, shape, one that is not)."""
    if mode == "shape":
        return {"items": [1, "x", {"foo": 1}]} if path.startswith("/v1/jobs") else {"items": "no"}
    if path.startswith("/v1/jobs"):
        return {"items": [job()], "next": "n" + ESC if mode == "esc" else None}
    m = {"id": MESH, "format": "obj", "triangles": 12, "name": "a" + ESC if mode == "esc" else "a"}
    return {"items": [m]}


class H(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def log_message(self, *a):
        pass

    def reply(self, status, ctype, body, headers=()):
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        for k, v in headers:
            self.send_header(k, v)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def note(self):
        with open(log, "a") as f:
            f.write("%s %s %s %s\n" % (self.command, self.path, self.headers.get("Authorization", "-"),
                                     self.headers.get("Idempotency-Key", "-")))

    def do_POST(self):
        self.note()
        n = int(self.headers.get("Content-Length", "0"))
        self.rfile.read(n)
        if self.path.startswith("/v1/meshes") and mode == "html":
            self.reply(201, "text/html", b"<html>a proxy's page</html>")
        elif self.path.startswith("/v1/jobs") and mode == "esc":
            self.reply(422, "application/json", json.dumps({"error": {
                "code": "invalid\x1b[31m", "message": "bad" + ESC}}).encode())
        elif self.path.startswith("/v1/jobs") and mode in ("cut", "cutbody"):
            key, keys = self.headers.get("Idempotency-Key"), self.server.__dict__.setdefault("keys", [])
            if not keys:
                keys.append(key)
                self.close_connection = True
                if mode == "cutbody":
                    self.send_response(202)
                    self.send_header("Content-Type", "application/json")
                    self.send_header("Content-Length", "400")
                    self.end_headers()
                    self.wfile.write(b'{"id": "cdcd')
                    self.wfile.flush()
                self.connection.shutdown(2)
            elif key is not None and key == keys[0]:
                self.reply(200, "application/json", json.dumps(job("queued", 0)).encode())
            else:
                j = job("queued", 0)
                j["id"] = "ef" * 16
                self.reply(202, "application/json", json.dumps(j).encode())
        elif self.path.startswith("/v1/meshes"):
            self.reply(201, "application/json", json.dumps(
                {"id": MESH, "format": "obj", "triangles": 12, "vertices": 8}).encode())
        else:
            self.reply(202, "application/json", json.dumps(job("queued", 0)).encode())

    def do_GET(self):
        self.note()
        p = self.path
        if p.endswith("/events") and mode == "atonce":
            self.reply(503, "application/json",
                       b'{"error":{"code":"too_many_streams","message":"no streams"}}')
        elif p.endswith("/events"):
            ev = [job("running", 1e20), job()] if mode == "progress" else \
                [{}] if mode == "shape" else [job()]
            body = b"".join(b"event: job\ndata: " + json.dumps(j).encode() + b"\n\n" for j in ev)
            self.reply(200, "text/event-stream", body)
        elif "/result" in p:
            if mode == "dotname":
                self.reply(200, "application/octet-stream", BODY,
                           [("Content-Disposition", 'attachment; filename=".profile"')])
            elif mode == "gzip":
                self.reply(200, "application/octet-stream", gzip.compress(BODY),
                           [("Content-Encoding", "gzip")])
            elif mode == "redirect":
                self.reply(302, "text/plain", b"moved",
                           [("Location", "http://127.0.0.1:%d/steal" % self.server.server_port)])
            elif mode == "slow":
                self.send_response(200)
                self.send_header("Content-Type", "application/octet-stream")
                self.send_header("Content-Length", str(2000000))
                self.end_headers()
                try:
                    for _ in range(200):
                        self.wfile.write(b"\0" * 10000)
                        self.wfile.flush()
                        time.sleep(0.1)
                except OSError:
                    pass
            elif mode == "partial":
                self.reply(206, "application/octet-stream", BODY[-4:],
                           [("Content-Range", "bytes %d-%d/%d" % (len(BODY) - 4, len(BODY) - 1,
                                                                  len(BODY)))])
            else:
                self.reply(200, "application/octet-stream", BODY)
        elif p.startswith("/v1/jobs?") or p.startswith("/v1/meshes?"):
            self.reply(200, "application/json", json.dumps(lists(p)).encode())
        elif p.startswith("/v1/jobs/") and mode == "atonce":
            first = self.server.__dict__.setdefault("first_poll", time.monotonic())
            j = job() if time.monotonic() - first > 3 else job("running", 0.5)
            self.reply(200, "application/json", json.dumps(j).encode())
        elif p.startswith("/v1/jobs/"):
            self.reply(200, "application/json", json.dumps({} if mode == "shape" else job()).encode())
        else:
            self.reply(404, "application/json",
                       b'{"error":{"code":"not_found","message":"no such route"}}')


srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), H)
with open(portfile + ".tmp", "w") as f:
    f.write(str(srv.server_port))
os.rename(portfile + ".tmp", portfile)
srv.serve_forever()
