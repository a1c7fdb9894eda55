#!/usr/bin/env bash
# The `voxelize` kind through the API: analytic shapes made here (boxes with
# faces on cell boundaries -> exact counts; spheres, a torus, a hollow ball,
# a solid in its void, overlapping spheres, an open mesh -> volumes within a
# stated tolerance of the mesh's own volume), through every method where
# the engine has them, every output format read back independently, bricks
# of a larger grid, peel vs slice and peel vs scan voxel for voxel, and params errors.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
# 256M: small enough that the memory checks trigger on modest requests.
start_daemon --max-job-memory 256M || exit 1

python3 "$(dirname "$0")/shapes.py" "$TMP" || exit 1
vol() { jq -r ".$1" "$TMP/volumes.json"; }
# Tolerance on volumes, relative to the mesh volume: at 32 cells across, the
# voxel boundary error is about +-(surface area * h / 2) in the worst case
# but cancels on smooth shapes; 3% is several times what is seen.
TOL=0.03

# vox WHAT MESH PARAMS_JSON: a voxelize job, waited for; sets VJ and keeps
# the job body in $TMP/job.json.
vox() {
    run_job voxelize "$2" "$3"
    VJ=$JOB
    job_ok "$1"
}
# fetch FILE: the primary output of job VJ into FILE.
fetch() {
    api GET "/v1/jobs/$VJ/result"
    check "result of $VJ: 200" test "$STATUS" = 200
    cp "$BODY" "$1"
}
# near WHAT GOT WANT TOL: |GOT - WANT| <= TOL * |WANT|.
near() {
    check "$1: $2 within $4 of $3" awk -v a="$2" -v b="$3" -v t="$4" \
        'BEGIN { d = a - b; if (d < 0) d = -d; if (b < 0) b = -b; exit !(d <= t * b) }'
}
# bytes FILE -> "size sum" of a raw8 file; bits FILE -> "size popcount".
bytes() { python3 -c 'import sys; d = open(sys.argv[1], "rb").read(); print(len(d), sum(d))' "$1"; }
bits() { python3 -c 'import sys; d = open(sys.argv[1], "rb").read(); print(len(d), sum(bin(b).count("1") for b in d))' "$1"; }
# raw8 FILE LINEAR_INDEX -> the byte there.
raw8_at() { python3 -c 'import sys; print(open(sys.argv[1], "rb").read()[int(sys.argv[2])])' "$1" "$2"; }
nvox() { jq -r '.stats.dims | .[0] * .[1] * .[2]' "$TMP/job.json"; }

for s in sphere torus hollow nested two open; do
    upload "$TMP/$s.obj"
    expect_status "upload $s" 201
    declare "M_$s=$MESH_ID"
done
box_obj "$TMP/cube.obj" 0 0 0 1 1 1
upload "$TMP/cube.obj"
M_cube=$MESH_ID
box_obj "$TMP/long.obj" 0 0 0 2 1 1
upload "$TMP/long.obj"
M_long=$MESH_ID

api GET /v1/info
check "info lists voxelize" jq -e '[.kinds[].name] | index("voxelize") != null' "$BODY"

# Which methods the engine has: peel, scan and cpu always; slice once its branch is in.
METHODS=(peel scan cpu)
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$M_cube\",\"kind\":\"voxelize\",\"params\":{\"resolution\":4,\"method\":\"slice\",\"format\":\"summary\"}}"
if jq -e '.state == "succeeded"' "$BODY" >/dev/null; then
    METHODS+=(slice)
else
    echo "note: slice unavailable ($(jq -c .error "$BODY")), testing peel only"
fi

