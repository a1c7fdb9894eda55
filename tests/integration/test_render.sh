#!/usr/bin/env bash
# The `render` kind through the API (issue #4, seed 002): an icosphere and
# a torus made here, rendered with the normal and position outputs; the
# rendered normals against the analytic normals of the exact sphere and
# torus (spectral <= 0.06 deg for the sphere at N = 64, R = 8N, and >= 20x
# better than central differences on the same voxels); the comparison
# image's six labelled panels; summed meshes; turntable frames; 16-bit PNG;
# the VDB FloatGrid; orbit cameras (far eyes, tiny fields of view); params
# errors and limits.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
# 1G: the N=64 renders need about 0.3 GB; N=256 does not fit.
start_daemon --max-job-memory 1G || exit 1

python3 "$(dirname "$0")/render_shapes.py" "$TMP" || exit 1
RC="$VX_TOOLS/render_check"
for s in icosphere torus ball_a ball_b; do
    upload "$TMP/$s.obj"
    expect_status "upload $s" 201
    declare "M_$s=$MESH_ID"
done

api GET /v1/info
check "info lists render" jq -e '[.kinds[].name] | index("render") != null' "$BODY"

# job WHAT MESH PARAMS: a render job, waited for; sets J, keeps the body.
job() {
    run_job render "$2" "$3" 300
    J=$JOB
    job_ok "$1"
}
# get NAME FILE: output NAME of job J into FILE.
get() {
    api GET "/v1/jobs/$J/result/$1"
    check "output $1 of $J: 200" test "$STATUS" = 200
    cp "$BODY" "$2"
}
# le WHAT A B: A <= B (floats).
le() { check "$1: $2 <= $3" awk -v a="$2" -v b="$3" 'BEGIN { exit !(a <= b) }'; }

# --- sphere: spectral vs central differences, N = 64, R = 8N (defaults) ---
SPH='"width":256,"height":256,"outputs":["normal","position","depth"]'
job "sphere spectral" "$M_icosphere" "{$SPH}"
check "sphere: N 64, R 512, M 256, iso 0.5 by default" jq -e \
    '.params.N == 64 and .params.R == 512 and .params.L == 4 and .params.filter.D0 == 16 and .stats.M == 256 and .stats.iso == 0.5' "$TMP/job.json"
check "sphere: outputs image, normal, position, depth" jq -e \
    '.outputs | keys == ["depth","image","normal","position"]' "$TMP/job.json"
check "sphere: stage timings" jq -e \
    '[.stats.sampling_ms, .stats.lowpass_ms, .stats.interp_ms, .stats.render_ms, .stats.encode_ms] | all(. > 0)' "$TMP/job.json"
le "sphere: peak bytes under 400 MB" "$(st peak_bytes)" 400000000
check "FFTW wisdom kept in the cache dir" test -s "$DATA/cache/fftw3f.wisdom"
check "the wisdom file is FFTW's" grep -q 'fftw-3' "$DATA/cache/fftw3f.wisdom"
get normal "$TMP/n.pfm"
get position "$TMP/p.pfm"
get depth "$TMP/d.pfm"
get image "$TMP/s.png"
check "normal output is served as PFM" test "$CTYPE" != "" 
SPEC=$("$RC" normals "$TMP/n.pfm" "$TMP/p.pfm" sphere 0 0 0)
echo "sphere spectral: $SPEC"
HITS=$(jq -r .hits <<<"$SPEC")
check "sphere: hits = pixels_covered" test "$HITS" = "$(st pixels_covered)"
# the unit sphere in a view 2 * sqrt(3) * 1.05 wide (the bbox's bounding
# sphere plus 5%): pi / 3.6373^2 of the 256^2 pixels
DISC=$(awk -v h="$HITS" 'BEGIN { print h / (3.14159265 * 65536 / (3.6373 * 3.6373)) }')
le "sphere: about the expected disc (lower)" 0.98 "$DISC"
le "sphere: about the expected disc (upper)" "$DISC" 1.02
S_MEAN=$(jq -r .mean_deg <<<"$SPEC")
check "sphere: hits on the unit sphere (mean distance within 1%)" jq -e '.mean_dist > 0.99 and .mean_dist < 1.01' <<<"$SPEC"
le "sphere: spectral mean normal error <= 0.06 deg" "$S_MEAN" 0.06
check "depth PFM: 1 channel, misses NaN" jq -e ".channels == 1 and .width == 256 and .nan == $((65536 - HITS))" <<<"$("$RC" pfm "$TMP/d.pfm")"
check "position PFM: 3 channels" jq -e '.channels == 3 and .height == 256' <<<"$("$RC" pfm "$TMP/p.pfm")"
check "image: 256x256 8-bit RGB" jq -e '.width == 256 and .height == 256 and .bit_depth == 8 and .channels == 3' <<<"$("$VX_TOOLS/pngstat" "$TMP/s.png")"

