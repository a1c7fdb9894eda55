#!/usr/bin/env bash
# The Dockerfile, built and run offline the way ARCHITECTURE.md ("Known
# traps") describes: debootstrap a minimal bookworm, import it as
# debian:bookworm, `podman build` the real Dockerfile, then start the image's
# own voxeld with `buildah run` (podman run cannot work in this sandbox: no
# cgroups, no setrlimit) and talk to it: llvmpipe inside the image, a preview
# job, its PNG; then the image's config (user, healthcheck, port, volume, NVIDIA).
#
# Env: VX_CONTAINER_CACHE (the debootstrap root is kept there; default
# ${TMPDIR:-/tmp}/voxeld-rootfs), VX_IMAGE (default localhost/voxeld),
# VX_DEBIAN_MIRROR (debootstrap's mirror; default its own).
# Exit 77 (skipped) when podman, buildah, debootstrap or root is missing.
source "$(dirname "$0")/../integration/lib.sh"
source "$(dirname "$0")/../integration/box.sh"

T_START=$SECONDS
for tool in podman buildah debootstrap curl jq python3; do
    if ! command -v "$tool" >/dev/null; then
        echo "SKIP: $tool is not installed (scripts/install-deps.sh installs it)"
        exit 77
    fi
done
if [[ $(id -u) -ne 0 ]]; then
    echo "SKIP: debootstrap and chroot isolation need root"
    exit 77
fi

IMAGE=${VX_IMAGE:-localhost/voxeld}
CACHE=${VX_CONTAINER_CACHE:-${TMPDIR:-/tmp}/voxeld-rootfs}
ROOTFS=$CACHE/bookworm-minbase
BASE_IMAGE=docker.io/library/debian:bookworm
CTR=
BPID=

step() { echo "[$((SECONDS - T_START))s] $*"; }

container_cleanup() {
    # The voxeld inside the container, then `buildah run`, then the container.
    if [[ -n "$PID" ]] && kill -0 "$PID" 2>/dev/null; then kill -KILL "$PID" 2>/dev/null; fi
    if [[ -n "$BPID" ]] && kill -0 "$BPID" 2>/dev/null; then kill -KILL "$BPID" 2>/dev/null; fi
    [[ -n "$BPID" ]] && wait "$BPID" 2>/dev/null
    PID=
    if [[ -n "$CTR" ]]; then buildah rm "$CTR" >/dev/null 2>&1; fi
    cleanup
}
trap container_cleanup EXIT

# ---- base image: debootstrap once, import once -------------------------------------
if ! podman image exists "$BASE_IMAGE"; then
    if [[ ! -f "$ROOTFS/.voxeld-complete" ]]; then
        step "debootstrap --variant=minbase bookworm $ROOTFS"
        rm -rf "$ROOTFS"
        mkdir -p "$CACHE"
        if ! debootstrap --variant=minbase bookworm "$ROOTFS" ${VX_DEBIAN_MIRROR:-} >"$TMP/debootstrap.log" 2>&1; then
            tail -n 20 "$TMP/debootstrap.log"
            check "debootstrap bookworm" false
            finish
            exit 1
        fi
        touch "$ROOTFS/.voxeld-complete"
    fi
    step "import $ROOTFS as $BASE_IMAGE"
    # Without the marker and without the apt lists/caches debootstrap left.
    tar -C "$ROOTFS" --exclude=./.voxeld-complete --exclude='./var/cache/apt/archives/*.deb' -c . |
        podman import - "$BASE_IMAGE" >"$TMP/import.log" 2>&1
fi
check "base image $BASE_IMAGE present" podman image exists "$BASE_IMAGE"

# ---- build the real Dockerfile -------------------------------------------------
# --format docker: OCI image configs have no HEALTHCHECK. The build stage is
# built (and tagged) first, so that the images a rebuild replaces can be
# removed by id: reruns keep the cached apt layers but do not pile up a new
# untagged 1.4 GB build stage and 600 MB image each time.
step "podman build $IMAGE from $VX_SOURCE_DIR/Dockerfile"
T_BUILD=$SECONDS
image_id() { podman image inspect --format '{{.Id}}' "$1" 2>/dev/null || true; }
OLD_IDS="$(image_id "$IMAGE-build") $(image_id "$IMAGE")"
BUILT=0
pbuild() { podman build --pull=never --isolation chroot --network host --format docker \
    -f "$VX_SOURCE_DIR/Dockerfile" "$@" "$VX_SOURCE_DIR" >>"$TMP/build.log" 2>&1; }