for m in "${METHODS[@]}"; do
    # --- exact counts: boxes with faces on cell boundaries ---
    vox "$m cube r8 summary" "$M_cube" "{\"resolution\":8,\"method\":\"$m\",\"format\":\"summary\"}"
    check "$m cube: 512 voxels, dims 8^3, volume 1" jq -e \
        '.stats.voxels_inside == 512 and .stats.dims == [8,8,8] and .stats.volume == 1 and .stats.voxel_size == 0.125 and .stats.origin == [0,0,0]' "$TMP/job.json"
    check "$m cube: method as run" test "$(st method)" = "$m"
    check "$m cube: normalised params" jq -e '.params.resolution == 8 and .params.voxel_size == null and .params.grid == null and .params.inside == null and .params.format == "summary"' "$TMP/job.json"
    check "$m cube: summary has no outputs" jq -e '.outputs == {}' "$TMP/job.json"
    api GET "/v1/jobs/$VJ/result"
    expect_error "$m summary result" 404 output_not_found
    check "$m summary result: the message points at the stats" jq -e '.error.message | test("summary.*stats")' "$BODY"
    # no result directory to sync: no error logged for it
    check "$m summary: no store error logged" bash -c "! grep -a 'event=store.result_unsynced job=$VJ' '$TMP/daemon.log'"

    vox "$m cube r8 padding 2" "$M_cube" "{\"resolution\":8,\"padding\":2,\"method\":\"$m\",\"format\":\"raw8\"}"
    check "$m padded cube: dims 12^3, origin -0.25" jq -e '.stats.dims == [12,12,12] and .stats.origin == [-0.25,-0.25,-0.25] and .stats.voxels_inside == 512' "$TMP/job.json"
    fetch "$TMP/$m-cube.raw8"
    check "$m padded cube raw8: content type" test "$CTYPE" = application/octet-stream
    check "$m padded cube raw8: 1728 bytes, 512 set" test "$(bytes "$TMP/$m-cube.raw8")" = "1728 512"
    check "$m padded cube: (1,2,2) outside, (2,2,2) inside" test "$(raw8_at "$TMP/$m-cube.raw8" $((1 + 12 * (2 + 12 * 2))))$(raw8_at "$TMP/$m-cube.raw8" $((2 + 12 * (2 + 12 * 2))))" = 01

    vox "$m 2x1x1 r8" "$M_long" "{\"resolution\":8,\"method\":\"$m\",\"format\":\"raw8\"}"
    check "$m 2x1x1: dims [8,4,4], 128 voxels" jq -e '.stats.dims == [8,4,4] and .stats.voxels_inside == 128' "$TMP/job.json"
    fetch "$TMP/$m-long.raw8"
    check "$m 2x1x1 raw8: 128 bytes all set" test "$(bytes "$TMP/$m-long.raw8")" = "128 128"

    # Tie rule: the cube's x faces exactly on voxel centres (x = 0 and x = 1
    # are the centres of i = 0 and i = 8): [entry, exit) keeps i = 0..7.
    vox "$m tie grid" "$M_cube" "{\"grid\":{\"origin\":[-0.0625,0,0],\"voxel_size\":0.125,\"dims\":[10,8,8]},\"method\":\"$m\",\"format\":\"raw8\"}"
    check "$m tie: 512 voxels" test "$(st voxels_inside)" = 512
    fetch "$TMP/$m-tie.raw8"
    check "$m tie: centre on the entry face is inside, on the exit face outside" \
        test "$(raw8_at "$TMP/$m-tie.raw8" 0)$(raw8_at "$TMP/$m-tie.raw8" 7)$(raw8_at "$TMP/$m-tie.raw8" 8)" = 110

    # --- volumes of curved shapes ---
    for s in sphere torus hollow nested; do
        id=M_$s
        vox "$m $s" "${!id}" "{\"resolution\":32,\"method\":\"$m\",\"format\":\"raw8\"}"
        near "$m $s volume" "$(st volume)" "$(vol $s)" $TOL
        fetch "$TMP/$m-$s.raw8"
        check "$m $s raw8: nx*ny*nz bytes, sum = voxels_inside" test "$(bytes "$TMP/$m-$s.raw8")" = "$(nvox) $(st voxels_inside)"
        cp "$TMP/job.json" "$TMP/$m-$s.json"
    done
    # The centre voxel (16,16,16) of the 32^3 grid over [-1,1]^3 (centre at
    # 0.03125): in the void of `hollow`, in the inner ball of `nested`.
    check "$m hollow: void empty" test "$(raw8_at "$TMP/$m-hollow.raw8" $((16 + 32 * (16 + 32 * 16))))" = 0
    check "$m nested: solid in the void" test "$(raw8_at "$TMP/$m-nested.raw8" $((16 + 32 * (16 + 32 * 16))))" = 1

    vox "$m two nonzero" "$M_two" "{\"resolution\":48,\"method\":\"$m\",\"format\":\"raw8\"}"
    near "$m two spheres, nonzero = union" "$(st volume)" "$(vol two_union)" $TOL
    fetch "$TMP/$m-two.raw8"
    vox "$m two parity" "$M_two" "{\"resolution\":48,\"method\":\"$m\",\"inside\":\"parity\",\"format\":\"summary\"}"
    # every method's parity counts crossings: the symmetric difference
    near "$m two spheres, parity = symmetric difference" "$(st volume)" "$(vol two_xor)" $TOL

    if [[ $m == cpu ]]; then
        api POST /v1/jobs -H "Content-Type: application/json" \
            -d "{\"mesh\":\"$M_open\",\"kind\":\"voxelize\",\"params\":{\"method\":\"cpu\",\"inside\":\"robust\"}}"
        expect_error "cpu robust refused at submission" 422 invalid_params
        continue
    fi
    vox "$m open robust" "$M_open" "{\"resolution\":32,\"method\":\"$m\",\"inside\":\"robust\",\"format\":\"summary\"}"
    near "$m open mesh, robust ~ the closed sphere" "$(st volume)" "$(vol open_closed)" 0.04
    if [[ $m == scan ]]; then
        check "scan robust runs peel (stats say so)" test "$(st method)" = peel
    fi
