# Sourced by the cluster-mode tests after lib.sh: a PostgreSQL of their own
# (tests/support/pg.sh; skip, exit 77, without one) and voxeld replicas on
# it, each on a free port with its own data dir.
#   URL                          the database's URL (stopped at exit)
#   REPLICA_FLAGS=(...)          flags every replica gets (its store, lease...)
#   start_replica I              replica rI: RPID[I], RBASE[I], RDATA[I], log $TMP/rI.log
#   on I                         later api calls go to rI
#   submit I KIND MESH PARAMS [curl args]   JOB = the new job's id
#   wait_final I JID SECONDS     polls rI until the job has finished
# A test with more to stop at exit sets CLUSTER_STOP to a function.
PGSH="$VX_SOURCE_DIR/tests/support/pg.sh"
if ! bash "$PGSH" url /nonexistent >/dev/null 2>&1 || [[ ! -x /usr/lib/postgresql/15/bin/initdb ]]; then
    echo "skip: no PostgreSQL server (apt-get install postgresql-15)"
    exit 77
fi
# PostgreSQL's dir outside $TMP (mode 700, root's): the server runs as nobody.
PGDIR=$(mktemp -d /tmp/vxpg.XXXXXX)
declare -a RPID RBASE RDATA
REPLICA_FLAGS=()
CLUSTER_STOP=
stop_all() {
    local i
    for i in "${!RPID[@]}"; do
        [[ -n "${RPID[$i]:-}" ]] && kill -KILL "${RPID[$i]}" 2>/dev/null
    done
    [[ -n "$CLUSTER_STOP" ]] && "$CLUSTER_STOP"
    bash "$PGSH" stop "$PGDIR" >/dev/null 2>&1
    rm -rf "$PGDIR"
}
trap 'stop_all; cleanup' EXIT
# no fsync: a commit stalled by a loaded disk could hold a lease renewal
# past the tests' 3 s leases (PostgreSQL is stopped cleanly, never crashed)
export VX_PG_OPTS="${VX_PG_OPTS:--c fsync=off -c synchronous_commit=off}"
URL=$(bash "$PGSH" start "$PGDIR") || { echo "cannot start PostgreSQL"; exit 1; }

start_replica() {
    local i=$1 log=$TMP/r$1.log
    RDATA[$i]=$TMP/data$i
    touch "$log"
    local from
    from=$(($(wc -l <"$log") + 1))
    "$VOXELD" --listen 127.0.0.1:0 --data-dir "${RDATA[$i]}" --workers 2 --http-threads 4 \
        --database "$URL" --replica-name "r$i" "${REPLICA_FLAGS[@]}" 2>>"$log" &
    RPID[$i]=$!
    local t port
    for t in $(seq 1 600); do
        port=$(tail -n +"$from" "$log" | grep -a 'event=voxeld.ready' | sed -n 's/.*port=\([0-9]*\).*/\1/p')
        if [[ -n "$port" ]]; then
            RBASE[$i]="http://127.0.0.1:$port"
            return 0
        fi
        if ! kill -0 "${RPID[$i]}" 2>/dev/null; then
            echo "replica r$i exited during start:"; tail -n 20 "$log"; RPID[$i]=; return 1
        fi
        sleep 0.1
    done
    echo "replica r$i did not become ready"; return 1
}
on() { BASE=${RBASE[$1]}; }
submit() {
    on "$1"
    api POST /v1/jobs -H "Content-Type: application/json" "${@:5}" \
        -d "{\"mesh\":\"$3\",\"kind\":\"$2\",\"params\":$4}"
    JOB=$(jqb '.id // empty')
}
wait_final() {
    on "$1"
    local t=0
    while ((t < $3)); do
        api GET "/v1/jobs/$2?wait=5"
        case "$(jqb .state)" in succeeded | failed | canceled) return 0 ;; esac
        t=$((t + 5))
    done
    return 1
}
