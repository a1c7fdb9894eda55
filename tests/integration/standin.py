#!/usr/bin/env python3
"""A voxeld stand-in for test_voxelctl.sh: it answers one request, is gone
(connections refused) for GAP seconds, then answers one more on the same
port (a server restarting).

    standin.py PORTFILE upload GAP   a POST: 503 shutting_down with
                                     Retry-After 1, then 201 with a mesh id
    standin.py PORTFILE job GAP      GET of a job or its /events: running,
                                     then succeeded

The port goes into PORTFILE (whole, by a rename) once it listens."""
import http.server
import json
import os
import sys
import time

portfile, mode, gap = sys.argv[1], sys.argv[2], float(sys.argv[3])


class H(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def log_message(self, *a):
        pass

    def reply(self, status, ctype, body, headers=()):
        self.send_response(status)
        for k, v in headers:
            self.send_header(k, v)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(body)
        self.close_connection = True

    def do_POST(self):
        self.rfile.read(int(self.headers["Content-Length"]))
        if self.server.first:
            doc = {"error": {"code": "shutting_down", "message": "stopping"}}
            self.reply(503, "application/json", json.dumps(doc).encode(), [("Retry-After", "1")])
        else:
            self.reply(201, "application/json", json.dumps({"id": "ab" * 32}).encode())

    def do_GET(self):
        done = not self.server.first
        job = {"id": "0123456789abcdef" * 2, "kind": "voxelize",
               "state": "succeeded" if done else "running", "progress": 1 if done else 0.5,
               "outputs": {}, "stats": {"voxels_inside": 7}}
        if self.path.endswith("/events"):
            self.reply(200, "text/event-stream", ("data: %s\n\n" % json.dumps(job)).encode())
        else:
            self.reply(200, "application/json", json.dumps(job).encode())


srv = http.server.HTTPServer(("127.0.0.1", 0), H)
port = srv.server_address[1]
srv.first = True
with open(portfile + ".tmp", "w") as f:
    f.write(str(port))
os.rename(portfile + ".tmp", portfile)
srv.handle_request()
srv.server_close()
time.sleep(gap)
srv = http.server.HTTPServer(("127.0.0.1", port), H)
srv.first = False
srv.timeout = 20  # (a voxelctl that gave up never comes)
srv.handle_request()