done

# --- scan, cpu and peel agree voxel for voxel on closed meshes (raw8 identical) ---
for other in scan cpu; do
    for s in cube long tie sphere torus hollow nested two; do
        mis=$(cmp -l "$TMP/peel-$s.raw8" "$TMP/$other-$s.raw8" 2>/dev/null | wc -l)
        check "peel and $other raw8 both there for $s" test -s "$TMP/$other-$s.raw8" -a -s "$TMP/peel-$s.raw8"
        echo "peel vs $other, $s: $mis voxels differ"
        check "peel vs $other agree on $s ($mis differ)" cmp -s "$TMP/peel-$s.raw8" "$TMP/$other-$s.raw8"
    done
done

# --- peel and slice agree voxel for voxel on closed meshes ---
if [[ " ${METHODS[*]} " == *" slice "* ]]; then
    for s in cube long tie sphere torus hollow nested two; do
        mis=$(cmp -l "$TMP/peel-$s.raw8" "$TMP/slice-$s.raw8" 2>/dev/null | wc -l)
        echo "peel vs slice, $s: $mis voxels differ"
        check "peel vs slice agree on $s ($mis differ)" test "$mis" -eq 0
    done
fi

# --- every format, on the sphere ---
vox "sphere vdb" "$M_sphere" '{"resolution":24,"vdb_grid":"bool"}'
# auto: cpu for nonzero/parity solid fills, on every renderer
check "default format is vdb" jq -e '.params.format == "vdb" and .params.method == "auto" and .stats.method == "cpu"' "$TMP/job.json"
N_IN=$(st voxels_inside)
H=$(st voxel_size)
fetch "$TMP/s.vdb"
check "vdb content type" test "$CTYPE" = application/x-openvdb
check "vdb disposition" bash -c "grep -qi 'filename=\"$VJ-voxels.vdb\"' '$HDRS'"
"$VX_TOOLS/vdbinfo" "$TMP/s.vdb" >"$TMP/s.vdb.json"
check "vdb: BoolGrid voxels, active = voxels_inside" jq -e --argjson n "$N_IN" \
    '.grids | length == 1 and .[0].name == "voxels" and .[0].type == "bool" and .[0].active_voxels == $n' "$TMP/s.vdb.json"
check "vdb: transform scale h, index (0,0,0) at the first centre" jq -e --slurpfile j "$TMP/job.json" \
    '.grids[0].transform as $t | $j[0].stats as $s | $t.linear and ($t.voxel_size | all(. == $s.voxel_size)) and ([range(3)] | all(($t.translation[.] - ($s.origin[.] + $s.voxel_size / 2)) | fabs < 1e-9))' "$TMP/s.vdb.json"
check "vdb: active bbox inside the grid" jq -e --slurpfile j "$TMP/job.json" \
    '.grids[0].bbox as $b | $j[0].stats.dims as $d | ($b[0] | all(. >= 0)) and ([range(3)] | all($b[1][.] < $d[.]))' "$TMP/s.vdb.json"
check "vdb: metadata" jq -e --slurpfile j "$TMP/job.json" \
    '.grids[0].metadata as $m | $j[0] as $j | $m.method == $j.stats.method and $m.inside == "nonzero" and $m.mesh == $j.mesh and $m.dims == $j.stats.dims and $m.supersample == 1' "$TMP/s.vdb.json"

# Supersampling is slicing's (auto picks slice for it).
if [[ " ${METHODS[*]} " == *" slice "* ]]; then
    vox "sphere vdb supersample 2" "$M_sphere" '{"resolution":24,"supersample":2,"threshold":4,"vdb_grid":"fog"}'
    check "supersample 2 ran slice" test "$(st method)" = slice
    fetch "$TMP/c.vdb"
    "$VX_TOOLS/vdbinfo" "$TMP/c.vdb" >"$TMP/c.vdb.json"
    check "vdb coverage: FloatGrid, active >= voxels_inside" jq -e --argjson n "$(st voxels_inside)" \
        '.grids[0].name == "coverage" and .grids[0].type == "float" and .grids[0].active_voxels >= $n and .grids[0].metadata.threshold == 4' "$TMP/c.vdb.json"
    near "supersample 2 volume" "$(st volume)" "$(vol sphere)" 0.05
fi

