#!/usr/bin/env bash
# A full disk (issue #10, defect 4): every write gets an answer (507 with the
# JSON error, also for an upload that fills the disk half-way through its
# body), nothing acknowledged is lost, the daemon starts on a full disk and
# serves reads, /readyz and /metrics report free space against the floor,
# and no error names a server path. Runs on a small tmpfs; needs root to
# mount it (skipped, exit 77, otherwise).
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
if [[ $(id -u) -ne 0 ]]; then echo "SKIP: needs root to mount a small tmpfs"; exit 77; fi
DISK=$TMP/disk
mkdir -p "$DISK"
if ! mount -t tmpfs -o size=24m voxeld-full-disk "$DISK"; then echo "SKIP: cannot mount a tmpfs here"; exit 77; fi
trap 'if [[ -n "$PID" ]]; then kill -KILL "$PID" 2>/dev/null; wait "$PID" 2>/dev/null; PID=; fi; umount -l "$DISK"; cleanup' EXIT
DATA=$DISK/data
FLOOR=$((1 << 20))

# fill_to BYTES: a filler file leaves about BYTES free (0 = none at all).
fill_to() {
    rm -f "$DISK/filler" "$DISK/filler2"
    local avail
    avail=$(df -B1 --output=avail "$DISK" | tail -n 1)
    local want=$(((avail - $1) / 65536))
    if ((want > 0)); then dd if=/dev/zero of="$DISK/filler" bs=64k count="$want" status=none 2>/dev/null; fi
    if (($1 == 0)); then dd if=/dev/zero of="$DISK/filler2" bs=4k status=none 2>/dev/null; fi
    return 0
}
free_bytes() { df -B1 --output=avail "$DISK" | tail -n 1 | tr -d ' '; }
no_paths() { ! grep -q -e "$DISK" -e "$TMP" "$BODY"; }

start_daemon --min-free-disk "$FLOOR" || exit 1
box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
expect_status "upload with room" 201
BOX=$MESH_ID
run_job preview "$BOX" '{"width":32,"height":32}'
job_ok "a job with room"
DONE=$JOB
api GET /readyz
expect_status "readyz with room" 200
check "readyz disk_space true" jq -e '.checks.disk_space == true' "$BODY"

# An upload larger than the space left: the body fills the disk half-way.
python3 - "$TMP/big.obj" <<'PY'
import sys
n = 260
with open(sys.argv[1], "w") as f:
    for j in range(n):
        for i in range(n):
            f.write(f"v {i*0.001:.6f} {j*0.001:.6f} {(i*j)%7*0.0001:.6f}\n")
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i + 1
            f.write(f"f {a} {a+1} {a+n+1}\nf {a} {a+n+1} {a+n}\n")
PY
fill_to $((3 << 20))
upload "$TMP/big.obj"
expect_error "upload that fills the disk mid-body ($(stat -c %s "$TMP/big.obj") bytes)" 507 insufficient_storage
check "that error names no server path" no_paths
check "the half-written upload is gone again" test "$(find "$DATA/tmp" -type f | wc -l)" -eq 0
# A chunked upload that fills the disk is answered 507 when it does, not
# at its end (it was read to its end first: never, for one that does not
# end). The disk is above the floor, so the head is accepted.
fill_to $((3 << 20))
IFS='|' read -r line code secs end < <(endless_chunks /v1/meshes model/obj)
check "an endless chunked upload on a filling disk is answered 507 insufficient_storage ($line, $code, after ${secs}s, then $end)" \
    test "$line" = "HTTP/1.1 507 Insufficient Storage" -a "$code" = insufficient_storage -a "$end" != none
check "its half-written upload is gone again" test "$(find "$DATA/tmp" -type f | wc -l)" -eq 0
api GET /livez
expect_status "serving after it" 200

