#!/usr/bin/env bash
# The browser side served by the daemon (daemon/routes_web.c): the viewer at
# /, /docs, /openapi.yaml and /ui/{name}, built into the binary; public with
# a token set; Content-Type, ETag and 304; unknown files 404, other
# methods 405. (test_viewer.sh drives the page in a browser.)
source "$(dirname "$0")/lib.sh"
printf 'web-token\n' >"$TMP/token"
start_daemon --token-file "$TMP/token" || exit 1

api GET /
expect_status "the viewer page without a token" 200
check "/ is HTML ($CTYPE)" test "$CTYPE" = "text/html; charset=utf-8"
check "/ loads the viewer script" grep -q '/ui/app.js' "$BODY"
check "/ names no other origin (no CDN)" bash -c "! grep -Eq '(src|href)=\"(https?:)?//' '$BODY'"
etag=$(header ETag)
check "/ has a strong ETag ($etag)" bash -c "[[ '$etag' =~ ^\\\"[0-9a-f]{16}\\\"$ ]]"
check "/ is revalidated" test "$(header Cache-Control)" = "no-cache"
api GET / -H "If-None-Match: $etag"
expect_status "/ with its ETag" 304
check "304 has no body" test ! -s "$BODY"
api GET / -H "If-None-Match: \"0000000000000000\", W/$etag"
expect_status "/ with its ETag in a list" 304
api GET / -H 'If-None-Match: "0000000000000000"'
expect_status "/ with another ETag" 200
csp=$(header Content-Security-Policy)
has() { [[ "$1" == *"$2"* ]]; }
# the one inline script (the import map) by its hash, no other
MAPHASH=$(sed -n 's|.*<script type="importmap">\(.*\)</script>.*|\1|p' "$BODY" | tr -d '\n' |
    /usr/bin/python3 -c 'import sys, hashlib, base64; print(base64.b64encode(hashlib.sha256(sys.stdin.buffer.read()).digest()).decode())')
check "/ loads from its own origin only, the import map by its hash ($csp)" \
    has "$csp" "default-src 'self'; script-src 'self' 'sha256-$MAPHASH';"
check "/ allows no other inline script" bash -c "[[ '$csp' != *unsafe-inline* ]]"
check "/ is not framed" has "$csp" "frame-ancestors 'none'"
api HEAD /
expect_status "HEAD /" 200

api GET /openapi.yaml
expect_status "/openapi.yaml" 200
check "the contract as YAML ($CTYPE)" test "$CTYPE" = "application/yaml"
check "/openapi.yaml is api/openapi.yaml byte for byte" cmp -s "$BODY" "$VX_SOURCE_DIR/api/openapi.yaml"
api GET /docs
expect_status "/docs" 200
check "/docs is HTML" test "$CTYPE" = "text/html; charset=utf-8"
check "/docs loads its script" grep -q '/ui/docs.js' "$BODY"

for f in app.js forms.js view3d.js docs.js; do
    api GET "/ui/$f"
    expect_status "/ui/$f" 200
    check "/ui/$f is JavaScript ($CTYPE)" test "$CTYPE" = "text/javascript; charset=utf-8"
    check "/ui/$f is viewer/$f" cmp -s "$BODY" "$VX_SOURCE_DIR/viewer/$f"
done
api GET /ui/style.css
check "/ui/style.css is CSS ($CTYPE)" test "$CTYPE" = "text/css; charset=utf-8"
check "nosniff" test "$(header X-Content-Type-Options)" = "nosniff"
# The npm libraries (tools/viewer), when the build has them.
npm=$VX_SOURCE_DIR/tools/viewer/node_modules
if [[ -f $npm/three/build/three.core.min.js ]]; then
    api GET /ui/three.core.min.js
    expect_status "/ui/three.core.min.js" 200
    check "three.js as npm installed it" cmp -s "$BODY" "$npm/three/build/three.core.min.js"
    api GET /ui/three.LICENSE.txt
    expect_status "three.js's license" 200
    api GET /ui/js-yaml.mjs
    expect_status "/ui/js-yaml.mjs" 200
else
    echo "note: $npm lacks three.js (npm ci --prefix tools/viewer): vendored files not checked"
fi

api GET /ui/nope.js
expect_error "an unknown viewer file" 404 not_found
api GET /ui/
expect_error "/ui/ alone" 404 not_found
api GET /ui/../openapi.yaml --path-as-is
expect_error "no path walking" 404 not_found
api POST / -H "Content-Type: application/json" -d '{}'
expect_error "POST /" 405 method_not_allowed
check "405 Allow" test "$(header Allow)" = "GET, HEAD, OPTIONS"
api GET / -H "If-Match: $etag"
expect_status "/ with If-Match of its ETag" 200
api GET /ui/app.js -H 'If-Match: "0000000000000000"'
expect_error "a viewer file with If-Match of another ETag" 412 precondition_failed
api DELETE /openapi.yaml
expect_error "DELETE /openapi.yaml" 405 method_not_allowed
# The API behind it still wants the token.
api GET /v1/meshes
expect_error "the API still needs the token" 401 unauthorized

stop_daemon
finish