if pbuild --target build -t "$IMAGE-build" && pbuild -t "$IMAGE"; then
    BUILT=1
else
    tail -n 40 "$TMP/build.log"
fi
step "build took $((SECONDS - T_BUILD)) s"
NEW_IDS="$(image_id "$IMAGE-build") $(image_id "$IMAGE")"
for id in $OLD_IDS; do
    [[ " $NEW_IDS " == *" $id "* ]] || podman rmi "$id" >/dev/null 2>&1 || true
done
check "podman build of the Dockerfile" test "$BUILT" -eq 1
if [[ $BUILT -ne 1 ]]; then
    finish
    exit 1
fi

# ---- the image's configuration ----------------------------------------------------
podman image inspect "$IMAGE" >"$TMP/inspect.json"
cfg() { jq -e "$1" "$TMP/inspect.json" >/dev/null; }
check "User is set and not root ($(jq -r '.[0].Config.User' "$TMP/inspect.json"))" \
    cfg '.[0].Config.User as $u | $u != null and $u != "" and $u != "root" and $u != "0" and ($u | startswith("0:") | not) and ($u | startswith("root:") | not)'
check "Healthcheck curls /readyz" \
    cfg '(.[0].Healthcheck // .[0].Config.Healthcheck).Test | join(" ") | test("curl -fsS.*http://127.0.0.1:8080/readyz")'
check "ExposedPorts 8080/tcp" cfg '.[0].Config.ExposedPorts | has("8080/tcp")'
check "Volumes /var/lib/voxeld" cfg '.[0].Config.Volumes | has("/var/lib/voxeld")'
check "NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility" \
    cfg '.[0].Config.Env | index("NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility") != null'
check "NVIDIA_VISIBLE_DEVICES=all" cfg '.[0].Config.Env | index("NVIDIA_VISIBLE_DEVICES=all") != null'
check "Entrypoint listens on 0.0.0.0:8080 with /var/lib/voxeld" \
    cfg '.[0].Config.Entrypoint == ["voxeld","--listen","0.0.0.0:8080","--data-dir","/var/lib/voxeld"]'
check "Cmd adds nothing (arguments to the image add to the Entrypoint)" \
    cfg '(.[0].Config.Cmd // []) == []'
check "OCI labels (title, version, licenses)" \
    cfg '.[0].Config.Labels | .["org.opencontainers.image.title"] == "voxeld" and has("org.opencontainers.image.version") and has("org.opencontainers.image.licenses")'
step "image size $(jq -r '.[0].Size / 1048576 | floor' "$TMP/inspect.json") MiB"

# ---- a container from it ---------------------------------------------------------
CTR=$(buildah from --pull=never "$IMAGE" 2>"$TMP/from.log")
check "buildah from $IMAGE" test -n "$CTR"
[[ -z "$CTR" ]] && cat "$TMP/from.log"
brun() { buildah run --isolation chroot --network host "$CTR" -- "$@"; }
brun cat /usr/share/glvnd/egl_vendor.d/10_nvidia.json >"$TMP/vendor.json" 2>&1
check "NVIDIA glvnd vendor file" jq -e '.file_format_version == "1.0.0" and .ICD.library_path == "libEGL_nvidia.so.0"' "$TMP/vendor.json"
brun cat /usr/share/glvnd/egl_vendor.d/50_mesa.json >"$TMP/mesa.json" 2>&1
check "Mesa glvnd vendor file (llvmpipe fallback)" jq -e '.ICD.library_path | test("libEGL_mesa")' "$TMP/mesa.json"
# the CA bundle libcurl verifies an https:// S3 endpoint with (libcurl4
# only recommends ca-certificates: the image had none)
check "the image has the CA certificates" brun test -s /etc/ssl/certs/ca-certificates.crt
brun id >"$TMP/id.txt" 2>&1
check "runs as uid/gid 10001 ($(cat "$TMP/id.txt"))" grep -q '^uid=10001(voxeld) gid=10001(voxeld)' "$TMP/id.txt"
check "in groups video and render" bash -c "grep -q '(video)' '$TMP/id.txt' && grep -q '(render)' '$TMP/id.txt'"
brun voxeld --version >"$TMP/version.txt" 2>&1
check "voxeld --version in the image" grep -q '^voxeld ' "$TMP/version.txt"
brun voxelctl --version >"$TMP/ctl-version.txt" 2>&1
check "voxelctl --version in the image" grep -q '^voxelctl ' "$TMP/ctl-version.txt"
brun sh -c 'test -d /var/lib/voxeld && test -w /var/lib/voxeld' >/dev/null 2>&1
check "/var/lib/voxeld is writable by the image's user" test $? -eq 0
# Every shared library resolves (the runtime packages are complete).
brun sh -c 'ldd /usr/bin/voxeld /usr/bin/voxelctl' >"$TMP/ldd.txt" 2>&1
check "no missing shared library: $(grep 'not found' "$TMP/ldd.txt" | tr -s ' \t\n' ' ')" bash -c "! grep -q 'not found' '$TMP/ldd.txt'"
brun voxeld --list-egl-devices >"$TMP/devices.txt" 2>&1
check "an EGL device in the image (llvmpipe)" grep -qi 'EGL device' "$TMP/devices.txt"

PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
BASE=http://127.0.0.1:$PORT
step "buildah run voxeld on port $PORT"
# The image's own Entrypoint plus arguments, as `docker run IMAGE ARGS`
# runs it: the arguments add to the defaults (--data-dir stays), and a flag
# given again (--listen) wins.
mapfile -t ENTRY < <(jq -r '.[0].Config.Entrypoint[]' "$TMP/inspect.json")
buildah run --isolation chroot --network host "$CTR" -- \
    "${ENTRY[@]}" --listen "127.0.0.1:$PORT" --workers 2 --http-threads 4 \
    >"$TMP/daemon.out" 2>"$TMP/daemon.log" &
BPID=$!
UP=0
for i in $(seq 1 600); do
    if curl -fsS -o /dev/null "$BASE/livez" 2>/dev/null; then UP=1; break; fi
    kill -0 "$BPID" 2>/dev/null || break
    sleep 0.1
done
check "voxeld in the container answers /livez" test "$UP" -eq 1
[[ $UP -ne 1 ]] && tail -n 20 "$TMP/daemon.log"
# The voxeld process (a descendant of buildah run) gets the SIGTERM.
PID=$(sed -n 's/.*event=voxeld.start.* pid=\([0-9]*\).*/\1/p' "$TMP/daemon.log" | head -n 1)
check "voxeld pid from its start line" test -n "$PID"
check "the Entrypoint's --data-dir is kept beside the arguments" grep -q 'event=voxeld.start.* data_dir=/var/lib/voxeld' "$TMP/daemon.log"
if [[ -n "$PID" ]] && [[ "$(cat "/proc/$PID/comm" 2>/dev/null)" != voxeld ]]; then
    # Not in this pid namespace (a runtime with its own): signal buildah instead.
    PID=
fi

api GET /livez
expect_status "/livez" 200
api GET /readyz
expect_status "/readyz" 200
check "ready with GL (llvmpipe in the image)" jq -e '.status == "ready" and .checks.gl == true' "$BODY"
api GET /v1/info
expect_status "/v1/info" 200
check "renderer is llvmpipe ($(jqb .gl.renderer))" jq -e '.gl.renderer | test("llvmpipe")' "$BODY"
check "HEALTHCHECK command passes in the container" \
    brun curl -fsS -o /dev/null "http://127.0.0.1:$PORT/readyz"

box_obj "$TMP/box.obj" 0 0 0 2 1 1
upload "$TMP/box.obj"
expect_status "upload OBJ" 201
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
expect_status "preview job" 202
JID=$(jqb '.id // empty')
check "preview succeeded" jq -e '.state == "succeeded"' "$BODY"
api GET "/v1/jobs/$JID/result"
expect_status "result" 200
check "result is image/png" test "$CTYPE" = "image/png"
cp "$BODY" "$TMP/preview.png"
python3 - "$TMP/preview.png" >"$TMP/png.txt" <<'PY'
import struct, sys
d = open(sys.argv[1], "rb").read()
assert d[:8] == b"\x89PNG\r\n\x1a\n" and d[12:16] == b"IHDR"
print(*struct.unpack(">II", d[16:24]))
PY
check "PNG 64x64 ($(cat "$TMP/png.txt"))" test "$(cat "$TMP/png.txt")" = "64 64"

# ---- stop ------------------------------------------------------------------------
if [[ -n "$PID" ]]; then kill -TERM "$PID"; else kill -TERM "$BPID"; fi
rc=0
wait "$BPID" || rc=$?
BPID=
PID=
check "container voxeld exits 0 on SIGTERM (got $rc)" test "$rc" -eq 0
check "graceful exit logged" grep -q 'event=voxeld.exit status=0' "$TMP/daemon.log"
buildah rm "$CTR" >/dev/null 2>&1
check "buildah rm" test $? -eq 0
CTR=

step "total $((SECONDS - T_START)) s"
finish
