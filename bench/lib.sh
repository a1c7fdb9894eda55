# Sourced by the bench scripts: bench_voxeld LOG ARG... starts "$build/voxeld"
# on a free port with the given flags, its stderr into LOG, and waits for
# its ready line; sets vpid, port and base (http://127.0.0.1:PORT), or
# exits 1 with the log's tail when it does not come up within 30 s.
bench_voxeld() {
    local log=$1
    shift
    : >"$log" # there before the first read below
    "$build/voxeld" --listen 127.0.0.1:0 "$@" 2>>"$log" &
    vpid=$!
    port=
    for _ in $(seq 300); do
        port=$(sed -n 's/.*event=voxeld.ready port=\([0-9]*\).*/\1/p' "$log")
        [[ -n "$port" ]] && break
        sleep 0.1
    done
    if [[ -z "$port" ]]; then
        echo "voxeld did not start:" >&2
        tail -n 20 "$log" >&2
        exit 1
    fi
    base=http://127.0.0.1:$port
}
