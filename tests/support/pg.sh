#!/usr/bin/env bash
# A throw-away PostgreSQL server for tests and benches: Debian's initdb and
# pg_ctl (postgresql-15) in a temp dir, listening on a unix socket only (no
# port to collide on), as an unprivileged user when run as root (nobody:
# PostgreSQL refuses to run as root).
#
#   pg.sh run CMD ARGS...   start one, run CMD with VX_PG_URL (postgresql://
#                           URL), VX_PG_DIR and VX_PG_SH set, then stop it and
#                           remove the dir whatever happens; exits with CMD's status
#   pg.sh start DIR         initdb DIR/data if needed, start; prints the URL
#   pg.sh stop DIR | restart DIR | url DIR
#
# VX_PG_BIN: the server's bin dir (default /usr/lib/postgresql/15/bin).
# VX_PG_OPTS: more server options, e.g. "-c fsync=off".
set -euo pipefail

bin=${VX_PG_BIN:-/usr/lib/postgresql/15/bin}
if [[ ! -x $bin/initdb || ! -x $bin/pg_ctl ]]; then
    echo "pg.sh: no PostgreSQL server in $bin (apt-get install postgresql-15)" >&2
    exit 1
fi

# Runs a server command as the directory's owner (nobody when we are root).
as_owner() {
    if [[ $(id -u) -eq 0 ]]; then
        setpriv --reuid=nobody --regid=nogroup --clear-groups -- "$@"
    else
        "$@"
    fi
}

url() { echo "postgresql://voxeld@/postgres?host=$1/sock"; }

start() {
    local dir=$1
    mkdir -p "$dir/sock"
    if [[ $(id -u) -eq 0 ]]; then chown -R nobody:nogroup "$dir"; fi
    if [[ ! -f $dir/data/PG_VERSION ]]; then
        as_owner "$bin/initdb" -D "$dir/data" -U voxeld --auth=trust -E UTF8 --locale=C -N \
            >"$dir/initdb.log" 2>&1 || { cat "$dir/initdb.log" >&2; return 1; }
    fi
    # shellcheck disable=SC2086 # VX_PG_OPTS is a list of options
    as_owner "$bin/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w -t 60 \
        -o "-c listen_addresses= -k $dir/sock -c max_connections=60 ${VX_PG_OPTS:-}" start \
        >/dev/null || { cat "$dir/server.log" >&2; return 1; }
    url "$dir"
}

stop() { as_owner "$bin/pg_ctl" -D "$1/data" -w -t 60 -m fast stop >/dev/null; }

case "${1:-}" in
start) start "$2" ;;
stop) stop "$2" ;;
restart)
    stop "$2"
    start "$2" >/dev/null
    ;;
url) url "$2" ;;
run)
    shift
    dir=$(mktemp -d /tmp/vxpg.XXXXXX)
    # shellcheck disable=SC2317 # called by the EXIT trap
    cleanup() {
        as_owner "$bin/pg_ctl" -D "$dir/data" -m immediate stop >/dev/null 2>&1 || true
        rm -rf "$dir"
    }
    trap cleanup EXIT
    trap 'exit 130' INT TERM
    VX_PG_URL=$(start "$dir")
    VX_PG_SH=$(readlink -f "$0")
    export VX_PG_URL VX_PG_DIR=$dir VX_PG_SH
    set +e
    "$@"
    rc=$?
    set -e
    exit $rc
    ;;
*)
    sed -n '2,15p' "$0" >&2
    exit 2
    ;;
esac