job "sphere central-difference" "$M_icosphere" "{$SPH,\"normals\":\"central-difference\"}"
get normal "$TMP/n.pfm"
get position "$TMP/p.pfm"
CD=$("$RC" normals "$TMP/n.pfm" "$TMP/p.pfm" sphere 0 0 0)
echo "sphere central-difference: $CD"
C_MEAN=$(jq -r .mean_deg <<<"$CD")
le "sphere: spectral at least 20x better than central differences" "$(awk -v s="$S_MEAN" 'BEGIN { print 20 * s }')" "$C_MEAN"
job "sphere sobel3d" "$M_icosphere" "{$SPH,\"normals\":\"sobel3d\"}"
get normal "$TMP/n.pfm"
get position "$TMP/p.pfm"
echo "sphere sobel3d: $("$RC" normals "$TMP/n.pfm" "$TMP/p.pfm" sphere 0 0 0)"
le "sphere: sobel3d worse than spectral" "$S_MEAN" "$("$RC" normals "$TMP/n.pfm" "$TMP/p.pfm" sphere 0 0 0 | jq .mean_deg)"

# --- torus, from an orbit camera ---
TOR='"width":256,"height":256,"camera":{"type":"orbit","azimuth":20,"elevation":50},"outputs":["normal","position"]'
job "torus spectral" "$M_torus" "{$TOR}"
get normal "$TMP/n.pfm"
get position "$TMP/p.pfm"
T_SPEC=$("$RC" normals "$TMP/n.pfm" "$TMP/p.pfm" torus 1)
echo "torus spectral: $T_SPEC"
# The band-limited torus is not exactly a torus (the low-pass moves the
# inner and outer sides differently), so its normals differ from the exact
# torus's by more than the sphere's do: a looser bound.
le "torus: spectral mean normal error <= 0.25 deg" "$(jq -r .mean_deg <<<"$T_SPEC")" 0.25
job "torus central-difference" "$M_torus" "{$TOR,\"normals\":\"central-difference\"}"
get normal "$TMP/n.pfm"
get position "$TMP/p.pfm"
T_CD=$("$RC" normals "$TMP/n.pfm" "$TMP/p.pfm" torus 1)
echo "torus central-difference: $T_CD"
le "torus: spectral at least 5x better than central differences" \
    "$(jq -r .mean_deg <<<"$T_SPEC" | awk '{ print 5 * $1 }')" "$(jq -r .mean_deg <<<"$T_CD")"

# --- lights, ambient, background: a red light from +z, no ambient ---
job "red light" "$M_icosphere" '{"N":16,"width":64,"height":64,"ambient":0,"background":[0,0,1],"lights":[{"direction":[0,0,1],"color":[1,0,0]}]}'
get image "$TMP/red.png"
PS=$("$VX_TOOLS/pngstat" "$TMP/red.png" --bg 0,0,255)
check "red light: centre = colour red x 1 (204, 0, 0), corner = background" jq -e \
    '.center_pixel[0] >= 200 and .center_pixel[0] <= 205 and .center_pixel[1] == 0 and .center_pixel[2] == 0 and .covered > 500' <<<"$PS"
check "red light: normalised lights echoed" jq -e '.params.lights[0].color == [1,0,0] and .params.ambient == 0' "$TMP/job.json"

# --- compare: six labelled panels of the same shape ---
job "compare" "$M_icosphere" '{"N":32,"width":128,"height":128,"compare":true}'
get image "$TMP/c.png"
check "compare: 3x2 panels of 128" jq -e '.width == 384 and .height == 256' <<<"$("$VX_TOOLS/pngstat" "$TMP/c.png")"
P=$("$RC" panels "$TMP/c.png" 3 2)
echo "compare panels: $P"
check "compare: every panel shows the shape, within 10% of the spectral one" jq -e \
    '.covered as $c | $c[0] > 3000 and ($c | all(. > 0.9 * $c[0] and . < 1.1 * $c[0]))' <<<"$P"