# The faces pattern: centre + six face centres, any method (auto: cpu).
vox "sphere vdb samples faces" "$M_sphere" '{"resolution":24,"supersample":2,"samples":"faces","threshold":1,"vdb_grid":"fog"}'
check "faces echoed, auto ran cpu" jq -e '.params.samples == "faces" and .params.threshold == 1 and .stats.method == "cpu"' "$TMP/job.json"
fetch "$TMP/f.vdb"
"$VX_TOOLS/vdbinfo" "$TMP/f.vdb" >"$TMP/f.vdb.json"
check "faces vdb: coverage in sevenths, active = voxels_inside at threshold 1" jq -e --argjson n "$(st voxels_inside)" \
    '.grids[0] | .name == "coverage" and .active_voxels == $n and .metadata.samples == "faces" and .metadata.threshold == 1' "$TMP/f.vdb.json"
N_FACES1=$(st voxels_inside)
vox "sphere samples faces by cpu" "$M_sphere" '{"resolution":24,"supersample":2,"samples":"faces","threshold":1,"method":"cpu","format":"summary"}'
check "faces by cpu: cpu ran, the same count" test "$(st method) $(st voxels_inside)" = "cpu $N_FACES1"
vox "sphere samples faces threshold 4" "$M_sphere" '{"resolution":24,"supersample":2,"samples":"faces","threshold":4,"format":"summary"}'
near "faces threshold 4 volume" "$(st volume)" "$(vol sphere)" 0.05
N_FACES4=$(st voxels_inside)
check "faces: threshold 1 sets more voxels than 4 ($N_FACES1 > $N_FACES4)" test "$N_FACES1" -gt "$N_FACES4"
vox "sphere samples faces with peel" "$M_sphere" '{"resolution":24,"supersample":2,"samples":"faces","threshold":4,"method":"peel","format":"summary"}'
check "faces with peel: peel ran on the four grids, same voxels as scan" jq -e --argjson n "$N_FACES4" \
    '.stats.method == "peel" and .stats.passes >= 4 and .stats.voxels_inside == $n' "$TMP/job.json"

vox "sphere binvox" "$M_sphere" '{"resolution":24,"format":"binvox"}'
fetch "$TMP/s.binvox"
check "binvox content type" test "$CTYPE" = application/x-binvox
D=$(jq -r '.stats.dims | max' "$TMP/job.json")
check "binvox header" test "$(head -c 200 "$TMP/s.binvox" | sed -n '1p;2p;5p' | tr '\n' '|')" = "#binvox 1|dim $D $D $D|data|"
check "binvox scale = d * h" awk -v s="$(sed -n 4p "$TMP/s.binvox" | cut -d' ' -f2)" -v w="$(awk -v d="$D" -v h="$H" 'BEGIN{print d*h}')" 'BEGIN{exit !((s-w)^2 < 1e-18)}'
check "binvox body: d^3 voxels, voxels_inside set" test "$(python3 - "$TMP/s.binvox" <<'PY'
import sys
d = open(sys.argv[1], "rb").read()
body = d[d.index(b"data\n") + 5:]
print(sum(body[i + 1] for i in range(0, len(body), 2)), sum(body[i + 1] for i in range(0, len(body), 2) if body[i]))
PY
)" = "$((D * D * D)) $N_IN"

vox "sphere raw1" "$M_sphere" '{"resolution":24,"format":"raw1"}'
fetch "$TMP/s.raw1"
check "raw1: ceil(n/8) bytes, popcount = voxels_inside" test "$(bits "$TMP/s.raw1")" = "$((($(nvox) + 7) / 8)) $N_IN"
vox "sphere raw8" "$M_sphere" '{"resolution":24,"format":"raw8"}'
fetch "$TMP/s.raw8"
check "raw1 = raw8 bit for bit" python3 -c '
import sys
r8 = open(sys.argv[1], "rb").read(); r1 = open(sys.argv[2], "rb").read()
sys.exit(any(((r1[i >> 3] >> (i & 7)) & 1) != r8[i] for i in range(len(r8))))' "$TMP/s.raw8" "$TMP/s.raw1"

vox "sphere surface" "$M_sphere" '{"resolution":24,"fill":"surface","format":"summary"}'
check "surface: a shell (0 < n < solid)" test "$(st voxels_inside)" -gt 0 -a "$(st voxels_inside)" -lt "$N_IN"

# A U-shaped prism whose caps are single concave 8-gons: ear-clipped, its
# surface is that of the same prism with the caps triangulated by hand (a
# fan from a cap's first corner would span the notch)
python3 - "$TMP" <<'PY'
import sys
U = [(0, 0), (3, 0), (3, 2), (2, 2), (2, 1), (1, 1), (1, 2), (0, 2)]
tris = [(0, 1, 4), (1, 2, 3), (1, 3, 4), (0, 4, 5), (0, 5, 7), (5, 6, 7)]
for name, caps in (("u_ngon", [list(range(8))]), ("u_tris", [list(t) for t in tris])):
    with open(f"{sys.argv[1]}/{name}.obj", "w") as f:
        for z in (0, 1):
            for x, y in U:
                f.write(f"v {x} {y} {z + 0.013}\n")
        for c in caps:
            f.write("f " + " ".join(str(i + 1) for i in reversed(c)) + "\n")  # bottom, facing -z
            f.write("f " + " ".join(str(i + 9) for i in c) + "\n")
        for i in range(8):
            j = (i + 1) % 8
            f.write(f"f {i + 1} {j + 1} {j + 9} {i + 9}\n")
