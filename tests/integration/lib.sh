# Sourced by tests/integration/test_*.sh: start a real voxeld on a free port
# with a temp data dir, talk to it with curl, assert with jq.
#
# Every request made through `api` is recorded in $VX_API_LOG (JSON lines)
# so that test_zz_openapi.sh can check each response against
# api/openapi.yaml and that every operation in it was exercised.
set -uo pipefail
: "${VOXELD:?VOXELD must point at the voxeld binary}"
: "${VX_TOOLS:?}" "${VX_MESH_DIR:?}" "${VX_SOURCE_DIR:?}"

TMP=$(mktemp -d "${TMPDIR:-/tmp}/voxeld-it.XXXXXX")
VX_API_LOG=${VX_API_LOG:-$TMP/api.jsonl}
# Response bodies outlive the test's temp dir: the contract check reads them.
BODIES=${VX_API_LOG%.jsonl}.bodies/$(basename "$0" .sh)-$$
mkdir -p "$BODIES"
DATA=$TMP/data
PASS=0
FAIL=0
PID=
PORT=
BASE=
NREQ=0
STATUS=
BODY=
HDRS=
CTYPE=
TOKEN=

cleanup() {
    if [[ -n "$PID" ]] && kill -0 "$PID" 2>/dev/null; then kill -KILL "$PID" 2>/dev/null; fi
    if [[ $FAIL -eq 0 && -z "${VX_KEEP_TMP:-}" ]]; then rm -rf "$TMP"; else echo "kept $TMP"; fi
}
trap cleanup EXIT

# start_daemon [extra voxeld flags...]: waits for the ready line.
start_daemon() {
    touch "$TMP/daemon.log"
    local from
    from=$(($(wc -l <"$TMP/daemon.log") + 1))
    "$VOXELD" --listen 127.0.0.1:0 --data-dir "$DATA" --workers 2 --http-threads 4 "$@" \
        2>>"$TMP/daemon.log" &
    PID=$!
    local i
    for i in $(seq 1 600); do
        PORT=$(tail -n +"$from" "$TMP/daemon.log" | grep -a 'event=voxeld.ready' | sed -n 's/.*port=\([0-9]*\).*/\1/p')
        if [[ -n "$PORT" ]]; then
            BASE="http://127.0.0.1:$PORT"
            return 0
        fi
        if ! kill -0 "$PID" 2>/dev/null; then
            echo "voxeld exited during start:"; tail -n 20 "$TMP/daemon.log"; PID=; return 1
        fi
        sleep 0.1
    done
    echo "voxeld did not become ready"; tail -n 20 "$TMP/daemon.log"; return 1
}

# stop_daemon: SIGTERM, expect exit status 0.
stop_daemon() {
    kill -TERM "$PID"
    local rc=0
    wait "$PID" || rc=$?
    PID=
    check "daemon exits 0 on SIGTERM (got $rc)" test "$rc" -eq 0
}

kill9_daemon() {
    kill -KILL "$PID"
    wait "$PID" 2>/dev/null
    PID=
}

# api METHOD PATH [curl args...]: sets STATUS, BODY (file), HDRS (file), CTYPE.
api() {
    local method=$1 path=$2
    shift 2
    NREQ=$((NREQ + 1))
    BODY=$BODIES/r$NREQ.body
    HDRS=$BODIES/r$NREQ.headers
    local auth=()
    if [[ -n "$TOKEN" ]]; then auth=(-H "Authorization: Bearer $TOKEN"); fi
    # A JSON request body (-d/--data*, or @FILE) is kept for the contract check
    # (up to 256 KiB: it checks no larger ones).
    local reqf= reqct= reqv= a prev=
    for a in "$@"; do
        case "$prev" in
        -H) if [[ "${a,,}" == content-type:* ]]; then reqct=${a#*:} && reqct=${reqct# }; fi ;;
        -d | --data | --data-raw | --data-binary) reqv=$a ;;
        esac
        prev=$a
    done
    if [[ -n "$reqv" && "${reqct,,}" == application/json* ]]; then
        reqf=$BODIES/r$NREQ.request
        if [[ "$reqv" == @?* ]]; then cp "${reqv#@}" "$reqf" 2>/dev/null || reqf=; else printf '%s' "$reqv" >"$reqf"; fi
        if [[ -n "$reqf" && $(stat -c %s "$reqf") -gt 262144 ]]; then rm -f "$reqf"; reqf=; fi
    fi
    local out
    if [[ "$method" == HEAD ]]; then
        out=$(curl -sS -I -o /dev/null -D "$HDRS" -w '%{http_code} %{content_type}' "${auth[@]}" "$@" "$BASE$path")
        : >"$BODY"
    else
        out=$(curl -sS -X "$method" -o "$BODY" -D "$HDRS" -w '%{http_code} %{content_type}' "${auth[@]}" "$@" "$BASE$path")
    fi
    STATUS=${out%% *}
    CTYPE=${out#* }
    [[ "$CTYPE" == "$out" ]] && CTYPE=
    local headers
    headers=$(tr -d '\r' <"$HDRS" | awk -F': ' 'NF>=2 && $1 !~ /^HTTP/ {printf "%s\t%s\n", tolower($1), substr($0, length($1)+3)}' |
        jq -R -s 'split("\n") | map(select(length>0) | split("\t") | {(.[0]): .[1]}) | add // {}')
    jq -cn --arg m "$method" --arg p "$path" --argjson s "${STATUS:-0}" --arg ct "$CTYPE" \
        --argjson h "$headers" --arg b "$BODY" --arg rf "$reqf" --arg rct "$reqct" \
        '{method:$m, path:$p, status:$s, content_type:$ct, headers:$h, body_file:$b}
         + if $rf == "" then {} else {request_body_file:$rf, request_content_type:$rct} end' >>"$VX_API_LOG"
}