check "compare: every panel is labelled" jq -e '.ink | all(. > 20)' <<<"$P"
# The float outputs of a compare are the selected method's (here sobel2d,
# a middle panel): the same bytes as the plain render with that method.
job "compare sobel2d outputs" "$M_icosphere" '{"N":32,"width":96,"height":64,"compare":true,"normals":"sobel2d","outputs":["normal","depth"]}'
get normal "$TMP/cn.pfm"
get depth "$TMP/cd.pfm"
job "sobel2d outputs" "$M_icosphere" '{"N":32,"width":96,"height":64,"normals":"sobel2d","outputs":["normal","depth"]}'
get normal "$TMP/pn.pfm"
get depth "$TMP/pd.pfm"
check "compare: its normal output is the sobel2d render's" cmp -s "$TMP/cn.pfm" "$TMP/pn.pfm"
check "compare: its depth output is the sobel2d render's" cmp -s "$TMP/cd.pfm" "$TMP/pd.pfm"

# --- meshes: two overlapping balls summed ---
job "one ball" "$M_ball_a" '{"N":32,"width":128,"height":128}'
ONE=$(st pixels_covered)
job "two balls" "$M_ball_a" "{\"N\":32,\"width\":128,\"height\":128,\"meshes\":[\"$M_ball_b\"]}"
check "two balls: 2 meshes" test "$(st meshes)" = 2
le "two balls cover more than one" "$((ONE + 1))" "$(st pixels_covered)"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$M_ball_a\",\"kind\":\"render\",\"params\":{\"meshes\":[\"$(printf 'ab%.0s' {1..32})\"]}}"
expect_error "unknown mesh in meshes" 404 mesh_not_found

# --- turntable, 16-bit, voxels ---
job "turntable" "$M_torus" '{"N":16,"width":64,"height":48,"camera":{"type":"orbit"},"frames":3,"bits":16,"outputs":["depth","voxels"]}'
check "turntable: numbered outputs" jq -e \
    '.outputs | keys == ["depth_000","depth_001","depth_002","image_000","image_001","image_002","voxels"]' "$TMP/job.json"
get image_001 "$TMP/t1.png"
check "turntable frame: 64x48 16-bit" jq -e '.width == 64 and .height == 48 and .bit_depth == 16' <<<"$("$VX_TOOLS/pngstat" "$TMP/t1.png")"
get image_000 "$TMP/t0.png"
check "turntable frames differ" test "$(md5sum <"$TMP/t0.png")" != "$(md5sum <"$TMP/t1.png")"
get voxels "$TMP/v.vdb"
VI=$("$VX_TOOLS/vdbinfo" "$TMP/v.vdb")
check "voxels: a FloatGrid density of 16^3 voxels" jq -e \
    '.grids[0].name == "density" and (.grids[0].type | test("float")) and .grids[0].active_voxels > 100 and .grids[0].active_voxels <= 4096' <<<"$VI"

# --- errors ---
bad() {
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$M_ball_a\",\"kind\":\"render\",\"params\":$2}"
    expect_error "$1" 422 invalid_params
    check "$1: message names $3" grep -q -- "$3" "$BODY"
}
bad "odd N" '{"N":63}' params.N
bad "R below N" '{"N":64,"R":32}' params.R
bad "L too large" '{"L":17}' params.L
bad "over memory" '{"N":256,"R":1024}' "job memory limit"
bad "unknown normals" '{"normals":"phong"}' params.normals
bad "unknown camera field" '{"camera":{"zoom":2}}' params.camera.zoom
bad "bad axis" '{"camera":{"axis":"x"}}' params.camera.axis
bad "frames on the axis camera" '{"frames":4}' params.frames
bad "bits 12" '{"bits":12}' params.bits
bad "unknown output" '{"outputs":["mesh"]}' params.outputs
bad "an output twice" '{"outputs":["depth","normal","depth"]}' 'params.outputs lists .*depth.* twice'
bad "zero light" '{"lights":[{"direction":[0,0,0]}]}' "params.lights\[0\].direction"
bad "filter D0" '{"filter":{"D0":-1}}' params.filter.D0
bad "too many pixels" '{"width":8192,"height":8192,"compare":true}' params.width