PY
for u in u_ngon u_tris; do
    upload "$TMP/$u.obj"
    expect_status "upload $u" 201
    vox "$u surface" "$MESH_ID" '{"resolution":30,"fill":"surface","format":"summary"}'
    declare "S_$u=$(st voxels_inside)"
    vox "$u solid" "$MESH_ID" '{"resolution":30,"format":"summary"}'
    declare "V_$u=$(st voxels_inside)"
done
check "concave caps: the surface of the hand-triangulated prism ($S_u_tris)" test "$S_u_ngon" = "$S_u_tris"
check "concave caps: the same solid ($V_u_tris)" test "$V_u_ngon" = "$V_u_tris"

vox "sphere voxel_size" "$M_sphere" '{"voxel_size":0.1,"format":"summary"}'
check "voxel_size: 20 cells across" jq -e '.stats.dims == [20,20,20] and .stats.voxel_size == 0.1 and .params.resolution == null' "$TMP/job.json"

# --- bricks of a larger grid add up to the whole ---
vox "whole grid" "$M_sphere" '{"grid":{"origin":[-1.0625,-1.0625,-1.0625],"voxel_size":0.0625,"dims":[34,34,34]},"format":"summary"}'
WHOLE=$(st voxels_inside)
SUM=0
for bx in 0 1; do for by in 0 1; do for bz in 0 1; do
    o="[$(awk -v a=$bx -v b=$by -v c=$bz 'BEGIN{printf "%.17g,%.17g,%.17g", -1.0625+a*17*0.0625, -1.0625+b*17*0.0625, -1.0625+c*17*0.0625}')]"
    vox "brick $bx$by$bz" "$M_sphere" "{\"grid\":{\"origin\":$o,\"voxel_size\":0.0625,\"dims\":[17,17,17]},\"format\":\"summary\"}"
    SUM=$((SUM + $(st voxels_inside)))
done; done; done
check "bricks add up to the whole ($SUM vs $WHOLE)" test "$SUM" -eq "$WHOLE"
vox "non-cubic brick" "$M_sphere" '{"grid":{"origin":[-1,-0.5,0],"voxel_size":0.125,"dims":[16,8,4]},"format":"binvox"}'
fetch "$TMP/b.binvox"
check "non-cubic binvox padded to a cube of 16" test "$(sed -n 2p "$TMP/b.binvox")" = "dim 16 16 16"

# --- params errors: 422 invalid_params, the field named ---
bad() {
    local what=$1 params=$2 needle=$3
    api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$M_cube\",\"kind\":\"voxelize\",\"params\":$params}"
    expect_error "$what" 422 invalid_params
    check "$what: message names $needle ($(jqb .error.message))" bash -c "jq -r .error.message '$BODY' | grep -qF -- '$needle'"
}
bad "resolution 0" '{"resolution":0}' params.resolution
bad "resolution and voxel_size" '{"resolution":8,"voxel_size":0.1}' params.voxel_size
bad "grid and resolution" '{"resolution":8,"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[2,2,2]}}' params.grid
bad "grid with padding" '{"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[2,2,2]},"padding":1}' params.padding
bad "grid dims 0" '{"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[2,0,2]}}' 'params.grid.dims[1]'
# one job (bricks size 0, or a dense format: a .vdb past --brick-threshold
# runs as bricks, test_voxelize_bricks.sh)
bad "grid too many voxels" '{"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[4096,4096,4096]},"bricks":{"size":0}}' 2048^3
# binvox writes a cube of the longest axis: 4096 x 1 x 1 was 539 MB
bad "binvox of a 4096 x 1 x 1 grid" '{"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[4096,1,1]},"format":"binvox"}' "binvox pads it to a 4096^3 cube"
bad "grid over memory" '{"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[2048,2048,512]},"format":"raw1"}' "job memory limit"
bad "resolution over memory" '{"resolution":2048,"bricks":{"size":0}}' "job memory limit"
# a resolution is checked with the grid the mesh's box gives, not a cube:
# a flat plate at 3000 (3002 x 3002 x 3 with padding 1) runs; a cube at
# 3000 is over 2048^3
box_obj "$TMP/plate.obj" 0 0 0 1 1 0.0001
upload "$TMP/plate.obj"
M_plate=$MESH_ID
vox "flat plate at resolution 3000" "$M_plate" '{"resolution":3000,"padding":1,"format":"summary"}'
check "flat plate at 3000: dims 3002 x 3002 x 3 ($(jq -c .stats.dims "$TMP/job.json"))" \
    test "$(jq -c .stats.dims "$TMP/job.json")" = "[3002,3002,3]"
