#!/usr/bin/env bash
# examples/python/voxeld_client.py (standard library only) against the daemon:
# as a program and as a module (events, errors, download, cancel).
source "$(dirname "$0")/lib.sh"
PYC=$VX_SOURCE_DIR/examples/python/voxeld_client.py
echo "py-token" >"$TMP/token"
start_daemon --token-file "$TMP/token" || exit 1
cd "$TMP"
MESH=$VX_MESH_DIR/suzanne.obj

VOXELD_URL=$BASE VOXELD_TOKEN=py-token python3 "$PYC" voxelize "$MESH" -p resolution=48 -p format=binvox -o py.binvox >job.json 2>py.err
rc=$?
check "program: exit 0 ($(tail -n 1 py.err))" test $rc -eq 0
check "program: the succeeded job" jq -e '.state == "succeeded" and .params.resolution == 48' job.json
check "program: a binvox file" test "$(head -n 1 py.binvox)" = "#binvox 1"
check "program: progress lines" grep -q 'succeeded 100%' py.err
VOXELD_URL=$BASE VOXELD_TOKEN=py-token python3 "$PYC" voxelize "$MESH" -p resolution=16 -p format=summary -o none.raw >/dev/null 2>py.err
rc=$?
check "program: -o of a job with no file says so ($(tail -n 1 py.err))" \
    sh -c "test $rc -eq 0 && test ! -e none.raw && grep -q 'wrote no file' py.err"
python3 "$PYC" --server "$BASE" --token nope voxelize "$MESH" 2>py.err
check "program: a wrong token exits 1 with the server's message" sh -c "test $? -eq 1 && grep -q 'unauthorized, HTTP 401' py.err"

PYTHONPATH=$(dirname "$PYC") python3 - "$BASE" "$MESH" >module.out 2>&1 <<'PY'
import sys
from voxeld_client import Client, VoxeldError
base, mesh_file = sys.argv[1], sys.argv[2]
c = Client(base, token="py-token")
mesh = c.upload(mesh_file)
assert len(mesh["id"]) == 64, mesh
assert mesh.get("name") == "suzanne.obj", mesh  # named after its file
job = c.submit(mesh["id"], "voxelize", {"resolution": 96})
events = list(c.events(job["id"]))
assert events, "no events"
assert all(e["id"] == job["id"] for e in events)
p = [e["progress"] for e in events]
assert p == sorted(p), p
assert events[-1]["state"] == "succeeded", events[-1]
assert [e["state"] for e in events[:-1] if e["state"] in ("succeeded", "failed", "canceled")] == []
assert c.wait(job["id"])["state"] == "succeeded"
c.download(job["id"], "m.vdb")
assert open("m.vdb", "rb").read(8)[:4] == b"\x20\x42\x44\x56", "not a .vdb"
assert job["id"] in [j["id"] for j in c.jobs(state="succeeded")]
assert mesh["id"] in [m["id"] for m in c.meshes()]
try:
    c.submit(mesh["id"], "voxelize", {"resolution": -1})
    raise SystemExit("no error for a bad param")
except VoxeldError as e:
    assert e.status == 422 and e.code == "invalid_params", e
try:
    c.cancel(job["id"])
    raise SystemExit("canceled a finished job")
except VoxeldError as e:
    assert e.status == 409 and e.code == "job_finished", e
assert c.job(job["id"])["state"] == "succeeded"  # cancel deleted nothing
assert c.delete(job["id"]) is None  # 204
try:
    c.job(job["id"])
    raise SystemExit("a deleted job is still there")
except VoxeldError as e:
    assert e.status == 404 and e.code == "job_not_found", e
# Query values the server takes: plain decimals (1e+06 was refused), and
# a state that is not a name is refused as itself, not read as two params.
small = c.submit(mesh["id"], "voxelize", {"resolution": 16})["id"]
assert c.job(small, wait=1000000, progress=0.00001)["state"] in ("running", "succeeded")
try:
    c.jobs(state="succeeded&limit=1")
    raise SystemExit("a state with '&' was taken")
except VoxeldError as e:
    assert e.status == 400 and "state" in e.message, e
# A server that is not there: VoxeldError, status 0.
try:
    Client("http://127.0.0.1:1").meshes()
    raise SystemExit("no error without a server")
