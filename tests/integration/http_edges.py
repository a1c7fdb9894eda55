#!/usr/bin/env python3
"""HTTP framing and header edge cases on raw sockets (what curl would tidy
up before sending), against a running voxeld:

    http_edges.py PORT JOB_ID [TOKEN]

JOB_ID is a finished job whose primary result is compressible (raw8).
Prints one line per case, "PASS name" or "FAIL name: what came"; exits 0.
Standard library only."""
import http.client
import socket
import sys

PORT, JOB = int(sys.argv[1]), sys.argv[2]
AUTH = b"Authorization: Bearer %s\r\n" % sys.argv[3].encode() if len(sys.argv) > 3 else b""
RESULT = b"/v1/jobs/%s/result" % JOB.encode()


def exchange(data, wait=2.0):
    """Sends data on a new connection and reads until the server closes it
    or nothing comes for `wait` seconds."""
    s = socket.create_connection(("127.0.0.1", PORT))
    s.settimeout(wait)
    s.sendall(data)
    got = b""
    try:
        while True:
            b = s.recv(65536)
            if not b:
                break
            got += b
    except socket.timeout:
        pass
    s.close()
    return got


def head_of(resp):
    head = resp.split(b"\r\n\r\n", 1)[0].decode("latin-1")
    lines = head.split("\r\n")
    fields = {}
    for l in lines[1:]:
        k, _, v = l.partition(":")
        fields.setdefault(k.strip().lower(), []).append(v.strip())
    return lines[0], fields


def report(name, ok, what):
    print("%s %s%s" % ("PASS" if ok else "FAIL", name, "" if ok else ": " + what))


def answers(resp):
    return resp.count(b"HTTP/1.1 ")


# HEAD on a coded result: the headers GET would send, and no byte after
# them (the last chunk a chunked answer sends even to HEAD was read as the
# next answer by a client reusing the connection).
r = exchange(b"HEAD " + RESULT + b" HTTP/1.1\r\nHost: x\r\n" + AUTH + b"Accept-Encoding: gzip\r\n\r\n")
status, f = head_of(r)
after = r.split(b"\r\n\r\n", 1)[1] if b"\r\n\r\n" in r else b"?"
report("HEAD of a gzip result: 200 gzip", status.startswith("HTTP/1.1 200") and f.get("content-encoding") == ["gzip"], status + " " + repr(f.get("content-encoding")))
report("HEAD of a gzip result: no body after the head", after == b"", repr(after[:40]))
report("HEAD of a gzip result: no Content-Length", "content-length" not in f, repr(f.get("content-length")))
c = http.client.HTTPConnection("127.0.0.1", PORT, timeout=5)
hdrs = {"Accept-Encoding": "zstd"}
if AUTH:
    hdrs["Authorization"] = "Bearer " + sys.argv[3]
c.request("HEAD", RESULT.decode(), headers=hdrs)
h = c.getresponse()
h.read()
c.request("GET", "/livez")
try:
    g = c.getresponse()
    report("HEAD of a zstd result, then GET on the same client", g.status == 200, str(g.status))
except Exception as e:  # noqa: BLE001
    report("HEAD of a zstd result, then GET on the same client", False, type(e).__name__ + " " + str(e))
c.close()

# HEAD of an event stream: no Content-Length (the stream has none)
r = exchange(b"HEAD /v1/jobs/%s/events HTTP/1.1\r\nHost: x\r\n%s\r\n" % (JOB.encode(), AUTH))
status, f = head_of(r)
report("HEAD of events: 200 text/event-stream, no Content-Length",
       status.startswith("HTTP/1.1 200") and "content-length" not in f and f.get("content-type") == ["text/event-stream"],
       status + " " + repr(f.get("content-length")))