bad "cube at resolution 3000" '{"resolution":3000,"format":"summary"}' "2048^3 for one job"
bad "unknown method" '{"method":"magic"}' params.method
bad "unknown inside" '{"inside":"odd"}' params.inside
bad "threshold 9" '{"supersample":2,"threshold":9}' params.threshold
bad "supersample 3" '{"supersample":3}' params.supersample
bad "supersample 2 with peel" '{"supersample":2,"method":"peel"}' params.supersample
bad "supersample 2 with scan" '{"supersample":2,"method":"scan"}' params.supersample
bad "supersample 2 with cpu" '{"supersample":2,"method":"cpu"}' params.supersample
bad "fill surface with cpu" '{"fill":"surface","method":"cpu"}' params.method
bad "faces without supersample 2" '{"samples":"faces"}' params.samples
bad "faces threshold 8" '{"supersample":2,"samples":"faces","threshold":8}' params.threshold
bad "faces with fill surface" '{"supersample":2,"samples":"faces","fill":"surface"}' params.fill
# what cannot run is refused at submission, not failed as unsupported later
bad "fill surface with slice" '{"fill":"surface","method":"slice"}' params.fill
bad "fill surface with supersample 2 (auto slices)" '{"fill":"surface","supersample":2}' params.fill
bad "unknown samples" '{"supersample":2,"samples":"corners"}' params.samples
bad "unknown format" '{"format":"stl"}' params.format
bad "unknown field" '{"colour":"red"}' params.colour

# voxel_size: the dims come from the mesh; its stored box tells them at
# submission, so a grid over the memory limit is 422 naming the field.
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$M_cube\",\"kind\":\"voxelize\",\"params\":{\"voxel_size\":0.001}}"
expect_error "voxel_size over memory: 422 at submission" 422 invalid_params
check "naming params.voxel_size and the memory limit" \
    jq -e '.error.message | test("params.voxel_size.*job memory limit")' "$BODY"
# past 16384 voxels along an axis, however far: the same answer
for vs in 1e-6 5e-324; do
    api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$M_cube\",\"kind\":\"voxelize\",\"params\":{\"voxel_size\":$vs,\"format\":\"raw8\"}}"
    expect_error "voxel_size $vs: 422 at submission" 422 invalid_params
    check "voxel_size $vs: naming the 16384 per axis ($(jq -c .error "$BODY"))" \
        jq -e '.error.message | test("params.voxel_size .* gives .*16384")' "$BODY"
done

# resolution with padding past 16384 names the params given, not the
# voxel_size they make
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$M_cube\",\"kind\":\"voxelize\",\"params\":{\"resolution\":16384,\"padding\":1,\"format\":\"summary\"}}"
expect_error "resolution 16384 padding 1: 422 at submission" 422 invalid_params
check "resolution 16384 padding 1: naming both ($(jq -c .error "$BODY"))" \
    jq -e '.error.message | test("params.resolution 16384 with padding 1 gives 16386 .*16384")' "$BODY"

# A level set's memory follows the surface, not the grid: a 256^3 sphere
# (the worst case of every leaf partial would be ~470 MB) runs under 256M.
vox "sphere r256 level set" "$M_sphere" '{"resolution":256,"format":"vdb","vdb_grid":"level_set"}'
check "sphere r256 level set: succeeded with a .vdb" jq -e '.state == "succeeded" and (.outputs.voxels | endswith("/result/voxels"))' "$TMP/job.json"

# A 0/1 fog grid's leaves hold masks only (their floats are made as they
# are written): 64 plates 2 voxels thick, 8 voxels apart, make every leaf
# of a 512^3 grid partial (~1.2 GB as float leaves, over 256M), and the fog
# tree fits as the bool one does.
python3 - "$TMP/plates.obj" <<'EOF2'
import sys
with open(sys.argv[1], "w") as f:
    for p in range(64):
        z0, z1 = (8 * p + 1) / 512, (8 * p + 3) / 512
        b = 8 * p
        for x in (0, 1):
            for y in (0, 1):
                for z in (z0, z1):
                    f.write("v %g %g %g\n" % (x, y, z))
        # vertices b+1..b+8: (x, y, z) with z fastest
        for q in ((1, 5, 7, 3), (2, 4, 8, 6), (1, 2, 6, 5), (3, 7, 8, 4), (1, 3, 4, 2), (5, 6, 8, 7)):
            f.write("f %s\n" % " ".join(str(b + i) for i in q))
