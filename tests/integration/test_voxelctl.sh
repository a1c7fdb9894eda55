#!/usr/bin/env bash
# voxelctl against a real daemon (token from the flag and from VOXELD_*),
# its errors and exit codes, and --local / `voxeld run` without a server.
source "$(dirname "$0")/lib.sh"
CTL=$(dirname "$VOXELD")/voxelctl
if [[ ! -x "$CTL" ]]; then echo "no voxelctl next to $VOXELD"; exit 1; fi
MESH=$VX_MESH_DIR/suzanne.obj
echo "s3cret-token" >"$TMP/token"
start_daemon --token-file "$TMP/token" || exit 1
export VOXELD_URL=$BASE VOXELD_TOKEN=s3cret-token
cd "$TMP"

# voxelize: upload, follow (plain lines: stderr is not a terminal), download.
"$CTL" voxelize "$MESH" -r 64 -f binvox -o out.binvox >ctl.out 2>ctl.err
rc=$?
check "voxelize: exit 0 ($(tail -n 2 ctl.err))" test $rc -eq 0
check "voxelize: a binvox file" test "$(head -n 1 out.binvox)" = "#binvox 1"
check "voxelize: 64 voxels along the longest side" awk '/^dim/ { exit !($2 == 64 || $3 == 64 || $4 == 64) }' out.binvox
check "voxelize: progress lines end with succeeded 100%" grep -Eq '^[0-9a-f]{32} succeeded 100%$' ctl.err
check "voxelize: says where the result went" grep -q 'wrote out.binvox' ctl.err

# On a terminal (script(1) gives it one): a progress bar redrawn with \r.
if command -v script >/dev/null; then
    script -qec "'$CTL' voxelize '$MESH' -r 96 -o tty.vdb" /dev/null >tty.out 2>&1
    check "terminal: a progress bar redrawn in place" grep -aq $'\rsucceeded \[#\{30\}\] 100%' tty.out
    check "terminal: the result" test -s tty.vdb
fi

# --json: the finished Job on stdout.
"$CTL" --json voxelize "$MESH" -r 32 -f raw8 -p padding=1 -o out.raw >job.json 2>/dev/null
check "--json: exit 0" test $? -eq 0
check "--json: the succeeded job with the params given" jq -e '.state == "succeeded" and .params.resolution == 32 and .params.padding == 1 and .params.format == "raw8"' job.json
JID=$(jq -r .id job.json)
MID=$(jq -r .mesh job.json)
"$CTL" get "$JID" --name voxels -o again.raw 2>/dev/null
check "get --name -o: the same bytes as the job's download" cmp -s out.raw again.raw
# --name is one output's name, escaped: never another path of the API.
"$CTL" get "$JID" --name "../../../meshes/$MID" -o escaped.json 2>ctl.err
rc=$?
check "get --name ../../../meshes/ID: exit 1, nothing written ($(cat ctl.err))" sh -c "test $rc -eq 1 && test ! -e escaped.json"
"$CTL" get "$JID" --name "a b" -o ab.raw 2>ctl.err
rc=$?
check "get --name 'a b': the server's output_not_found ($(cat ctl.err))" sh -c "test $rc -eq 1 && grep -q output_not_found ctl.err"
"$CTL" --json get "$JID" >get.json
check "get --json: the job" jq -e --arg j "$JID" '.id == $j' get.json
check "get: a table row" sh -c "'$CTL' get '$JID' | grep -q '^$JID  voxelize'"
check "jobs: lists the job" sh -c "'$CTL' jobs | grep -q '^$JID'"
check "jobs --json --state succeeded: the job among them" sh -c "'$CTL' --json jobs --state succeeded | jq -e --arg j '$JID' '[.items[].id] | index(\$j) != null'"
check "meshes: lists the mesh" sh -c "'$CTL' meshes | grep -q '^$MID'"
# a state that is none is a bad command line (exit 2, the states named;
# it went to the server, whose 400 exited 1)
check "jobs --state bogus: exit 2, the states named" sh -c "'$CTL' jobs --state bogus 2>st.err; test \$? = 2 && grep -q 'queued, running' st.err"
# Bad command lines said as voxelctl, naming what was given (exit 2, before
# any request): getopt's messages named the binary's path; "--state and
# --newest is not an option" for --newest alone; a malformed --after went
# to the server (400, exit 1); -p camera.fov after -p camera=orbit dropped
# "orbit"; --local with a command its private server cannot answer
bad_line() { # bad_line WHAT PATTERN ARGS...: exit 2, PATTERN on stderr
    local what=$1 pat=$2
    shift 2
    "$CTL" "$@" >/dev/null 2>bl.err
    local rc=$?
    check "$what: exit 2 ($(cat bl.err))" sh -c "test $rc = 2 && grep -q -- '$pat' bl.err"
}
bad_line "a missing option value" "^voxelctl: a value is missing after .--server" jobs --server
bad_line "an unknown option" "^voxelctl: unknown option .-z" -z jobs
bad_line "a value to an option that takes none" "^voxelctl: no value is taken by .--json=1" --json=1 jobs
bad_line "a non-ASCII short option" "unknown option .(a byte that is no ASCII letter)" -é jobs
bad_line "--newest to meshes" "^voxelctl: --newest is not an option of meshes" meshes --newest
bad_line "--no-wait to jobs" "^voxelctl: --no-wait is not an option of jobs" jobs --no-wait
bad_line "--after not a job id" "--after wants a job id" jobs --after xyz
bad_line "--after a job id to meshes" "--after wants a mesh id" meshes --after 0123456789abcdef0123456789abcdef
bad_line "-p under a value that is no object" "camera was given a value that is not an object" preview "$MESH" -p camera=orbit -p camera.fov=10
bad_line "... two levels down, named whole" "camera.x was given a value" preview "$MESH" -p camera.x=1 -p camera.x.y=2
bad_line "--local jobs" "not with jobs" --local jobs
bad_line "--local --server" "not with --server" --local --server "$BASE" voxelize "$MESH"
bad_line "--local --no-wait" "not with --no-wait" --local --no-wait voxelize "$MESH"
# A reader that leaves stdout (head) is a write error said, exit 1: it was
# death by SIGPIPE (141) without a word
"$CTL" -q voxelize "$MESH" -r 128 -f raw8 -o - 2>pipe.err | head -c 10 >/dev/null
rc=${PIPESTATUS[0]}
check "-o - into a pipe closed early: exit 1, said ($rc: $(cat pipe.err))" sh -c "test $rc = 1 && grep -q 'Broken pipe' pipe.err"