except VoxeldError as e:
    assert e.status == 0 and e.code == "unreachable", e
print("module ok", len(events), "events")
PY
check "module: events, wait, download, lists and errors ($(tail -n 1 module.out))" grep -q '^module ok' module.out

# The program: no server, or no such file, is a message and exit 1, not a
# traceback.
python3 "$PYC" --server http://127.0.0.1:1 voxelize "$MESH" 2>py.err
check "program: no server exits 1 with a message" sh -c "test $? -eq 1 && grep -q unreachable py.err && ! grep -q Traceback py.err"
python3 "$PYC" --server "$BASE" --token py-token voxelize "$TMP/none.obj" 2>py.err
check "program: a missing file exits 1 with a message" sh -c "test $? -eq 1 && grep -q 'No such file' py.err && ! grep -q Traceback py.err"

# Ctrl-C while the job runs: no traceback, exit 130, the job named (it goes
# on). SIGINT is given back its default first (a script's background job
# starts with it ignored).
python3 -c 'import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
os.execvp(sys.argv[1], sys.argv[1:])' python3 "$PYC" --server "$BASE" --token py-token render \
    "$VX_MESH_DIR/spot_triangulated.obj" -p N=64 -p R=1024 -p width=256 -p height=256 -o int.png 2>int.err &
ipid=$!
for _ in $(seq 100); do grep -q running int.err && break; sleep 0.1; done
kill -INT "$ipid"
wait "$ipid"
rc=$?
check "program: Ctrl-C exits 130 and names the job ($(tail -n 1 int.err))" \
    sh -c "test $rc -eq 130 && grep -Eq 'interrupted; job [0-9a-f]{32} goes on' int.err && ! grep -q Traceback int.err"

# Against a stand-in server: a 429 with Retry-After is sent again, an event
# stream that drops or is refused (503) is followed by polling, and a download cut short raises
# (code incomplete) and leaves the old file, with no part file beside it.
PYTHONPATH=$(dirname "$PYC") python3 - >fake.out 2>&1 <<'PY'
import http.server, json, os, threading, time
from voxeld_client import Client, VoxeldError
JOB = {"id": "0123456789abcdef0123456789abcdef", "state": "queued", "progress": 0}
submits = []
plain = []
class H(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    def log_message(self, *a):
        pass
    def answer(self, status, doc, headers=()):
        body = json.dumps(doc).encode()
        self.send_response(status)
        for k, v in headers:
            self.send_header(k, v)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)
    def do_POST(self):
        self.rfile.read(int(self.headers["Content-Length"]))
        submits.append(time.monotonic())
        if len(submits) == 1:
            self.answer(429, {"error": {"code": "queue_full", "message": "full"}}, [("Retry-After", "1")])
        else:
            self.answer(202, JOB)
    def do_GET(self):
        if self.path == "/v1/jobs/full?wait=30":  # no wait to spare
            self.answer(503, {"error": {"code": "too_many_waits", "message": "full"}}, [("Retry-After", "1")])
        elif self.path == "/v1/jobs/full":  # running, then done at the second look
            plain.append(time.monotonic())
            self.answer(200, dict(JOB, state="succeeded" if len(plain) > 1 else "running"))
        elif self.path in ("/v1/jobs/busy/events", "/v1/jobs/full/events"):  # no stream to spare
            self.answer(503, {"error": {"code": "too_many_streams", "message": "busy"}}, [("Retry-After", "5")])
        elif self.path.endswith("/events"):  # one event, then the connection drops
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Transfer-Encoding", "chunked")
            self.end_headers()
            d = b'data: {"id":"0123456789abcdef0123456789abcdef","state":"running","progress":0.5}\n\n'
            self.wfile.write(b"%x\r\n%s\r\n" % (len(d), d))
            self.wfile.flush()
            self.close_connection = True
        elif self.path.startswith("/v1/jobs/") and "?" in self.path:
            self.answer(200, dict(JOB, state="succeeded", progress=1))
        elif self.path == "/v1/jobs/short/result":  # 1000 of 100000 bytes
            self.send_response(200)
            self.send_header("Content-Length", "100000")
            self.end_headers()
            self.wfile.write(b"x" * 1000)
            self.close_connection = True
        else:
            self.send_response(200)
            self.send_header("Content-Length", "10")
            self.end_headers()
            self.wfile.write(b"0123456789")
srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), H)
threading.Thread(target=srv.serve_forever, daemon=True).start()
base = "http://127.0.0.1:%d" % srv.server_address[1]
try:
    Client(base, retry_for=0).submit("m", "voxelize")
    raise SystemExit("retry_for=0 tried again")
except VoxeldError as e:
    assert e.status == 429 and e.retry_after == 1, e
submits.clear()
c = Client(base)
assert c.submit("m", "voxelize")["id"] == JOB["id"]
assert len(submits) == 2 and submits[1] - submits[0] >= 0.9, submits
seen = []
assert c.wait("j", seen.append)["state"] == "succeeded"
assert seen[0]["progress"] == 0.5, seen
t = time.monotonic()  # streams busy (503): polled at once, not retried
assert c.wait("busy")["state"] == "succeeded"
assert time.monotonic() - t < 4, time.monotonic() - t
t = time.monotonic()  # waits full (503 too_many_waits): asked without, a second apart
assert c.wait("full")["state"] == "succeeded"
assert len(plain) == 2 and plain[1] - plain[0] >= 0.9, plain
assert time.monotonic() - t < 8, time.monotonic() - t
with open("old.bin", "wb") as f:
    f.write(b"old")
try:
    c.download("short", "old.bin")
    raise SystemExit("a download cut short was taken")
except VoxeldError as e:
    assert e.code == "incomplete", e
assert open("old.bin", "rb").read() == b"old"
assert not [f for f in os.listdir(".") if f.endswith(".part")], os.listdir(".")
c.download("whole", "new.bin")
assert open("new.bin", "rb").read() == b"0123456789"
print("fake ok")
PY
check "stand-in server: 429 retried, a dropped stream polled, full waits polled without one, a short download refused ($(tail -n 1 fake.out))" grep -q '^fake ok' fake.out

stop_daemon

# A result answered with a redirect (urllib followed it, Authorization and
# all, and saved what came) or a 206 of its tail that was not asked for
# (saved as the whole file), an upload answered with an HTML page or a job
# whose id is a path (tracebacks): an error, no file (hostile_server.py).
# at MODE [ARGS]: the client's voxelize of the torus (and ARGS) against
# hostile_server.py in MODE, in $TMP/h-MODE: rc (also in the file rc), out.txt
at() {
    local m=$1
    shift
    mkdir -p "$TMP/h-$m"
    python3 "$VX_SOURCE_DIR/tests/integration/hostile_server.py" "$TMP/h-$m/port" "$TMP/h-$m/log" "$m" &
    local hpid=$!
    for _ in $(seq 100); do [[ -s "$TMP/h-$m/port" ]] && break; sleep 0.05; done
    rc=0
    python3 "$PYC" --server "http://127.0.0.1:$(cat "$TMP/h-$m/port")" "$@" voxelize \
        "$VX_SOURCE_DIR/examples/meshes/torus.obj" -o "$TMP/h-$m/out.bin" >"$TMP/h-$m/out.txt" 2>&1 || rc=$?
    kill "$hpid"
    echo $rc >"$TMP/h-$m/rc"
}
for m in redirect partial html badid; do
    at $m --token SECRET
    check "$m: the client fails (rc $rc: $(tail -n 1 "$TMP/h-$m/out.txt")), no file" \
        bash -c "test $rc -ne 0 && ! test -e '$TMP/h-$m/out.bin' && ! grep -q Traceback '$TMP/h-$m/out.txt'"
done
check "redirect: nothing went to the Location (the token with it)" bash -c "! grep -q '^GET /steal' '$TMP/h-redirect/log'"
check "redirect: said as one, with its Location (a 302 without a body said nothing)" \
    grep -q 'a redirect to http://127.0.0.1:[0-9]*/steal, not followed' "$TMP/h-redirect/out.txt"