EOF2
upload "$TMP/plates.obj"
expect_status "upload plates" 201
M_plates=$MESH_ID
PG='"grid":{"origin":[0,0,0],"voxel_size":0.001953125,"dims":[512,512,512]}'
vox "plates fog 512^3" "$M_plates" "{$PG,\"format\":\"vdb\",\"vdb_grid\":\"fog\"}"
check "plates fog: 64 plates of 2 voxels" test "$(st voxels_inside)" = $((64 * 2 * 512 * 512))
vox "plates bool 512^3" "$M_plates" "{$PG,\"format\":\"vdb\",\"vdb_grid\":\"bool\"}"
check "plates: 64 plates of 2 voxels" test "$(st voxels_inside)" = $((64 * 2 * 512 * 512))

# A .vdb needs a voxel of at least ~1.44e-5 (OpenVDB's transforms refuse
# h^3 under 3e-15); the other formats have no such bound. A tetrahedron of
# edge 1e-4 at resolution 32 (h 3.1e-6) is 422 as vdb at submission (the
# mesh's box gives h), runs as raw8; explicit voxel sizes under the bound
# are 422 too; edge 4.7e-4 (h 1.47e-5, just over) writes a .vdb.
tet_obj "$TMP/tiny.obj" 1e-4
upload "$TMP/tiny.obj"
expect_status "upload tiny" 201
M_tiny=$MESH_ID
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$M_tiny\",\"kind\":\"voxelize\",\"params\":{\"resolution\":32,\"format\":\"vdb\"}}"
expect_error "tiny vdb: 422 at submission, from the mesh's box" 422 invalid_params
check "naming params.resolution and the voxel size" \
    jq -e '.error.message | test("params.resolution gives a voxel size")' "$BODY"
vox "tiny raw8" "$M_tiny" '{"resolution":32,"format":"raw8"}'
check "tiny raw8: voxels set" test "$(st voxels_inside)" -gt 0
bad "vdb voxel_size 1e-6" '{"voxel_size":1e-6,"format":"vdb"}' params.voxel_size
bad "vdb grid voxel_size 1e-6" '{"grid":{"origin":[0,0,0],"voxel_size":1e-6,"dims":[4,4,4]}}' params.grid.voxel_size
# ...and a level set's 3-voxel background must be a finite float: an
# explicit voxel_size over FLT_MAX / 3 is 422. Meshes stop at 1e30, so one
# at the bound voxelizes as fog and level set at resolution 1.
box_obj "$TMP/huge.obj" -1e38 -1e38 -1e38 1e38 1e38 1e38
upload "$TMP/huge.obj"
expect_error "upload a cube at 1e38" 422 coordinate_out_of_range
box_obj "$TMP/huge.obj" -1e30 -1e30 -1e30 1e30 1e30 1e30
upload "$TMP/huge.obj"
expect_status "upload huge" 201
M_huge=$MESH_ID
vox "huge level set" "$M_huge" '{"resolution":1,"format":"vdb","vdb_grid":"level_set"}'
vox "huge fog" "$M_huge" '{"resolution":1,"format":"vdb","vdb_grid":"fog"}'
vox "huge level set at resolution 2 (h 1e30)" "$M_huge" '{"resolution":2,"format":"vdb","vdb_grid":"level_set"}'
bad "level set voxel_size 2e38" '{"grid":{"origin":[0,0,0],"voxel_size":2e38,"dims":[2,2,2]},"format":"vdb","vdb_grid":"level_set"}' params.grid.voxel_size

# Vertices no face uses (left over in an OBJ): outside the mesh's bbox and
# every grid made from it, and one far away (past 2^50 voxels of the grid)
# bothers neither CPU engine; the same voxels as the mesh without them.
{ cat "$TMP/sphere.obj"; printf 'v 100 100 100\nv 1e20 -1e20 1e20\n'; } >"$TMP/stray.obj"
upload "$TMP/stray.obj"
expect_status "upload a sphere with two unused vertices" 201
M_stray=$MESH_ID
check "its bbox holds the used vertices only ($(jqb -c .bbox))" \
    jq -e '([.bbox.max[] | . <= 1.0001] | all) and ([.bbox.min[] | . >= -1.0001] | all)' "$BODY"
check "its vertices count them all" test "$(jqb .vertices)" -eq "$(grep -c '^v ' "$TMP/stray.obj")"
run_job preview "$M_sphere" '{"width":64,"height":64}'
PX=$(st pixels_covered)
run_job preview "$M_stray" '{"width":64,"height":64}'
check "unused vertices: the preview frames the same sphere ($PX pixels, got $(st pixels_covered))" \
    test "$(st pixels_covered)" = "$PX" -a "$PX" -gt 1000