# A mesh so small that its voxels are under what OpenVDB's transforms take
# (h^3 >= 3e-15): the voxels output fails the job with voxel_size_too_small
# (not an OpenVDB exception as io_error at the end); without it the render
# runs.
tet_obj "$TMP/tiny.obj" 1e-4
upload "$TMP/tiny.obj"
expect_status "upload tiny" 201
TINY=$MESH_ID
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$TINY\",\"kind\":\"render\",\"params\":{\"N\":32,\"outputs\":[\"voxels\"]}}"
expect_error "tiny mesh, voxels output: told at submission from its box" 422 invalid_params
check "the message gives the voxel size" jq -e '.error.message | test("voxel size would be")' "$BODY"
# with further meshes, the box is their union's: the same tiny mesh twice
# is still 422, a tiny mesh beside a larger one renders.
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$TINY\",\"kind\":\"render\",\"params\":{\"N\":32,\"outputs\":[\"voxels\"],\"meshes\":[\"$TINY\"]}}"
expect_error "tiny mesh twice, voxels output: told at submission from the union box" 422 invalid_params
printf 'v 3.0001 0 0\nv 3 1e-4 0\nv 3 0 1e-4\nv 3 0 0\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n' >"$TMP/tiny_far.obj"
upload "$TMP/tiny_far.obj"
expect_status "upload a tiny mesh 3 units away" 201
job "two tiny meshes 3 apart, voxels output (their union box is large enough)" "$TINY" \
    "{\"N\":32,\"outputs\":[\"voxels\"],\"meshes\":[\"$MESH_ID\"]}"
job "tiny mesh, image only" "$TINY" '{"N":32}'

# Cameras far from the mesh: the rays are marched from where they enter the
# grid (from 1e11 mesh sizes away a step of t was below t's precision, and
# the job never ended: not for a cancel, the job timeout or SIGTERM), and
# an orthographic eye farther than the fitting distance sees the image it
# sees from there.
far() { # WHAT MESH CAMERA: the render's pixels_covered into COV
    run_job render "$2" "{\"N\":16,\"width\":32,\"height\":32,\"camera\":$3}" 60
    job_ok "$1"
    COV=$(jq -r '.stats.pixels_covered' "$TMP/job.json")
}
far "torus, orthographic from the fitting distance" "$M_torus" '{"type":"orbit","fov":0}'
NEAR=$COV
far "torus, orthographic from 1e12" "$M_torus" '{"type":"orbit","distance":1e12,"fov":0}'
check "orthographic from 1e12: the same pixels as from near ($COV, $NEAR)" test "$COV" = "$NEAR" -a "$COV" -gt 0
far "torus, perspective from 1e11 with a fov of 1e-9" "$M_torus" '{"type":"orbit","distance":1e11,"fov":1e-9}'
check "perspective from 1e11: the torus in view ($COV pixels)" test "$COV" -gt 0
tet_obj "$TMP/tinier.obj" 1e-30
upload "$TMP/tinier.obj"
far "a mesh of 1e-30, orthographic from 1" "$MESH_ID" '{"type":"orbit","distance":1,"fov":0}'
check "a mesh of 1e-30 from 1e30 sizes away: in the image ($COV pixels)" test "$COV" -gt 0
# A fitted perspective eye (distance 0) for a tiny fov: placed as for a fov
# of 1e-6 degrees (VX_BL_MIN_FIT_FOV), the same picture. A fov of 1e-300 put
# the eye 1e302 radii away (an empty image: the rays' entry points lost the
# mesh), and on a mesh of 1e30 at infinity: NaN rays, read off the grid, and
# the daemon died (SIGSEGV) on every restart until the job was dropped.
far "torus, fitted perspective with a fov of 1e-6" "$M_torus" '{"type":"orbit","fov":1e-6}'
NEAR=$COV
far "torus, fitted perspective with a fov of 1e-300" "$M_torus" '{"type":"orbit","fov":1e-300}'
check "fov 1e-300: the picture of fov 1e-6 ($COV, $NEAR pixels)" test "$COV" = "$NEAR" -a "$COV" -gt 0
tet_obj "$TMP/huge.obj" 1e30
upload "$TMP/huge.obj"
far "a mesh of 1e30, fitted perspective with a fov of 1e-300" "$MESH_ID" '{"type":"orbit","azimuth":0,"elevation":0,"fov":1e-300}'
check "a mesh of 1e30, fov 1e-300: in the image ($COV pixels)" test "$COV" -gt 0
api GET /livez
check "the daemon is still up after it" test "$STATUS" = 200
# An open mesh and a closed one whose faces disagree on their way round
# are sampled by the rule voxelize takes for them (nonzero left an open
# box one wall, 0.073 of the box for 0.364, and a flipped face a flange)
box_obj "$TMP/cube.obj" 0 0 0 1 1 1
grep -v '^f 2 3 7 6$' "$TMP/cube.obj" >"$TMP/open.obj"
sed 's/^f 1 4 3 2$/f 1 2 3 4/' "$TMP/cube.obj" >"$TMP/flip.obj"
for s in cube open flip; do
    upload "$TMP/$s.obj"
    far "a unit cube, $s" "$MESH_ID" '{"type":"orbit"}'
    declare "MD_$s=$(st mean_density)" "IN_$s=$(jq -c .stats.inside "$TMP/job.json")"