# A mesh id instead of a file; the token from --token over the environment.
VOXELD_TOKEN=wrong "$CTL" --token s3cret-token --quiet preview "$MID" -p width=64 -p height=48 -o p.png 2>ctl.err
rc=$?
check "preview by mesh id: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "preview: a PNG" sh -c "head -c 8 p.png | od -An -c | grep -q 'P   N   G'"
check "--quiet: no progress lines, no 'wrote' line" sh -c "! grep -q -e '%' -e wrote ctl.err"

# Failures: the server's message, exit 1; bad usage, exit 2.
VOXELD_TOKEN=wrong "$CTL" jobs >/dev/null 2>ctl.err
check "wrong token: exit 1" test $? -eq 1
check "wrong token: the server's error" grep -q 'unauthorized.*HTTP 401' ctl.err
"$CTL" voxelize "$MESH" -r 99999 -o x.binvox 2>ctl.err
check "bad param: exit 1" test $? -eq 1
check "bad param: names it" grep -q 'params.resolution.*invalid_params' ctl.err
check "bad param: no file written" test ! -e x.binvox
"$CTL" cancel "$JID" 2>ctl.err
check "cancel a finished job: exit 1, job_finished" sh -c "test $? -eq 1 && grep -q job_finished ctl.err"
"$CTL" get "$JID" >ctl.out 2>ctl.err
check "cancel deleted nothing" test $? -eq 0
"$CTL" delete "$JID" >ctl.out 2>ctl.err
check "delete a finished job: exit 0, deleted" sh -c "test $? -eq 0 && grep -q deleted ctl.out"
"$CTL" get "$JID" 2>ctl.err
check "a deleted job: exit 1, job_not_found" sh -c "test $? -eq 1 && grep -q job_not_found ctl.err"
"$CTL" get 0123456789abcdef0123456789abcdef 2>ctl.err
check "get an unknown job: exit 1, job_not_found" sh -c "test $? -eq 1 && grep -q job_not_found ctl.err"
"$CTL" voxelize /nonexistent.obj 2>ctl.err
check "a missing file: exit 1" test $? -eq 1
"$CTL" frobnicate x 2>/dev/null
check "an unknown command: exit 2" test $? -eq 2
"$CTL" --server http://127.0.0.1:1 jobs 2>ctl.err
check "no server: exit 1 with curl's reason" sh -c "test $? -eq 1 && grep -qi 'connect' ctl.err"
# get -o / --name too: no server there is said at once (it was taken for a
# server gone while the job was followed: asked again for 2 minutes).
for opt in "-o never.raw" "--name voxels"; do
    s0=$(date +%s%N)
    # shellcheck disable=SC2086
    timeout 10 "$CTL" --server http://127.0.0.1:1 get 0123456789abcdef0123456789abcdef $opt 2>ctl.err
    rc=$?
    ms=$((($(date +%s%N) - s0) / 1000000))
    check "get $opt, no server: exit 1 at once (rc $rc, ${ms} ms) with curl's reason ($(head -c 150 ctl.err))" \
        sh -c "test $rc -eq 1 && test $ms -lt 5000 && grep -qi 'connect' ctl.err && ! grep -q 'asking again' ctl.err"
done

# Local mistakes are said at once, before anything is sent.
mkdir -p adir
s0=$(date +%s%N)
"$CTL" upload adir 2>ctl.err
rc=$?
ms=$((($(date +%s%N) - s0) / 1000000))
check "a directory to upload: exit 1 at once (${ms} ms), said so" sh -c "test $rc -eq 1 && test $ms -lt 1500 && grep -q 'adir: Is a directory' ctl.err"
for bad in abc 2x 0 1001; do
    "$CTL" jobs --limit "$bad" >/dev/null 2>ctl.err
    check "--limit $bad: a bad command line, exit 2" sh -c "test $? -eq 2 && grep -q 'limit wants' ctl.err"
done
for bad in abc 2x 0; do
    "$CTL" voxelize "$MID" -r "$bad" >/dev/null 2>ctl.err
    check "-r $bad: a bad command line, exit 2" sh -c "test $? -eq 2 && grep -q 'r wants' ctl.err"
done
"$CTL" --no-wait voxelize "$MID" -r 16 -o nw.binvox 2>ctl.err
check "--no-wait with -o: exit 2" sh -c "test $? -eq 2 && test ! -e nw.binvox"
for bad in '' ftp://127.0.0.1:1 127.0.0.1:8080; do
    "$CTL" --server "$bad" jobs >/dev/null 2>ctl.err
    check "--server '$bad': exit 2, said so" sh -c "test $? -eq 2 && grep -q 'server wants an http' ctl.err"
done
"$CTL" --token $'s3cret\nX-Injected: 1' jobs >/dev/null 2>ctl.err
check "a token with a newline: exit 2, never sent" sh -c "test $? -eq 2 && grep -q 'no header can carry' ctl.err"
njobs=$("$CTL" --json jobs --limit 1000 | jq '.items | length')
"$CTL" voxelize "$MID" -r 16 -o /nonexistent-dir/x.binvox 2>ctl.err
check "-o into a missing dir: exit 1, said before the job" sh -c "test $? -eq 1 && grep -q 'cannot write /nonexistent-dir' ctl.err"
check "-o into a missing dir: no job was submitted" test "$("$CTL" --json jobs --limit 1000 | jq '.items | length')" -eq "$njobs"
# The same through a dangling symlink (its target's dir is checked, not the
# link's), and in /proc, where access(W_OK) lets root pass (it ran the job
# and failed after it): a part file is tried.
ln -s /nonexistent-dir/x.binvox lost.binvox
"$CTL" voxelize "$MID" -r 16 -o lost.binvox 2>ctl.err
rc=$?
check "-o a link into a missing dir: exit 1, said before the job ($(cat ctl.err))" \
    sh -c "test $rc -eq 1 && grep -q 'cannot write /nonexistent-dir' ctl.err && test -L lost.binvox"
