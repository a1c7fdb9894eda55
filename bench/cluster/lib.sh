# Sourced by bench/cluster/*.sh (after setting root, build and work): a
# throw-away PostgreSQL (tests/support/pg.sh, durable commits) as $url, and
#   start N MODE [flags...]   N cluster replicas on it sharing a file://
#                             store (MODE cluster), or one local daemon
#                             (MODE local); bases[] = their URLs, pids[];
#                             logs $work/MODE N-I.log
#   stop                      SIGTERM to all, and waits
source "$root/bench/lib.sh"
pgdir=$(mktemp -d /tmp/vxpg.XXXXXX)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
    "$root/tests/support/pg.sh" stop "$pgdir" >/dev/null 2>&1 || true
    rm -rf "$work" "$pgdir"
}
trap cleanup EXIT
url=$("$root/tests/support/pg.sh" start "$pgdir")

start() {
    local n=$1 mode=$2 i
    shift 2
    bases=()
    for i in $(seq 1 "$n"); do
        local flags=()
        if [[ $mode == cluster ]]; then
            flags=(--database "$url" --blob-store "file://$work/shared" --replica-name "r$i")
        fi
        bench_voxeld "$work/$mode$n-$i.log" --data-dir "$work/$mode$n-data$i" --workers 2 \
            "${flags[@]}" "$@"
        pids+=("$vpid")
        bases+=("$base")
    done
}
stop() {
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
    for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
    pids=()
}
