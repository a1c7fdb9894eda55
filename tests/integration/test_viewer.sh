#!/usr/bin/env bash
# The viewer in a real browser: Debian's chromium driven by playwright-core
# (tools/viewer, installed by scripts/install-deps.sh) runs
# tests/browser/viewer.cjs against a daemon with a token: upload spot,
# voxelize and gregory from the generated form, and a non-empty 3D view.
# Screenshots: BUILD/test-artifacts/viewer*.png. Skipped (77) without
# chromium or playwright-core.
source "$(dirname "$0")/lib.sh"
CHROMIUM=${VX_CHROMIUM:-/usr/bin/chromium}
NPM=$VX_SOURCE_DIR/tools/viewer/node_modules
if [[ ! -x $CHROMIUM ]]; then
    echo "SKIP: no chromium at $CHROMIUM (apt-get install chromium; scripts/install-deps.sh does)"
    exit 77
fi
if [[ ! -d $NPM/playwright-core ]] || ! command -v node >/dev/null; then
    echo "SKIP: no playwright-core in $NPM or no node (npm ci --prefix tools/viewer; scripts/install-deps.sh does)"
    exit 77
fi
printf 'viewer-token\n' >"$TMP/token"
start_daemon --token-file "$TMP/token" || exit 1
api GET /ui/three.core.min.js
check "the build embeds three.js (else: npm ci --prefix tools/viewer, then build again)" test "$STATUS" = 200

ART=$(dirname "$VOXELD")/test-artifacts
NODE_PATH=$NPM VX_CHROMIUM=$CHROMIUM timeout 120 node "$VX_SOURCE_DIR/tests/browser/viewer.cjs" \
    "$BASE" viewer-token "$VX_MESH_DIR/spot_triangulated.obj" "$VX_MESH_DIR/spot_control_mesh.obj" "$ART"
rc=$?
check "the browser run passes (rc $rc; screenshots in $ART)" test "$rc" -eq 0
check "a screenshot is kept" test -s "$ART/viewer.png"
stop_daemon
finish