"$CTL" voxelize "$MID" -r 16 -o /proc/x.binvox 2>ctl.err
rc=$?
check "-o in /proc: exit 1, said before the job ($(cat ctl.err))" sh -c "test $rc -eq 1 && grep -q 'cannot write /proc' ctl.err"
check "-o a link into a missing dir, -o in /proc: no job was submitted" test "$("$CTL" --json jobs --limit 1000 | jq '.items | length')" -eq "$njobs"
# Uploads are named by the file's base name; a download without -o takes
# the server's name (filename*, UTF-8).
# (a comment makes new bytes: the mesh itself was stored unnamed above)
printf '# named\n' | cat - "$MESH" >"named mesh é.obj"
NMID=$("$CTL" upload "named mesh é.obj" 2>/dev/null)
check "upload: named by its file" sh -c "'$CTL' meshes --limit 1000 | grep '^$NMID' | grep -q 'named mesh é.obj'"
"$CTL" --json upload "named mesh é.obj" >up.json 2>/dev/null
check "upload --json: the server's mesh ($(head -c 120 up.json))" \
    jq -e --arg id "$NMID" '.id == $id and .name == "named mesh é.obj" and .triangles > 0 and (.bbox.max | length) == 3' up.json
# A file name the server would refuse as a mesh name (not UTF-8, a bidi
# override) uploads unnamed instead of failing.
printf '# latin-1\n' | cat - "$MESH" >"$(printf 'caf\xe9.obj')"
"$CTL" --json upload "$(printf 'caf\xe9.obj')" >up1.json 2>ctl.err
rc=$?
check "upload of a Latin-1 file name: exit 0, unnamed ($rc, $(cat ctl.err))" \
    sh -c "test $rc -eq 0 && jq -e '.id and (has(\"name\") | not)' up1.json >/dev/null"
printf '# rlo\n' | cat - "$MESH" >"$(printf 'x\xe2\x80\xaegpj.obj')"
"$CTL" --json upload "$(printf 'x\xe2\x80\xaegpj.obj')" >up2.json 2>ctl.err
rc=$?
check "upload of a file name with U+202E: exit 0, unnamed ($rc, $(cat ctl.err))" \
    sh -c "test $rc -eq 0 && jq -e '.id and (has(\"name\") | not)' up2.json >/dev/null"
mkdir -p dl && (cd dl && "$CTL" --quiet preview "$NMID" -p width=32 -p height=32 2>../ctl.err)
check "a download without -o: the server's UTF-8 name ($(ls dl))" sh -c "ls dl | grep -Eq '^named mesh é-[0-9a-f]{32}-image\.png$'"
# Paging: the rest after --after, said on stderr when there is more.
"$CTL" meshes --limit 1 >page1 2>ctl.err
AFTER=$(sed -n 's/.*--after \([0-9a-f]*\).*/\1/p' ctl.err)
check "meshes --limit 1: says there are more ($(cat ctl.err))" test -n "$AFTER"
"$CTL" meshes --limit 1 --after "$AFTER" >page2 2>/dev/null
check "meshes --after: the next page" sh -c "test -s page2 && ! cmp -s page1 page2 && test \"\$(cut -c1-64 page2)\" \\> \"$AFTER\""

# --no-wait prints the id; cancel takes it (a job that takes seconds:
# peel with three-axis voting; a plain 512^3 job had finished first).
NJ=$("$CTL" --no-wait voxelize "$MID" -r 1024 -p method=peel -p inside=robust 2>/dev/null)
check "--no-wait: a job id ($NJ)" grep -Eq '^[0-9a-f]{32}$' <<<"$NJ"
"$CTL" cancel "$NJ" >cancel.out 2>&1
rc=$?
check "cancel: exit 0 ($(cat cancel.out))" test $rc -eq 0