# Under the floor: writes answer 507 before the body, reads keep working.
fill_to $((FLOOR / 2))
box_obj "$TMP/box2.obj" 0 0 0 1 2 3
upload "$TMP/box2.obj"
expect_error "upload under the floor" 507 insufficient_storage
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
expect_error "job under the floor" 507 insufficient_storage
check "names no server path" no_paths
api GET /readyz
expect_status "readyz under the floor" 503
check "readyz says disk_space false" jq -e '.checks.disk_space == false' "$BODY"
api GET /metrics
check "metrics report free bytes under the floor" \
    awk -v f="$FLOOR" '$1=="voxeld_data_dir_free_bytes" {fr=$2} $1=="voxeld_data_dir_min_free_bytes" {fl=$2} END {exit !(fl==f && fr<f)}' "$BODY"
api GET "/v1/jobs/$DONE/result"
expect_status "results still download" 200

# A completely full disk: kill -9, and the daemon starts again on it.
fill_to 0
check "the disk is full" test "$(free_bytes)" -lt 8192
kill9_daemon
start_daemon --min-free-disk "$FLOOR" || exit 1
check "started on a full disk" grep -q 'event=journal.compact_skipped' "$TMP/daemon.log"
api GET "/v1/jobs/$DONE"
check "finished job still there" jq -e '.state == "succeeded"' "$BODY"
api GET "/v1/meshes/$BOX"
expect_status "mesh still there" 200
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
expect_error "job on a full disk" 507 insufficient_storage
upload "$TMP/box2.obj"
expect_error "upload on a full disk" 507 insufficient_storage
# A floor of 0 still refuses writes when not a byte is free.
kill9_daemon
start_daemon --min-free-disk 0 || exit 1
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
check "job with floor 0 on a full disk: 507 (got $STATUS)" test "$STATUS" = 507
# A full disk is a writable data dir without room: 507 and disk_space
# false, not the read-only dir's 503 and data_dir false (its probe file
# failing with ENOSPC was taken for a read-only dir).
upload "$TMP/box2.obj"
expect_error "upload with floor 0 on a full disk" 507 insufficient_storage
api GET /readyz
expect_status "readyz on a full disk" 503
check "readyz: data_dir true, disk_space false ($(jq -c .checks "$BODY"))" \
    jq -e '.checks.data_dir == true and .checks.disk_space == false' "$BODY"
check "readyz: the reason is the full disk ($(jqb .reason))" test "$(jqb .reason)" = "the data directory's disk is full"
# A stop on a full disk keeps the journal as appended, and says so.
stop_daemon
check "a stop on a full disk logs its compaction skipped" grep -q 'event=journal.compact_skipped at=stop' "$TMP/daemon.log"
start_daemon --min-free-disk 0 || exit 1

# Room again: writes work without a restart, and what they acknowledge
# survives kill -9 (a crash mid-record left a torn tail before it).
rm -f "$DISK/filler" "$DISK/filler2"
printf '#0badf00d {"job":{"id":"torn' >>"$DATA/journal.log"
kill9_daemon
start_daemon --min-free-disk "$FLOOR" || exit 1
api GET /readyz
expect_status "readyz with room again" 200
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":48,\"height\":48}}"
expect_status "job with room again" 202
AFTER=$(jqb .id)
kill9_daemon
check "no journal record was lost or dropped" bash -c "! grep -q 'journal.bad_record' '$TMP/daemon.log'"
start_daemon --min-free-disk "$FLOOR" || exit 1
wait_job "$AFTER" 120
check "the job acknowledged after the full disk ran" jq -e '.state == "succeeded"' "$BODY"
upload "$TMP/box2.obj"
expect_status "upload with room again" 201