# A server that is no URL, a token with a newline: exit 2, said (tracebacks
# of urllib's ValueError); an output that cannot be written: said before
# anything is sent (it was found after the job ran, naming a part file)
rc=0
python3 "$PYC" --server nonsense voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" >bad.out 2>&1 || rc=$?
check "--server nonsense: exit 2, said ($(tail -n 1 bad.out))" bash -c "test $rc = 2 && grep -q 'http:// or https:// URL' bad.out && ! grep -q Traceback bad.out"
rc=0
python3 "$PYC" --server "http://127.0.0.1:1" --token $'ab\nX: y' voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" >bad.out 2>&1 || rc=$?
check "a token with a newline: exit 2, said ($(tail -n 1 bad.out))" bash -c "test $rc = 2 && grep -q 'no header' bad.out && ! grep -q Traceback bad.out"
mkdir -p "$TMP/h-badid"
python3 "$VX_SOURCE_DIR/tests/integration/hostile_server.py" "$TMP/h-badid/port2" "$TMP/h-badid/log2" badid &
hpid=$!
for _ in $(seq 100); do [[ -s "$TMP/h-badid/port2" ]] && break; sleep 0.05; done
for o in /nonexistent-dir/out.bin "$TMP"; do
    rc=0
    python3 "$PYC" --server "http://127.0.0.1:$(cat "$TMP/h-badid/port2")" voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" -o "$o" >bad.out 2>&1 || rc=$?
    check "-o $o: exit 1 before anything is sent ($(tail -n 1 bad.out))" bash -c "test $rc = 1 && grep -q 'cannot write' bad.out && ! test -s '$TMP/h-badid/log2'"
done
kill "$hpid"
# A job that is {} (a KeyError traceback), a failed job whose error is
# null ("job failed: None"), an error message with terminal escapes (they
# reached the terminal)
for m in shape nullerr esc atonce cut cutbody; do
    at $m
done
check "a job that is {}: bad_answer, exit 1 ($(tail -n 1 "$TMP/h-shape/out.txt"))" \
    bash -c "test \$(cat '$TMP/h-shape/rc') = 1 && grep -q 'bad_answer' '$TMP/h-shape/out.txt' && ! grep -q Traceback '$TMP/h-shape/out.txt'"
check "a failed job without an error: said ($(tail -n 1 "$TMP/h-nullerr/out.txt"))" \
    bash -c "test \$(cat '$TMP/h-nullerr/rc') = 1 && grep -q 'job failed: (the server gave no error)' '$TMP/h-nullerr/out.txt'"
check "?wait answered at once: polled once a second ($(grep -c '^GET /v1/jobs/[0-9a-f]*?wait' "$TMP/h-atonce/log") polls in 3 s), the result written" \
    bash -c "test \$(cat '$TMP/h-atonce/rc') = 0 && test -s '$TMP/h-atonce/out.bin' && test \$(grep -c '^GET /v1/jobs/[0-9a-f]*?wait' '$TMP/h-atonce/log') -le 6"
# A submission whose answer was lost (the connection closed after the
# server took it): sent again under its Idempotency-Key, the first job
# followed (it failed "unreachable"; without a key a retry queues another)
check "a lost submit answer: sent again with one key, the first job followed ($(grep 'POST /v1/jobs' "$TMP/h-cut/log" | tr '\n' ' '))" \
    bash -c "test \$(cat '$TMP/h-cut/rc') = 0 && test -s '$TMP/h-cut/out.bin' && test \$(grep '^POST /v1/jobs' '$TMP/h-cut/log' | awk '{print \$NF}' | grep -cE '^[0-9a-f]{32}\$') = 2 && test \$(grep '^POST /v1/jobs' '$TMP/h-cut/log' | awk '{print \$NF}' | sort -u | wc -l) = 1 && ! grep -q efef '$TMP/h-cut/log'"
check "a submit answer cut in its body: sent again with its key, no traceback ($(tail -n 1 "$TMP/h-cutbody/out.txt"))" \
    bash -c "test \$(cat '$TMP/h-cutbody/rc') = 0 && test -s '$TMP/h-cutbody/out.bin' && test \$(grep -c '^POST /v1/jobs' '$TMP/h-cutbody/log') = 2 && ! grep -q efef '$TMP/h-cutbody/log'"
check "escapes in an error: shown as '?' ($(tail -n 1 "$TMP/h-esc/out.txt" | cat -v))" \
    bash -c "test \$(cat '$TMP/h-esc/rc') = 1 && grep -q 'bad?' '$TMP/h-esc/out.txt' && ! grep -q \$'\\x1b' '$TMP/h-esc/out.txt'"
finish