# Results land whole where they are asked for: parallel runs without -o
# each through a part file of their own (they shared one: files swapped);
# -o through a symlink replaces its target (the link and the mode stay);
# -o on a FIFO (as a device) is written in place, not replaced by a file.
TOKEN=s3cret-token
mkdir -p par && (cd par && for r in 20 24 28 32; do "$CTL" -q voxelize "$MID" -r $r -f raw8 2>>../ctl.err & done && wait)
check "parallel runs: 4 results" test "$(ls par | grep -c 'voxels\.raw$')" -eq 4
bad=0
for f in par/*voxels.raw; do
    j=$(grep -Eo '[0-9a-f]{32}' <<<"$(basename "$f")")
    api GET "/v1/jobs/$j/result"
    cmp -s "$BODY" "$f" || bad=1
done
check "parallel runs: each file holds its own job's result" test $bad -eq 0
check "parallel runs: no part file left" test -z "$(ls -A par | grep part)"
echo old >target.binvox
chmod 640 target.binvox
ln -sf target.binvox link.binvox
"$CTL" -q voxelize "$MID" -r 16 -f binvox -o link.binvox 2>ctl.err
check "-o a symlink: the link stays" test -L link.binvox
check "-o a symlink: its target holds the result" test "$(head -n 1 target.binvox)" = "#binvox 1"
check "-o a symlink: the target's mode kept ($(stat -c %a target.binvox))" test "$(stat -c %a target.binvox)" = 640
# A dangling symlink: its target is made (the link was replaced by a file),
# also at the end of a chain of relative links.
ln -s made.binvox dangling.binvox
"$CTL" -q voxelize "$MID" -r 16 -f binvox -o dangling.binvox 2>ctl.err
check "-o a dangling symlink: the link stays ($(cat ctl.err))" test -L dangling.binvox
check "-o a dangling symlink: its target made" test "$(head -n 1 made.binvox)" = "#binvox 1"
mkdir -p chain
ln -s chain/hop.binvox chain1.binvox
ln -s ../chained.binvox chain/hop.binvox
"$CTL" -q voxelize "$MID" -r 16 -f binvox -o chain1.binvox 2>ctl.err
check "-o two relative dangling links: both stay ($(cat ctl.err))" sh -c "test -L chain1.binvox && test -L chain/hop.binvox"
check "-o two relative dangling links: the last target made" test "$(head -n 1 chained.binvox)" = "#binvox 1"
mkfifo fifo.out
cat fifo.out >fifo.copy &
catpid=$!
"$CTL" -q voxelize "$MID" -r 16 -f binvox -o fifo.out 2>ctl.err
rc=$?
check "-o a FIFO: exit 0 ($(cat ctl.err))" test $rc -eq 0
wait "$catpid"
check "-o a FIFO: still a FIFO" test -p fifo.out
check "-o a FIFO: the result went through it" cmp -s fifo.copy target.binvox
# A summary: the stats, on stdout or into -o.
"$CTL" -q voxelize "$MID" -r 16 -f summary >sum.json 2>ctl.err
check "summary: the stats on stdout" jq -e '.voxels_inside > 0 and .dims[0] > 0' sum.json
"$CTL" -q voxelize "$MID" -r 16 -f summary -o sum2.json 2>ctl.err
check "summary -o: the stats in the file" jq -e '.voxels_inside > 0' sum2.json
# --newest: the job just submitted comes first.
"$CTL" -q voxelize "$MID" -r 12 -f summary --json >last.json 2>/dev/null
check "jobs --newest: the latest job first" test "$("$CTL" jobs --newest --limit 1 | cut -c1-32)" = "$(jq -r .id last.json)"
# The next page as stderr names it keeps this page's order and filters (it
# said --after alone: that dropped --newest and --state).
for f in "--newest" "--newest --state succeeded" "--state succeeded"; do
    # shellcheck disable=SC2086
    "$CTL" jobs $f --limit 2 >pg1 2>ctl.err
    NEXT=$(sed -n 's/^voxelctl: more after these 2: \(.*--after [0-9a-f]*\) .*/\1/p' ctl.err)
    # shellcheck disable=SC2086
    "$CTL" jobs $NEXT >pg2 2>/dev/null
    # shellcheck disable=SC2086
    "$CTL" jobs $f --limit 4 >pg4 2>/dev/null
    check "jobs $f --limit 2: the next page as said ($NEXT) follows it" \
        sh -c "test -n '$NEXT' && test \$(wc -l <pg2) -eq 2 && cat pg1 pg2 | cmp -s - pg4"
done
# Usage errors say what is wrong and exit 2 before anything is sent.
for bad in "voxelize $MID -p azimuth=1e400" "voxelize $MID -r 8 -p resolution=16" \
    "render $MID --name normal" "jobs --name x" "get ../meshes/$MID" "--json get x -o -" \
    "voxelize" "frobnicate" "gregory $MID -r 8" "render $MID -f png" "preview $MID -f png" \
    "get notanid" "cancel 0123456789ABCDEF0123456789abcdef" "delete 0123456789abcdef"; do
    # shellcheck disable=SC2086
    "$CTL" $bad >/dev/null 2>ctl.err
    rc=$?
    check "usage error exits 2: $bad ($(head -c 100 ctl.err))" test $rc -eq 2
done
check "a kind without -r: said" sh -c "'$CTL' gregory '$MID' -r 8 2>&1 | grep -q -- '-r is not an option of gregory'"
# A mesh from standard input or a FIFO (read whole first: an upload needs
# its length).
"$CTL" -q upload - <"$MESH" >stdin.id 2>ctl.err
rc=$?
check "upload -: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "upload -: the same mesh as the file" test "$(cat stdin.id)" = "$MID"
mkfifo mesh.fifo
cat "$MESH" >mesh.fifo &
mkdir -p "$TMP/fifo-spool" # (its own spool dir: /tmp may hold another run's)
TMPDIR=$TMP/fifo-spool "$CTL" -q voxelize mesh.fifo -r 8 -f summary >fifo.json 2>ctl.err
rc=$?
check "voxelize a FIFO: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "voxelize a FIFO: the stats" jq -e '.voxels_inside > 0' fifo.json
check "no spooled file left" test -z "$(ls "$TMP/fifo-spool"/voxelctl-upload-* 2>/dev/null)"
# A turntable: every frame downloaded, its number put into -o's name.
TURN=(-r 16 -p camera.type=orbit -p width=32 -p height=24)
"$CTL" -q render "$MID" "${TURN[@]}" -p frames=3 -o spin.png 2>ctl.err
rc=$?
check "turntable: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "turntable: three PNG frames" test "$(for f in spin_000.png spin_001.png spin_002.png; do "$VX_TOOLS/pngstat" "$f"; done | jq -s 'map(select(.width == 32 and .height == 24)) | length')" = 3
check "turntable: no file under the plain name" test ! -e spin.png
check "turntable: the frames differ" sh -c 'test -s spin_001.png && ! cmp -s spin_000.png spin_001.png'
"$CTL" -q render "$MID" "${TURN[@]}" -p frames=3 -o - >spin.all 2>ctl.err
check "turntable -o -: the frames in turn on stdout" sh -c 'cat spin_000.png spin_001.png spin_002.png | cmp -s - spin.all'
# get -o on a job not yet finished waits for it as the job commands do
# (it got 409 job_not_finished), then fetches every frame of a turntable
# (it got the first only). A slow render ahead keeps it unfinished.
SLOW='"params":{"N":64,"R":512,"width":512,"height":512}'
api POST /v1/jobs -H 'Content-Type: application/json' -d "{\"mesh\":\"$MID\",\"kind\":\"render\",$SLOW}"
"$CTL" --no-wait render "$MID" "${TURN[@]}" -p frames=3 >turn.id 2>ctl.err
TJID=$(cat turn.id)
api GET "/v1/jobs/$TJID"
TSTATE=$(jq -r .state "$BODY")
"$CTL" get "$TJID" -o getspin.png 2>ctl.err
rc=$?
check "get -o on a $TSTATE job: waits for it, exit 0 ($(tail -n 1 ctl.err))" \
    sh -c "test $rc -eq 0 && test '$TSTATE' != succeeded && grep -Eq '^$TJID succeeded 100%$' ctl.err"