for p in '"method":"cpu"' '"inside":"winding"' '"method":"scan"' '"method":"peel"' '"method":"slice"'; do
    vox "sphere ($p)" "$M_sphere" "{\"resolution\":32,\"format\":\"raw1\",$p}"
    A=$(st voxels_inside) DA=$(jq -c .stats.dims "$TMP/job.json")
    vox "sphere with unused vertices ($p)" "$M_stray" "{\"resolution\":32,\"format\":\"raw1\",$p}"
    check "unused vertices: the same grid and voxels ($p: $A in $DA, got $(st voxels_inside) in $(jq -c .stats.dims "$TMP/job.json"))" \
        test "$(st voxels_inside)-$(jq -c .stats.dims "$TMP/job.json")" = "$A-$DA"
done
# Faces on planes of centres of a lattice whose origin and voxel size are
# not binary fractions: the half-open [entry, exit) tie along every axis,
# 3 x 3 x 3, with every method (it was 18: a layer lost along the rays).
box_obj "$TMP/ctr.obj" -0.15 -0.15 -0.15 0.15 0.15 0.15
upload "$TMP/ctr.obj"
M_ctr=$MESH_ID
for p in '"method":"cpu"' '"inside":"winding"' '"method":"scan"' '"method":"peel"' '"method":"slice"' '"method":"peel","inside":"robust"'; do
    vox "box on centre planes ($p)" "$M_ctr" "{\"grid\":{\"origin\":[-0.2,-0.2,-0.2],\"voxel_size\":0.1,\"dims\":[4,4,4]},\"format\":\"summary\",$p}"
    check "box on centre planes ($p): 27 voxels (got $(st voxels_inside))" test "$(st voxels_inside)" = 27
done
tet_obj "$TMP/small.obj" 4.7e-4
upload "$TMP/small.obj"
vox "small vdb (h just over the bound)" "$MESH_ID" '{"resolution":32,"format":"vdb"}'

# Rays through many surfaces: N boxes side by side along x, 2N depth
# layers a ray, each box around one voxel centre (faces a quarter voxel
# away): N x 16 x 16 voxels. Peeling holds as many layers as the GL's array
# textures (2048 on llvmpipe; it gave up at 256 before); past that, auto
# slices instead.
stack_obj() { # FILE N
    python3 - "$1" "$2" <<'PY'
import sys
path, n = sys.argv[1], int(sys.argv[2])
with open(path, "w") as f:
    for i in range(n):
        b = 8 * i
        for x in (i + 0.25, i + 0.75):
            for y in (0.3, 15.7):
                for z in (0.4, 15.6):
                    f.write(f"v {x!r} {y!r} {z!r}\n")
        for q in ((1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)):
            f.write("f %d %d %d %d\n" % tuple(b + v for v in q))
PY
}
for n in 150 1100; do
    stack_obj "$TMP/stack$n.obj" $n
    upload "$TMP/stack$n.obj"
    M_stack=$MESH_ID
    G="{\"origin\":[0,0,0],\"voxel_size\":1,\"dims\":[$n,16,16]}"
    vox "$n boxes along x ($((2 * n)) layers), auto robust" "$M_stack" "{\"grid\":$G,\"inside\":\"robust\",\"format\":\"summary\"}"
    check "$n boxes, auto robust: $((n * 256)) voxels (got $(st voxels_inside) by $(st method))" \
        test "$(st voxels_inside)" = $((n * 256))
    if [[ $n == 150 ]]; then
        check "300 layers: peeled" test "$(st method)" = peel
    else
        check "2200 layers (past llvmpipe's 2048): sliced" test "$(st method)" = slice
        run_job voxelize "$M_stack" "{\"grid\":$G,\"inside\":\"robust\",\"method\":\"peel\",\"format\":\"summary\"}"
        check "2200 layers, method peel asked for: fails too_many_layers" \
            jq -e '.state == "failed" and .error.code == "too_many_layers"' "$TMP/job.json"
    fi
done
stop_daemon

# The layers a ray needs within the GL's limit but past the job's memory
# (300 layers of 128^2 rays: 64 MiB at the next doubling): auto slices too.
stack_obj "$TMP/stack150.obj" 150
start_daemon --max-job-memory 64M || exit 1
upload "$TMP/stack150.obj"
G='{"origin":[0,0,0],"voxel_size":1,"dims":[150,128,128]}'
vox "300 layers past --max-job-memory 64M, auto robust" "$MESH_ID" "{\"grid\":$G,\"inside\":\"robust\",\"format\":\"summary\"}"
check "past the job's memory: sliced, $((150 * 256)) voxels (got $(st voxels_inside) by $(st method))" \
    test "$(st method) $(st voxels_inside)" = "slice $((150 * 256))"

stop_daemon
finish