# jqb FILTER: jq on the last body.
jqb() { jq -r "$@" "$BODY"; }
header() { tr -d '\r' <"$HDRS" | awk -F': ' -v n="$(echo "$1" | tr A-Z a-z)" 'tolower($1)==n {print substr($0, length($1)+3)}' | tail -n 1; }

check() {
    local what=$1
    shift
    if "$@" >/dev/null 2>&1; then
        PASS=$((PASS + 1))
    else
        FAIL=$((FAIL + 1))
        echo "FAIL: $what"
        if [[ -n "$BODY" && -f "$BODY" ]]; then echo "  last status $STATUS body: $(head -c 400 "$BODY")"; fi
    fi
}

expect_status() { check "$1: status $2 (got $STATUS)" test "$STATUS" = "$2"; }

# expect_error WHAT STATUS [CODE]: status, JSON error body, optional code.
expect_error() {
    local what=$1 st=$2 code=${3:-}
    check "$what: status $st (got $STATUS)" test "$STATUS" = "$st"
    check "$what: JSON error body" jq -e '.error.code and .error.message and (.error|length)==2' "$BODY"
    if [[ -n "$code" ]]; then check "$what: error code $code (got $(jqb .error.code 2>/dev/null))" test "$(jqb .error.code)" = "$code"; fi
}

# upload FILE [content-type]: POST /v1/meshes, sets MESH_ID.
upload() {
    local ct=${2:-model/obj}
    api POST /v1/meshes -H "Content-Type: $ct" --data-binary "@$1"
    MESH_ID=$(jqb '.id // empty')
}

# wait_job JID [seconds]: polls with ?wait until the job has finished.
wait_job() {
    local jid=$1 limit=${2:-120} t=0
    while ((t < limit)); do
        api GET "/v1/jobs/$jid?wait=10"
        case "$(jqb .state)" in succeeded | failed | canceled) return 0 ;; esac
        t=$((t + 10))
    done
    return 1
}

# until_running JID [seconds]: polls the job until it runs (a slow job
# holding the GL thread), at most that long (default 10); $BODY is its last
# answer.
until_running() {
    local jid=$1 n=$((${2:-10} * 10)) i
    for ((i = 0; i < n; i++)); do
        api GET "/v1/jobs/$jid"
        [[ "$(jqb .state)" == running ]] && return 0
        sleep 0.1
    done
    return 1
}

# slow_preview: uploads ogre.obj (OGRE) and submits SLOWREQ, an 8192^2
# preview of it with 8 samples that holds the GL thread for a while (SLOW,
# running on return unless the queue was busy).
slow_preview() {
    upload "$VX_MESH_DIR/ogre.obj"
    OGRE=$MESH_ID
    SLOWREQ="{\"mesh\":\"$OGRE\",\"kind\":\"preview\",\"params\":{\"width\":8192,\"height\":8192,\"samples\":8}}"
    api POST /v1/jobs -H "Content-Type: application/json" -d "$SLOWREQ"
    SLOW=$(jqb .id)
    until_running "$SLOW"
}

# run_job KIND MESH PARAMS_JSON [seconds]: submits a job and waits until it
# has finished; JOB = its id, $TMP/job.json = its last body (the caller
# checks the state: failures are sometimes what a test wants).
run_job() {
    local limit=${4:-120}
    api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$2\",\"kind\":\"$1\",\"params\":$3}"
    JOB=$(jqb '.id // empty')
    if [[ -n "$JOB" ]] && ! jq -e '.state == "succeeded" or .state == "failed"' "$BODY" >/dev/null; then
        wait_job "$JOB" "$limit"
    fi
    cp "$BODY" "$TMP/job.json"
}
# job_ok WHAT: the job in $TMP/job.json succeeded.
job_ok() { check "$1: succeeded ($(jq -c '.error' "$TMP/job.json" 2>/dev/null))" jq -e '.state == "succeeded"' "$TMP/job.json"; }
# st NAME: stats.NAME of the job in $TMP/job.json.
st() { jq -r ".stats.$1" "$TMP/job.json"; }

# endless_chunks PATH CONTENT-TYPE: a chunked POST whose body never ends
# (16 KiB chunks for up to 15 s), reading while it sends; prints
# "STATUS_LINE|CODE|SECONDS|END" (the error body's code, the seconds until
# the connection ended, END none, eof or reset).
endless_chunks() {
    python3 - "$PORT" "$1" "$2" <<'PY'
import json, socket, sys, time
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(("POST %s HTTP/1.1\r\nHost: x\r\nContent-Type: %s\r\n"
           "Transfer-Encoding: chunked\r\n\r\n" % (sys.argv[2], sys.argv[3])).encode())
chunk = b"4000\r\n" + b"v 1 2 3\n" * 2048 + b"\r\n"
t0, got, end = time.monotonic(), b"", "none"
s.settimeout(0.02)
while time.monotonic() - t0 < 15 and end == "none":
    try:
        s.send(chunk)
    except socket.timeout:
        pass
    except OSError:
        end = "reset"
    try:
        b = s.recv(65536)
        got += b
        if not b:
            end = "eof"
    except socket.timeout:
        pass
    except OSError:
        end = "reset"
    time.sleep(0.002)
head, _, body = got.partition(b"\r\n\r\n")
try:
    code = json.loads(body)["error"]["code"]
except ValueError:
    code = "-"
print("%s|%s|%.1f|%s" % (head.split(b"\r\n")[0].decode("latin-1"), code, time.monotonic() - t0, end))
PY
}

finish() {
    echo "$(basename "$0"): $PASS passed, $FAIL failed"
    [[ $FAIL -eq 0 ]]
}