check "get -o on a turntable: every frame, numbered as render -o numbers them" \
    sh -c 'for i in 0 1 2; do cmp -s spin_00$i.png getspin_00$i.png || exit 1; done; test ! -e getspin.png'
"$CTL" -q get "$TJID" -o again.png 2>ctl.err
check "get -o on a finished turntable: every frame too" \
    sh -c 'for i in 0 1 2; do cmp -s spin_00$i.png again_00$i.png || exit 1; done; test ! -e again.png'
"$CTL" -q get "$TJID" --name image_002 -o frame2.png 2>ctl.err
check "get --name one frame: that frame only" cmp -s spin_002.png frame2.png
# A job canceled while get waits for it (seconds of work: cancel comes
# first): said, exit 1, nothing written.
api POST /v1/jobs -H 'Content-Type: application/json' -d "{\"mesh\":\"$MID\",\"kind\":\"render\",$SLOW}"
CJID=$(jq -r .id "$BODY")
"$CTL" get "$CJID" -o never.png 2>cget.err &
gpid=$!
for _ in $(seq 100); do grep -Eq "^$CJID (queued|running)" cget.err && break; sleep 0.05; done
"$CTL" cancel "$CJID" >/dev/null 2>&1
wait "$gpid"
rc=$?
check "get -o, the job canceled meanwhile: exit 1, said, nothing written ($(cat cget.err))" \
    sh -c "test $rc -eq 1 && grep -q 'job $CJID canceled' cget.err && test ! -e never.png"
"$CTL" -q voxelize "$MID" -r 8 -f binvox -o - >/dev/full 2>ctl.err
rc=$?
check "stdout that cannot be written: exit 1 ($(cat ctl.err))" test $rc -eq 1
"$CTL" jobs >/dev/full 2>ctl.err
check "jobs into a full stdout: exit 1" test $? -eq 1

# -o "" (an unset variable) is a bad command line, not the server's name
# in the current directory.
mkdir -p emptyo && (cd emptyo && "$CTL" -q voxelize "$MID" -r 8 -f binvox -o "" 2>../ctl.err)
rc=$?
check "-o '': exit 2 before the job ($(cat ctl.err))" sh -c "test $rc -eq 2 && test -z \"\$(ls -A emptyo)\" && grep -q 'o wants a file name' ctl.err"
# --json with a summary and -o: the stats still go into -o (they were
# dropped), the job on stdout.
"$CTL" -q --json voxelize "$MID" -r 8 -f summary -o jsum.json >jsum.job 2>ctl.err
check "--json summary -o: the stats in the file ($(cat ctl.err))" jq -e '.voxels_inside > 0' jsum.json
check "--json summary -o: the job on stdout" jq -e '.state == "succeeded"' jsum.job
# A result that cannot be written (a full disk): the file and the reason,
# not curl's "failed writing received data" after the server's URL.
"$CTL" -q voxelize "$MID" -r 64 -f raw8 -o /dev/full 2>ctl.err
rc=$?
check "-o a full device: exit 1, names it and ENOSPC ($(cat ctl.err))" \
    sh -c "test $rc -eq 1 && grep -q 'writing /dev/full: No space left on device' ctl.err && ! grep -q 'Failed writing' ctl.err"
# Interrupted while standard input is read: the spooled copy is removed.
mkdir -p "$TMP/spool"
mkfifo slow.fifo
(exec 3>slow.fifo; head -c 1000 "$MESH" >&3; sleep 20) &
feeder=$!
TMPDIR=$TMP/spool "$CTL" -q upload - <slow.fifo >/dev/null 2>&1 &
upid=$!
for _ in $(seq 100); do [[ -n "$(ls -A "$TMP/spool")" ]] && break; sleep 0.05; done
check "upload -: spooled while stdin is read" test -n "$(ls -A "$TMP/spool")"
kill -TERM "$upid"
wait "$upid"
rc=$?
kill "$feeder" 2>/dev/null
wait "$feeder" 2>/dev/null
check "upload -, SIGTERM while reading: ended by it (rc $rc), the spool removed" \
    sh -c "test $rc -eq 143 && test -z \"\$(ls -A '$TMP/spool')\""

# One-shot, no server: --local and voxeld run give the server's bytes.
"$CTL" voxelize "$MESH" -r 64 -f binvox -o local.binvox >/dev/null 2>&1 # via the daemon
unset VOXELD_URL VOXELD_TOKEN
mkdir -p "$TMP/ltmp"
export TMPDIR=$TMP/ltmp # where --local makes its data dir
"$CTL" --local --quiet voxelize "$MESH" -r 64 -f binvox -o local2.binvox 2>ctl.err
rc=$?
check "--local: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "--local: the same grid as the daemon's" cmp -s local.binvox local2.binvox
"$VOXELD" run voxelize "$MESH" -r 64 -f binvox -o run.binvox --quiet 2>ctl.err
rc=$?
check "voxeld run: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "voxeld run: the same grid" cmp -s local.binvox run.binvox
"$CTL" --local voxelize "$MESH" -r 99999 2>ctl.err
check "--local: a bad param still exits 1 with the message" sh -c "test $? -eq 1 && grep -q invalid_params ctl.err"
# The private voxeld takes nothing of a service it runs beside: its token
# file (its own client got 401), its blob store (the job's mesh stayed in
# the shared store), its systemd socket (READY=1, STOPPING=1 of another)
printf 'secret\n' >"$TMP/svc-token"
mkdir -p "$TMP/svc-store"
python3 "$VX_SOURCE_DIR/tests/integration/notify_listen.py" "$TMP/svc-notify" "$TMP/svc-notify.log" &
npid=$!
for _ in $(seq 50); do [[ -S "$TMP/svc-notify" ]] && break; sleep 0.1; done
rc=0
VOXELD_TOKEN_FILE=$TMP/svc-token VOXELD_BLOB_STORE=file://$TMP/svc-store NOTIFY_SOCKET=$TMP/svc-notify \
    "$VOXELD" run voxelize "$MESH" -r 16 -f summary -o svc.json --quiet 2>ctl.err || rc=$?