# 304s of the web files carry no Content-Length
r = exchange(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
_, f = head_of(r)
etag = f.get("etag", ['"none"'])[0].encode()
r = exchange(b"GET / HTTP/1.1\r\nHost: x\r\nIf-None-Match: " + etag + b"\r\n\r\n")
status, f = head_of(r)
report("304 of / without Content-Length", status.startswith("HTTP/1.1 304") and "content-length" not in f, status + " " + repr(f.get("content-length")))
# If-None-Match on two lines is one list
r = exchange(b"GET / HTTP/1.1\r\nHost: x\r\nIf-None-Match: \"0000\"\r\nIf-None-Match: " + etag + b"\r\n\r\n")
status, _ = head_of(r)
report("If-None-Match over two lines: 304", status.startswith("HTTP/1.1 304"), status)

# Accept-Encoding on two lines is one list: zstd wins over gzip;q=0.1
r = exchange(b"GET " + RESULT + b" HTTP/1.1\r\nHost: x\r\n" + AUTH + b"Accept-Encoding: gzip;q=0.1\r\nAccept-Encoding: zstd\r\nConnection: close\r\n\r\n", wait=10)
status, f = head_of(r)
report("Accept-Encoding over two lines: zstd", f.get("content-encoding") == ["zstd"], status + " " + repr(f.get("content-encoding")))

# If-Range holds one tag: a list, even one with the result's own tag, sends
# the whole result (200), not 206
r = exchange(b"HEAD " + RESULT + b" HTTP/1.1\r\nHost: x\r\n" + AUTH + b"Connection: close\r\n\r\n")
rtag = head_of(r)[1].get("etag", ['"none"'])[0].encode()
r = exchange(b"GET " + RESULT + b" HTTP/1.1\r\nHost: x\r\n" + AUTH + b"Range: bytes=0-9\r\nIf-Range: \"a\", " + rtag + b"\r\nConnection: close\r\n\r\n", wait=10)
status, _ = head_of(r)
report("If-Range with a list: 200", status.startswith("HTTP/1.1 200"), status)
r = exchange(b"GET " + RESULT + b" HTTP/1.1\r\nHost: x\r\n" + AUTH + b"Range: bytes=0-9\r\nIf-Range: " + rtag + b"\r\nConnection: close\r\n\r\n", wait=10)
status, _ = head_of(r)
report("If-Range with the result's tag: 206", status.startswith("HTTP/1.1 206"), status)

# A space before a field's colon: 400 and the connection closed, never
# the body read as a second request (request smuggling)
body = b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n"
r = exchange(b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length : %d\r\n\r\n" % len(body) + body)
status, f = head_of(r)
report("space before a colon: 400 invalid_request", status.startswith("HTTP/1.1 400") and b"invalid_request" in r, status)
report("space before a colon: one answer, the connection closed", answers(r) == 1, "%d answers" % answers(r))
# a raw space in the request target
r = exchange(b"GET /li vez HTTP/1.1\r\nHost: x\r\n\r\n")
status, _ = head_of(r)
report("a space in the target: 400", status.startswith("HTTP/1.1 400"), status)
# absolute-form targets are taken (RFC 9112 3.2.2)
r = exchange(b"GET http://x/livez HTTP/1.1\r\nHost: x\r\n\r\n")
status, _ = head_of(r)
report("absolute-form target: 200", status.startswith("HTTP/1.1 200"), status)
# Host is a host and an optional port (RFC 9112 3.2: 400 for an invalid
# value): a port of digits up to 65535, one ":", brackets around an IPv6
# address only, %XX escapes whole (each of these but the space was 200)
for h in [b"a:b", b"a:-1", b"a:99999999999999999999", b"a:65536", b"[::1", b"[zz]:80",
          b"[::1]x", b"a:1:2", b"%4", b"a b", b"[v]", b"[vzz]", b"[v1.]"]:
    r = exchange(b"GET /livez HTTP/1.1\r\nHost: " + h + b"\r\nConnection: close\r\n\r\n")
    status, _ = head_of(r)
    report("Host %r: 400" % h, status.startswith("HTTP/1.1 400") and b"invalid_request" in r, status)
for h in [b"127.0.0.1:80", b"[::1]:8080", b"x:", b"localhost"]:
    r = exchange(b"GET /livez HTTP/1.1\r\nHost: " + h + b"\r\nConnection: close\r\n\r\n")
    status, _ = head_of(r)
    report("Host %r: 200" % h, status.startswith("HTTP/1.1 200"), status)
# valid, but not a name of this daemon without a token (DNS rebinding:
# test_cors_request_id.sh): 403, not 400
for h in [b"example.com", b"example.com:8080", b"[v1.fe]", b"%41"]:
    r = exchange(b"GET /livez HTTP/1.1\r\nHost: " + h + b"\r\nConnection: close\r\n\r\n")
    status, _ = head_of(r)
    report("Host %r: 403 host_not_allowed" % h,
           status.startswith("HTTP/1.1 403") and b"host_not_allowed" in r, status)