done
check "the rules: nonzero, winding (open), parity (flipped) ($IN_cube $IN_open $IN_flip)" \
    test "$IN_cube$IN_open$IN_flip" = '["nonzero"]["winding"]["parity"]'
check "an open cube, a flipped one: the solid cube's density ($MD_open, $MD_flip, $MD_cube)" \
    awk -v a="$MD_open" -v b="$MD_flip" -v c="$MD_cube" 'BEGIN { exit !(c > 0.3 && (a - c) ^ 2 < (0.02 * c) ^ 2 && (b - c) ^ 2 < (0.02 * c) ^ 2) }'
# A flat field (D0 1e-6 keeps the mean alone) has no gradient: a hit's
# normal faces the camera (it was NaN, which says "missed")
job "a flat field" "$M_icosphere" '{"N":16,"width":32,"height":32,"filter":{"D0":1e-6},"iso":0.01,"outputs":["normal","depth"]}'
get normal "$TMP/fn.pfm"
get depth "$TMP/fd.pfm"
FN=$("$RC" pfm "$TMP/fn.pfm")
FD=$("$RC" pfm "$TMP/fd.pfm")
check "a flat field: hits ($FD) have normals ($FN)" \
    jq -e --argjson d "$FD" '$d.nan < 1024 and .nan == 3 * $d.nan' <<<"$FN"
# A light direction of [0, 0, 1e-200] is not zero (its length's square
# underflows: it was 422 "must not be zero"): the light of [0, 0, 1].
job "a light direction [0, 0, 1]" "$M_ball_a" '{"N":16,"width":32,"height":32,"lights":[{"direction":[0,0,1]}]}'
get image "$TMP/l1.png"
job "a light direction [0, 0, 1e-200]" "$M_ball_a" '{"N":16,"width":32,"height":32,"lights":[{"direction":[0,0,1e-200]}]}'
get image "$TMP/l2.png"
check "a light direction [0, 0, 1e-200]: the picture of [0, 0, 1]" cmp -s "$TMP/l1.png" "$TMP/l2.png"
stop_daemon

# A turntable that cannot finish within the job timeout stops once its
# first frame shows it (it had run the whole timeout, then failed).
start_daemon --max-job-memory 1G --job-timeout 40 || exit 1
upload "$TMP/torus.obj"
run_job render "$MESH_ID" '{"N":16,"width":1024,"height":1024,"frames":360,"camera":{"type":"orbit"}}' 120
check "a 360-frame 1024^2 turntable under a 40 s timeout: job_timeout ($(jq -c .error "$TMP/job.json"))" \
    jq -e '.state == "failed" and .error.code == "job_timeout" and (.error.message | contains("would run past the job timeout of 40 s"))' "$TMP/job.json"
check "it stopped well before the timeout ($(jq .timings.run_ms "$TMP/job.json") ms)" \
    jq -e '.timings.run_ms < 30000' "$TMP/job.json"
stop_daemon
finish