sleep 0.3
kill "$npid"
check "voxeld run beside a service's environment: exit 0 ($(cat ctl.err))" test $rc -eq 0
check "... nothing in the service's store ($(find "$TMP/svc-store" -type f | head -n 3 | tr '\n' ' '))" \
    test -z "$(find "$TMP/svc-store" -type f)"
check "... nothing told to its systemd socket ($(tr '\n' ' ' <"$TMP/svc-notify.log" 2>/dev/null))" \
    test ! -s "$TMP/svc-notify.log"
# ... while a tuning setting applies to it
rc=0
VOXELD_MAX_JOB_MEMORY=1K "$VOXELD" run voxelize "$MESH" -r 16 -f summary -o svc2.json --quiet 2>ctl.err || rc=$?
check "... VOXELD_MAX_JOB_MEMORY applies (rc $rc: $(tail -n 1 ctl.err))" sh -c "test $rc = 1 && grep -q job_memory_limit ctl.err"
check "--local: its temporary data dirs are removed" test -z "$(ls -A "$TMP/ltmp")"
# Interrupted mid-job (Ctrl-C, kill): the private voxeld and its data dir go
# too, and the signal still ends the command. SIGINT is given back its
# default first (a script's background job starts with it ignored).
for sig in INT TERM; do
    python3 -c 'import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
os.execvp(sys.argv[1], sys.argv[1:])' "$CTL" --local --quiet render "$VX_MESH_DIR/spot_triangulated.obj" \
        -p N=64 -p R=1024 -p width=128 -p height=128 -o int.png 2>int.err &
    ipid=$!
    for _ in $(seq 100); do [[ -n "$(ls -A "$TMP/ltmp")" ]] && break; sleep 0.1; done
    sleep 1
    kill -"$sig" "$ipid"
    wait "$ipid"
    rc=$?
    check "--local, SIG$sig mid-job: ended by the signal (rc $rc)" test "$rc" -eq $((128 + $(kill -l "$sig")))
    check "--local, SIG$sig mid-job: no result written" test ! -e int.png
    check "--local, SIG$sig mid-job: says the private voxeld and its job stopped ($(tr '\n' ' ' <int.err))" \
        sh -c "grep -q 'interrupted; the private voxeld (--local) and its job are stopped' int.err && ! grep -q 'no answer' int.err"
    check "--local, SIG$sig mid-job: the data dir is removed" test -z "$(ls -A "$TMP/ltmp")"
    check "--local, SIG$sig mid-job: its voxeld is gone" sh -c "! pgrep -f '$TMP/ltm[p]' >/dev/null"
done
# The same while standard input is read: the spooled copy goes too.
(exec 3>slow.fifo; head -c 1000 "$MESH" >&3; sleep 20) &
feeder=$!
"$CTL" -q --local upload - <slow.fifo >/dev/null 2>&1 &
upid=$!
for _ in $(seq 100); do ls "$TMP"/ltmp/voxelctl-upload-* >/dev/null 2>&1 && break; sleep 0.1; done
check "--local upload -: spooled while stdin is read" sh -c "ls '$TMP'/ltmp/voxelctl-upload-*"
kill -TERM "$upid"
wait "$upid"
rc=$?
kill "$feeder" 2>/dev/null
wait "$feeder" 2>/dev/null
check "--local upload -, SIGTERM while reading: ended by it (rc $rc), spool and data dir removed" \
    sh -c "test $rc -eq 143 && test -z \"\$(ls -A '$TMP/ltmp')\""

# A full queue (429, Retry-After) is waited out: the job is submitted once
# there is room, not failed at once. (No event streams or ?wait holds on
# this daemon: see below.)
export VOXELD_URL VOXELD_TOKEN=s3cret-token
stop_daemon
start_daemon --token-file "$TMP/token" --workers 1 --max-queued-jobs 1 --max-waits 0 \
    --max-event-streams 0 || exit 1
VOXELD_URL=$BASE
# renders of a closed mesh: their GL stage (nonzero at R 1024) holds the GL
# thread, so the queued one stays queued (suzanne is open: sampled by
# winding on the CPU, its GL stage ended at once and the queue emptied)
upload "$VX_SOURCE_DIR/examples/meshes/torus.obj"
HID=$MESH_ID
HEAVY='"params":{"N":64,"R":1024,"width":768,"height":768}'
for _ in $(seq 20); do
    api POST /v1/jobs -H 'Content-Type: application/json' -d "{\"mesh\":\"$HID\",\"kind\":\"render\",$HEAVY}"
    [[ "$STATUS" == 429 ]] && break
done
check "the queue fills (got $STATUS)" test "$STATUS" = 429
"$CTL" --no-wait voxelize "$MID" -r 8 -f summary >retry.id 2>retry.err &
rpid=$!
for _ in $(seq 100); do grep -q 'trying again' retry.err && break; sleep 0.1; done
check "429: says it tries again ($(cat retry.err))" grep -q 'queue_full, HTTP 429.*trying again' retry.err
api GET '/v1/jobs?limit=1000'
for j in $(jq -r '.items[] | select(.state == "queued" or .state == "running") | .id' "$BODY"); do
    api DELETE "/v1/jobs/$j"
done
wait "$rpid"
rc=$?
check "429: submitted once there was room, exit 0 (rc $rc)" sh -c "test $rc -eq 0 && grep -Eq '^[0-9a-f]{32}$' retry.id"