# A result that runs out of space while it is written fails the job
# (io_error, no path named) and leaves no file: a .vdb used to be cut short
# (or left empty) and served as a succeeded job's result.
upload "$VX_MESH_DIR/spot_triangulated.obj"
expect_status "upload spot" 201
SPOT=$MESH_ID
kill9_daemon
start_daemon --min-free-disk 0 || exit 1
# (binvox at 512: its 256^3 file would fit in the room left)
for f in vdb:fog vdb:level_set vdb:bool raw8 raw1 npy vox binvox/512; do
    res=256
    [[ $f == */* ]] && res=${f#*/} f=${f%/*}
    p="\"format\":\"${f%%:*}\""
    [[ $f == vdb:* ]] && p="$p,\"vdb_grid\":\"${f#vdb:}\""
    fill_to $((192 << 10))
    run_job voxelize "$SPOT" "{\"resolution\":$res,$p}"
    check "$f on a disk that fills: failed io_error ($(jq -c '.state, .error' "$TMP/job.json" | tr '\n' ' '))" \
        jq -e '.state == "failed" and .error.code == "io_error"' "$TMP/job.json"
    cp "$TMP/job.json" "$BODY"
    check "$f: the error names no server path" no_paths
    check "$f: nor any path: the file only ($(jq -r .error.message "$TMP/job.json"))" sh -c "! jq -r .error.message '$TMP/job.json' | grep -q /"
    api GET "/v1/jobs/$JOB/result"
    check "$f: no result served (got $STATUS)" test "$STATUS" != 200
    check "$f: no file left behind" test -z "$(find "$DATA" -path "*$JOB*" -type f 2>/dev/null)"
done
# The other kinds' writers alike: io_error with errno's words and the
# file's name only (they were png_write "Write Error", mesh_io with the
# path, and a render's PFM without its reason).
for kp in 'preview|{"width":2048,"height":2048}' 'render|{"N":16,"width":512,"height":512,"outputs":["image","depth"]}' \
    'gregory|{"divisions":8,"format":"ply"}' 'gregory|{"divisions":8,"format":"glb"}' \
    'catmull-clark|{"levels":3,"format":"obj"}'; do
    k=${kp%%|*} p=${kp#*|}
    fill_to $((16 << 10))
    run_job "$k" "$SPOT" "$p"
    check "$k $p on a disk that fills: failed io_error ($(jq -c '.state, .error' "$TMP/job.json" | tr '\n' ' '))" \
        jq -e '.state == "failed" and .error.code == "io_error" and (.error.message | contains("No space left on device"))' "$TMP/job.json"
    check "$k: the file only, no path ($(jq -r .error.message "$TMP/job.json"))" sh -c "! jq -r .error.message '$TMP/job.json' | grep -q /"
    check "$k: no file left behind" test -z "$(find "$DATA" -path "*$JOB*" -type f 2>/dev/null)"
done
rm -f "$DISK/filler" "$DISK/filler2"
run_job voxelize "$SPOT" '{"resolution":256,"format":"vdb","vdb_grid":"fog"}'
job_ok "vdb fog with room again"

# Jobs that end once the disk is full: their records still go into the
# journal (the space it keeps allocated past its end), so what a client
# was told stays true after kill -9. They were told succeeded, the end was
# not written, and after a restart they were queued and ran again.
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$SPOT\",\"kind\":\"preview\",\"params\":{\"width\":4096,\"height\":4096,\"samples\":8}}"
expect_status "a slow job in front" 202
ENDS=()
for r in 20 21 22; do
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$SPOT\",\"kind\":\"voxelize\",\"params\":{\"resolution\":$r,\"format\":\"summary\"}}"
    expect_status "summary job $r queued behind it" 202
    ENDS+=("$(jqb .id)")
done
fill_to 0
for id in "${ENDS[@]}"; do
    wait_job "$id" 120
    check "job $id ended on the full disk" jq -e '.state == "succeeded"' "$BODY"
done
check "no journal record failed" bash -c "! grep -q 'event=journal.append_failed' '$TMP/daemon.log'"
kill9_daemon
rm -f "$DISK/filler" "$DISK/filler2"
start_daemon --min-free-disk 0 || exit 1
for id in "${ENDS[@]}"; do
    api GET "/v1/jobs/$id"
    check "after kill -9, job $id is still succeeded ($(jqb .state))" jq -e '.state == "succeeded"' "$BODY"
done

# A retry of an accepted submission (the same Idempotency-Key and
# request), and a reuse of a finished one, are answered with that job on a
# full disk (200); only a new job is refused (it was 507 before the key
# was looked at: a client whose 202 was lost thought it never went in).
IK='{"mesh":"'$BOX'","kind":"voxelize","params":{"resolution":9,"format":"summary"}}'
api POST "/v1/jobs?wait=30" -H "Content-Type: application/json" -H "Idempotency-Key: full-1" -d "$IK"
expect_status "a job with a key, with room" 202
KJ=$(jqb .id)
fill_to 0
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: full-1" -d "$IK"
expect_status "its retry on a full disk: the job" 200
check "the same job ($(jqb .id))" test "$(jqb .id)" = "$KJ"
api POST /v1/jobs -H "Content-Type: application/json" -d '{"mesh":"'$BOX'","kind":"voxelize","params":{"resolution":9,"format":"summary"},"reuse":true}'
expect_status "reuse of it on a full disk: the job" 200
check "reuse: the same job" test "$(jqb .id)" = "$KJ"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: full-2" -d "$IK"
expect_error "a new key on a full disk" 507 insufficient_storage
rm -f "$DISK/filler" "$DISK/filler2"

# New jobs on a full disk with no floor (--min-free-disk 0): each takes the
# journal's reserve only down to what the jobs not yet finished still need
# (a start and an end each, at least half the reserve), then new ones get
# 507, and the records of the jobs accepted before still go in. They had
# taken all of it: a job told succeeded ran again after kill -9. Sent
# without waiting, many are queued at the 507. (300 KB stay free: too
# little to top the reserve up, enough to pass the free-space check.)
stop_daemon
start_daemon --min-free-disk 0 --max-queued-jobs 1000 || exit 1
fill_to 300000
# submit.py: new jobs until the first refusal; prints the accepted ids,
# then the refusal's status and body. check.py: every id succeeded, once.
cat >"$TMP/submit.py" <<'PY'
import json, sys, urllib.request, urllib.error
base, mesh = sys.argv[1], sys.argv[2]
for i in range(1, 1001):
    p = {"resolution": 8 + i // 100, "padding": i % 50, "format": "summary",
         "supersample": 1 + i // 50 % 2}
    req = urllib.request.Request(base + "/v1/jobs", data=json.dumps(
        {"mesh": mesh, "kind": "voxelize", "params": p}).encode(),
        headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req) as r:
            print(json.load(r)["id"])
    except urllib.error.HTTPError as e:
        print("refused", e.code, e.read().decode())
        break
PY
cat >"$TMP/check.py" <<'PY'
import json, sys, time, urllib.request
base, bad = sys.argv[1], 0
for jid in open(sys.argv[2]).read().split():
    for _ in range(1200):
        with urllib.request.urlopen(base + "/v1/jobs/" + jid) as r:
            j = json.load(r)
        if j["state"] in ("succeeded", "failed", "canceled"):
            break
        time.sleep(0.1)
    if j["state"] != "succeeded" or j["attempts"] != 1:
        bad += 1
        print(jid, j["state"], j["attempts"])
print(bad)
PY
python3 "$TMP/submit.py" "$BASE" "$BOX" >"$TMP/submitted"
grep -v '^refused' "$TMP/submitted" >"$TMP/accepted"
N=$(wc -l <"$TMP/accepted")
echo "accepted $N jobs before the refusal"
# (mostly the journal's own refusal, "kept for the jobs already accepted";
# on a loaded machine the free-space check can come first: the disk full)
check "then 507 insufficient_storage ($(tail -n 1 "$TMP/submitted"))" \
    grep -q '^refused 507 .*insufficient_storage' "$TMP/submitted"
check "some jobs were accepted first ($N)" test "$N" -gt 20
check "the accepted jobs all succeeded" test "$(python3 "$TMP/check.py" "$BASE" "$TMP/accepted" | tail -n 1)" = 0
check "every record of the accepted jobs went in" bash -c "! grep -q 'event=journal.append_failed' '$TMP/daemon.log'"
kill9_daemon
FROM=$(wc -l <"$TMP/daemon.log")
start_daemon --min-free-disk 0 || exit 1
check "after kill -9 the $N accepted jobs are still succeeded, run once" \
    test "$(python3 "$TMP/check.py" "$BASE" "$TMP/accepted" | tail -n 1)" = 0
check "none was replayed to run again" bash -c "tail -n +$((FROM + 1)) '$TMP/daemon.log' | grep -q 'event=jobs.replayed.* requeued=0 '"

# A restart on a full disk keeps the journal's reserve it finds: the blocks
# a run before left allocated past its end (it topped up to 1 MiB, jobs
# used some). The failed top-up at start forgot them, and every new job was
# 507 though no job was unfinished and more than half the reserve was there.
rm -f "$DISK/filler" "$DISK/filler2"
stop_daemon
start_daemon --min-free-disk 0 || exit 1
python3 - "$BASE" "$BOX" <<'PY'
import json, sys, urllib.request
base, mesh = sys.argv[1], sys.argv[2]
for i in range(100):
    req = urllib.request.Request(base + "/v1/jobs?wait=30", data=json.dumps(
        {"mesh": mesh, "kind": "voxelize",
         "params": {"resolution": 8, "padding": 100 + i, "format": "summary"}}).encode(),
        headers={"Content-Type": "application/json"})
    urllib.request.urlopen(req).read()
PY
past_end() { echo $(($(stat -c '%b * %B - %s' "$DATA/journal.log"))); }
KEPT=$(past_end)
check "jobs used some of the reserve: $KEPT bytes past the end, between half and all of 1 MiB" \
    test "$KEPT" -gt $((600 << 10)) -a "$KEPT" -lt $((1 << 20))
fill_to 0
kill9_daemon
start_daemon --min-free-disk 0 || exit 1
FOUND=$(grep -o 'event=journal.reserve_failed .*reserved=[0-9]*' "$TMP/daemon.log" | tail -n 1 | sed 's/.*reserved=//')
check "its top-up failed, the reserve found ($FOUND) is logged: what is there, to 8 KiB" \
    test -n "$FOUND" -a "${FOUND:-0}" -le "$KEPT" -a "${FOUND:-0}" -ge $((KEPT - 8192))
fill_to 100000
run_job voxelize "$BOX" '{"resolution":8,"padding":99,"format":"summary"}'
job_ok "after a restart on a full disk, with 100 KB freed and the reserve found, a new job runs"

# The data dir made read-only under the daemon (a read-only bind mount over
# it): uploads and new jobs get 503 not_ready, as /readyz says, instead of
# a job accepted (202) that failed at its first output; reads still work.
rm -f "$DISK/filler" "$DISK/filler2"
if mount --bind "$DATA" "$DATA" && mount -o remount,ro,bind "$DATA"; then
    api GET /readyz
    expect_status "readyz on a read-only data dir" 503
    run_job voxelize "$BOX" '{"resolution":8,"format":"summary","padding":7}'
    check "a new job on a read-only data dir: 503 not_ready ($(jq -c .error "$TMP/job.json"))" \
        jq -e '.error.code == "not_ready" and (.error.message | contains("not writable"))' "$TMP/job.json"
    upload "$TMP/box.obj"
    expect_error "an upload on a read-only data dir" 503 not_ready
    api GET "/v1/jobs/$DONE"
    expect_status "reads still work" 200
    umount "$DATA"
    run_job voxelize "$BOX" '{"resolution":8,"format":"summary","padding":7}'
    job_ok "writable again: the job runs"
else
    echo "SKIP: no read-only bind mount here"
fi
stop_daemon
finish