# With no stream and no ?wait hold to spare (503 too_many_streams, then 503
# too_many_waits), a job is followed by plain GETs to its end: not taken
# for a server that stopped answering (given up after 2 minutes).
"$CTL" voxelize "$MID" -r 8 -f summary -o full.json 2>full.err
rc=$?
check "waits full: followed to its end, exit 0 ($rc, $(tr '\n' ' ' <full.err))" \
    sh -c "test $rc -eq 0 && jq -e .voxels_inside full.json >/dev/null && ! grep -q 'no answer' full.err"

# A server that answers 503 (shutting down) and is then gone for a moment
# (restarting): the upload is sent again once it is back (a stand-in).
python3 "$VX_SOURCE_DIR/tests/integration/standin.py" "$TMP/standin.port" upload 3 >standin.log 2>&1 &
spid=$!
for _ in $(seq 100); do [[ -s "$TMP/standin.port" ]] && break; sleep 0.05; done
"$CTL" --server "http://127.0.0.1:$(cat "$TMP/standin.port")" upload "$MESH" >standin.id 2>ctl.err
rc=$?
wait "$spid"
check "503, then no server, then back: the upload is sent again, exit 0 ($rc, $(cat ctl.err))" \
    sh -c "test $rc -eq 0 && test \"\$(cat standin.id)\" = $(printf 'ab%.0s' $(seq 32)) && grep -q 'shutting_down, HTTP 503' ctl.err && ! grep -q 'connect' ctl.err"

# A server that answered while get followed the job, then was gone for a
# moment (restarting), is asked again until it is back (a stand-in).
python3 "$VX_SOURCE_DIR/tests/integration/standin.py" "$TMP/standin2.port" job 1 >standin2.log 2>&1 &
spid=$!
for _ in $(seq 100); do [[ -s "$TMP/standin2.port" ]] && break; sleep 0.05; done
timeout 20 "$CTL" --server "http://127.0.0.1:$(cat "$TMP/standin2.port")" get 0123456789abcdef0123456789abcdef -o gone.json 2>ctl.err
rc=$?
wait "$spid"
check "get -o, the server gone after it answered: asked again, exit 0 ($rc, $(tr '\n' ' ' <ctl.err))" \
    sh -c "test $rc -eq 0 && grep -q 'asking again' ctl.err && jq -e '.voxels_inside == 7' gone.json"

stop_daemon

# A server that answers one thing wrong (hostile_server.py): its job id is
# a path ("../../x": voxelctl went on to GET /x/result and saved it), it
# names the result ".profile" (saved over the user's dot file), it sends
# the result gzipped unasked (saved as the result), its progress is 1e20
# (the bar wrote 2 GB of spaces to the terminal).
# hostile MODE: the stand-in started in $TMP/h-MODE, its port in HPORT
hostile() {
    mkdir -p "$TMP/h-$1"
    rm -f "$TMP/h-$1/port" "$TMP/h-$1/log"
    python3 "$VX_SOURCE_DIR/tests/integration/hostile_server.py" "$TMP/h-$1/port" "$TMP/h-$1/log" "$1" &
    HPID=$!
    for _ in $(seq 100); do [[ -s "$TMP/h-$1/port" ]] && break; sleep 0.05; done
    HPORT=$(cat "$TMP/h-$1/port")
}
# voxelize_at MODE [ARGS]: voxelctl voxelize of the torus (and ARGS) against
# the stand-in in MODE, in $TMP/h-MODE: its exit status in rc, out.txt, err.txt
voxelize_at() {
    local m=$1
    shift
    hostile "$m"
    (cd "$TMP/h-$m" && "$CTL" --server "http://127.0.0.1:$HPORT" voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" "$@" >out.txt 2>err.txt; echo $? >rc)
    kill "$HPID"
}
voxelize_at badid
check "a job id that is a path: exit 1, said ($(cat "$TMP/h-badid/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-badid/rc') = 1 && grep -q 'no job id' '$TMP/h-badid/err.txt'"
check "... and no request went to it" bash -c "! grep -q ' /x' '$TMP/h-badid/log'"
voxelize_at dotname
check "a result named .profile: written under another name, no dot file ($(ls -A "$TMP/h-dotname" | tr '\n' ' '))" \
    bash -c "test \$(cat '$TMP/h-dotname/rc') = 0 && ! test -e '$TMP/h-dotname/.profile' && grep -q '^wrote ' '$TMP/h-dotname/err.txt'"
voxelize_at gzip -o out.bin
check "a gzipped result not asked for: exit 1, said, nothing written ($(cat "$TMP/h-gzip/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-gzip/rc') = 1 && grep -q 'Content-Encoding gzip' '$TMP/h-gzip/err.txt' && ! test -e '$TMP/h-gzip/out.bin'"
hostile progress
(cd "$TMP/h-progress" && script -qc "'$CTL' --server http://127.0.0.1:$HPORT voxelize '$VX_SOURCE_DIR/examples/meshes/torus.obj' -o out.bin" /dev/null >tty.txt 2>&1)
kill "$HPID"
check "progress 1e20 on a terminal: one bar's worth ($(wc -c <"$TMP/h-progress/tty.txt") bytes)" \
    bash -c "test \$(wc -c <'$TMP/h-progress/tty.txt') -lt 2000 && grep -q '100%' '$TMP/h-progress/tty.txt'"
# ... an upload's 201 that is an HTML page said so (it was "upload: HTTP
# 201" alone), an error message's terminal escapes shown as '?'
voxelize_at html -o out.bin
voxelize_at esc -o out.bin
check "an HTML 201 to an upload: exit 1, the answer shown ($(cat "$TMP/h-html/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-html/rc') = 1 && grep -q 'not the JSON expected: <html>' '$TMP/h-html/err.txt'"
# Ctrl-C while the result of a job that has ended downloads: said so (it
# said the job "goes on", with how to cancel it)
hostile slow
(cd "$TMP/h-slow" && { "$CTL" --server "http://127.0.0.1:$HPORT" voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" -o out.bin >out.txt 2>err.txt & CP=$!; sleep 2; kill -INT $CP; wait $CP; echo $? >rc; })
kill "$HPID"
check "Ctrl-C during the download: 130, the job said ended, no file ($(tail -n 1 "$TMP/h-slow/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-slow/rc') = 130 && grep -q 'download interrupted; job .* has ended' '$TMP/h-slow/err.txt' && ! test -e '$TMP/h-slow/out.bin'"
check "escapes in an error: exit 1, none reaches the terminal ($(cat -v "$TMP/h-esc/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-esc/rc') = 1 && grep -q 'bad?' '$TMP/h-esc/err.txt' && ! grep -q \$'\\x1b' '$TMP/h-esc/err.txt'"
# ... nor through the lists, a job shown, or a failed job's error (they
# printed the server's fields as they came)
hostile esc
H="http://127.0.0.1:$HPORT"
(cd "$TMP/h-esc" && { "$CTL" --server "$H" jobs; "$CTL" --server "$H" meshes; "$CTL" --server "$H" get cdcdcdcdcdcdcdcdcdcdcdcdcdcdcdcd; } >lists.txt 2>&1)
kill "$HPID"
check "escapes in the lists and a job: shown as '?' ($(cat -v "$TMP/h-esc/lists.txt" | tr '\n' ' '))" \
    bash -c "grep -q '^cdcd.*voxelize?' '$TMP/h-esc/lists.txt' && grep -q 'triangles  a?' '$TMP/h-esc/lists.txt' && ! grep -q \$'\\x1b' '$TMP/h-esc/lists.txt' && ! grep -q \$'\\xc2\\x9b' '$TMP/h-esc/lists.txt'"
# A failed job whose error is null ("failed:  ()" before); lists and a job
# that are not (blank rows, exit 0 before)
voxelize_at nullerr -o out.bin
check "a failed job without an error: exit 1, said ($(cat "$TMP/h-nullerr/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-nullerr/rc') = 1 && grep -q 'failed (the server gave no error)' '$TMP/h-nullerr/err.txt'"
hostile shape
H="http://127.0.0.1:$HPORT"
for c in jobs meshes "get cdcdcdcdcdcdcdcdcdcdcdcdcdcdcdcd"; do
    rc=0
    (cd "$TMP/h-shape" && "$CTL" --server "$H" $c >out.txt 2>err.txt) || rc=$?
    check "$c answered with what is not one: exit 1, said ($(cat "$TMP/h-shape/err.txt"))" \
        bash -c "test $rc = 1 && grep -q 'not the JSON expected' '$TMP/h-shape/err.txt' && ! grep -q '[^[:space:]]' '$TMP/h-shape/out.txt'"
done
kill "$HPID"
# A server that answers ?wait at once (--request-timeout 0) and has no
# event stream is asked once a second (thousands of times a second before)
voxelize_at atonce -o out.bin
check "?wait answered at once: polled once a second ($(grep -c '^GET /v1/jobs/[0-9a-f]*?wait' "$TMP/h-atonce/log") polls in 3 s), the result written" \
    bash -c "test \$(cat '$TMP/h-atonce/rc') = 0 && test -s '$TMP/h-atonce/out.bin' && test \$(grep -c '^GET /v1/jobs/[0-9a-f]*?wait' '$TMP/h-atonce/log') -le 6"
# A submission whose answer was lost (the connection closed after the
# server took it) is sent again under the same Idempotency-Key, which
# answers the job it made (it failed, "Empty reply from server", and a
# retry without a key would have queued a second job)
voxelize_at cutbody -o out.bin
check "a submit answer cut in its body: sent again with its key, the first job followed ($(tr '\n' ' ' <"$TMP/h-cutbody/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-cutbody/rc') = 0 && test -s '$TMP/h-cutbody/out.bin' && test \$(grep -c '^POST /v1/jobs' '$TMP/h-cutbody/log') = 2 && ! grep -q efef '$TMP/h-cutbody/log'"
voxelize_at cut -o out.bin
check "a lost submit answer: sent again with its key, the first job followed, exit 0 ($(tr '\n' ' ' <"$TMP/h-cut/err.txt"))" \
    bash -c "test \$(cat '$TMP/h-cut/rc') = 0 && test -s '$TMP/h-cut/out.bin' && grep -q 'answer was lost' '$TMP/h-cut/err.txt' && grep -q '^GET /v1/jobs/cdcd' '$TMP/h-cut/log' && ! grep -q efef '$TMP/h-cut/log'"
check "... both submissions with one key of 32 hex digits ($(grep 'POST /v1/jobs' "$TMP/h-cut/log" | tr '\n' ' '))" \
    bash -c "test \$(grep '^POST /v1/jobs' '$TMP/h-cut/log' | awk '{print \$NF}' | grep -cE '^[0-9a-f]{32}\$') = 2 && test \$(grep '^POST /v1/jobs' '$TMP/h-cut/log' | awk '{print \$NF}' | sort -u | wc -l) = 1"
# Without -o, a current directory the result cannot be written in is said
# before the upload (it was found after the job ran); a summary writes no
# file there, so it goes on
hostile badid
H="http://127.0.0.1:$HPORT"
rc=0
(cd /proc && "$CTL" --server "$H" voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" >"$TMP/h-badid/cwd.out" 2>"$TMP/h-badid/cwd.err") || rc=$?
check "an unwritable current directory: exit 1, said, nothing sent ($(cat "$TMP/h-badid/cwd.err"))" \
    bash -c "test $rc = 1 && grep -q 'cannot write the result in the current directory' '$TMP/h-badid/cwd.err' && ! grep -q POST '$TMP/h-badid/log'"
(cd /proc && "$CTL" --server "$H" voxelize "$VX_SOURCE_DIR/examples/meshes/torus.obj" -f summary >/dev/null 2>"$TMP/h-badid/sum.err")
kill "$HPID"
check "... a summary there is submitted ($(cat "$TMP/h-badid/sum.err"))" \
    bash -c "test \$(grep -c 'POST /v1/jobs' '$TMP/h-badid/log') = 1"
finish
