#!/usr/bin/env bash
# Bricked voxelize (issue 15, single node): params.bricks {size} runs the
# grid as bricks of one lattice (grid.index_offset), one after another, and
# merges them with OpenVDB's tree merge into one pruned .vdb, or lists them
# in a manifest with merge false. Checked here:
# - 2x2x2 bricks of the bunny (bool, fog, level set) and of a generated
#   torus on random lattices (origin and voxel size not binary fractions,
#   random index offsets, random brick sizes) equal the same grid as one
#   job voxel by voxel (vdbcheck against the one job's raw8), with the one
#   job's transform;
# - the stats list the bricks (offset, dims, voxels_inside, ms) and sum;
# - a 200^3 level set as 27 bricks has the one job's band;
# - --brick-threshold bricks a large .vdb by default; bricks {size: 0} opts out;
# - the manifest lists every brick's URL and index offset; each brick file
#   holds its voxels at its offset of the whole grid's index space;
# - admission follows one brick: a grid refused as one job under
#   --max-job-memory is accepted as bricks;
# - bad brick sizes and combinations are 422.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
BUNNY="$VX_MESH_DIR/stanford-bunny.obj"
[[ -f "$BUNNY" ]] || { echo "skip: $BUNNY missing"; exit 77; }
mkdir -p "$TMP/shapes"
python3 "$VX_SOURCE_DIR/tests/integration/shapes.py" "$TMP/shapes" >/dev/null
start_daemon --brick-threshold 200000 || exit 1
upload "$BUNNY"
expect_status "upload bunny" 201
B=$MESH_ID
upload "$TMP/shapes/torus.obj"
expect_status "upload torus" 201
T=$MESH_ID

# get_result NAME FILE: the job's result NAME (or the primary one).
get_result() {
    api GET "/v1/jobs/$JOB/result${1:+/$1}"
    cp "$BODY" "$2"
}

# whole MESH PARAMS: one job's raw8 of the grid (bricks {size: 0}); sets
# NX NY NZ ORIGIN H IDX and $TMP/whole.raw.
whole() {
    run_job voxelize "$1" "$(jq -c '. + {format: "raw8"}' <<<"$2")"
    job_ok "one job $2"
    read -r NX NY NZ < <(jq -r '.stats.dims | map(tostring) | join(" ")' "$TMP/job.json")
    ORIGIN=$(jq -c .stats.origin "$TMP/job.json")
    H=$(jq -r .stats.voxel_size "$TMP/job.json")
    get_result "" "$TMP/whole.raw"
    WHOLE_INSIDE=$(st voxels_inside)
}

# bricked MESH PARAMS WHAT: the same params as bricks to .vdb, checked
# against $TMP/whole.raw voxel by voxel.
bricked() {
    run_job voxelize "$1" "$2"
    job_ok "$3"
    check "$3: stats list the bricks and sum them" jq -e '
        (.stats.bricks | length) == (.stats.brick_grid | .[0] * .[1] * .[2]) and
        .stats.bricks_done == (.stats.bricks | length) and
        ([.stats.bricks[].voxels_inside] | add) == .stats.voxels_inside and
        all(.stats.bricks[]; (.offset | length) == 3 and (.dims | length) == 3 and .ms >= 0) and
        .progress == 1' "$TMP/job.json"
    check "$3: as many voxels as one job" test "$(st voxels_inside)" = "$WHOLE_INSIDE"
    get_result "" "$TMP/b.vdb"
    check "$3: equals the one job voxel by voxel" "$VX_TOOLS/vdbcheck" "$TMP/b.vdb" "$TMP/whole.raw" "$NX" "$NY" "$NZ"
}

# The bunny, 2x2x2 bricks: S = ceil(max dim / 2) up to a multiple of 8.
P='{"resolution":60,"padding":2}'
whole "$B" "$P"
S=$(((((NX > NY ? (NX > NZ ? NX : NZ) : (NY > NZ ? NY : NZ)) + 1) / 2 + 7) / 8 * 8))
for g in bool fog level_set; do
    bricked "$B" "$(jq -c ". + {format: \"vdb\", vdb_grid: \"$g\", bricks: {size: $S}}" <<<"$P")" "bunny $g 2x2x2 bricks of $S"
    check "bunny $g: 8 bricks" jq -e '.stats.brick_grid == [2,2,2] and .stats.brick_size == '"$S" "$TMP/job.json"
    cp "$TMP/b.vdb" "$TMP/bunny_$g.vdb"
done
# the same transform and tree as one job's .vdb
run_job voxelize "$B" "$(jq -c '. + {format: "vdb", vdb_grid: "bool", bricks: {size: 0}}' <<<"$P")"
job_ok "bunny bool one job"
check "bricks {size: 0} is one job" jq -e '.stats.bricks == null' "$TMP/job.json"
get_result "" "$TMP/one.vdb"
"$VX_TOOLS/vdbinfo" "$TMP/one.vdb" | jq -c '.grids[0] | {transform, active_voxels, bbox, name, meta: (.metadata | keys)}' >"$TMP/one.json"
"$VX_TOOLS/vdbinfo" "$TMP/bunny_bool.vdb" | jq -c '.grids[0] | {transform, active_voxels, bbox, name, meta: (.metadata | keys)}' >"$TMP/bb.json"
check "bricked .vdb: same transform, bbox, voxels and metadata keys as one job's" cmp "$TMP/one.json" "$TMP/bb.json"

# A level set of nested spheres at 200^3 as one job and as 3x3x3 bricks of
# 72 (the merged tree's interior is tiles): the same band.
upload "$TMP/shapes/nested.obj"
expect_status "upload nested spheres" 201
N=$MESH_ID
for b in 0 72; do
    run_job voxelize "$N" "{\"resolution\":200,\"format\":\"vdb\",\"vdb_grid\":\"level_set\",\"bricks\":{\"size\":$b}}"
    job_ok "nested spheres level set, bricks of $b"
    get_result "" "$TMP/ls$b.vdb"
    "$VX_TOOLS/vdbinfo" "$TMP/ls$b.vdb" | jq -c '.grids[0] | {transform, active_voxels, value_sum, bbox, name, meta: (.metadata | keys)}' >"$TMP/ls$b.json"
done
check "bricked level set: 27 bricks" jq -e '.stats.brick_grid == [3,3,3]' "$TMP/job.json"
check "bricked level set: the one job's band (voxels, value sum, bbox, metadata keys)" cmp "$TMP/ls0.json" "$TMP/ls72.json"
check "the level set has a band" jq -e '.active_voxels > 100000' "$TMP/ls0.json"

# A generated torus on random lattices: origin and voxel size not binary
# fractions, random index offsets and brick sizes, every method.
seed=${VX_SEED:-$RANDOM}
echo "seed $seed"
RANDOM=$seed
methods=(scan peel slice)
for t in 0 1 2; do
    ox=$(python3 -c "import random; random.seed($seed + $t); print(-1.5 - random.random() * 0.1)")
    h=$(python3 -c "import random; random.seed($seed * 7 + $t); print(0.03 + random.random() * 0.01)")
    nx=$(python3 -c "import math; print(math.ceil(3.1 / $h))")
    nz=$(python3 -c "import math; print(math.ceil(1.0 / $h))")
    ix=$((RANDOM % 2000 - 1000)) iy=$((RANDOM % 2000 - 1000)) iz=$((RANDOM % 2000 - 1000))
    # index_offset i puts the box's voxel 0 at origin + i h: shift the
    # origin back so the box still covers the torus
    grid=$(python3 -c "print('{\"origin\":[%r,%r,%r],\"voxel_size\":%r,\"dims\":[$nx,$nx,$nz],\"index_offset\":[$ix,$iy,$iz]}' % ($ox - $ix * $h, $ox - $iy * $h, -0.51 - $iz * $h, $h))")
    m=${methods[$((RANDOM % 3))]}
    P="{\"grid\":$grid,\"method\":\"$m\"}"
    whole "$T" "$P"
    S=$((8 * (1 + RANDOM % 8)))
    bricked "$T" "$(jq -c ". + {format: \"vdb\", vdb_grid: \"fog\", bricks: {size: $S}}" <<<"$P")" "torus $m dims $NX,$NY,$NZ offset $ix,$iy,$iz bricks of $S"
    check "torus $t: index_offset echoed" jq -e ".stats.index_offset == [$ix,$iy,$iz] and .stats.bricks[0].index_offset == [$ix,$iy,$iz]" "$TMP/job.json"
done
# The box's last voxel at lattice index 2^40 exactly, as bricks: each
# brick's index_offset within the limit (422 past it, below)
ix=$((1099511627776 - 99))
P=$(python3 -c "print('{\"grid\":{\"origin\":[%r,-1.55,-0.52],\"voxel_size\":0.03125,\"dims\":[100,100,33],\"index_offset\":[$ix,0,0]}}' % (-1.55 - $ix * 0.03125))")
whole "$T" "$P"
bricked "$T" "$(jq -c '. + {format: "vdb", vdb_grid: "fog", bricks: {size: 64}}' <<<"$P")" "torus ending at index 2^40, bricks of 64"

api GET /v1/info
check "info: limits.brick_threshold_cells is the flag's" jq -e '.limits.brick_threshold_cells == 200000' "$BODY"
# --brick-threshold: a .vdb over 200000 cells bricks by default (512^3
# bricks), a raw8 does not.
run_job voxelize "$B" '{"resolution":64,"format":"vdb","vdb_grid":"bool"}'
job_ok "bunny 64 vdb past the threshold"
check "bricked by default: one 512 brick" jq -e '.stats.brick_size == 512 and .stats.brick_grid == [1,1,1]' "$TMP/job.json"
run_job voxelize "$B" '{"resolution":64,"format":"raw8"}'
check "raw8 past the threshold: one job" jq -e '.state == "succeeded" and .stats.bricks == null' "$TMP/job.json"

# merge false: a manifest of the brick files.
whole "$B" '{"resolution":48}'
run_job voxelize "$B" '{"resolution":48,"format":"vdb","vdb_grid":"bool","bricks":{"size":16},"merge":false}'
job_ok "manifest"
check "manifest: the primary output" jq -e '(.outputs | keys_unsorted[0]) == "manifest" and (.outputs | length) == 1 + (.stats.bricks | length)' "$TMP/job.json"
get_result "" "$TMP/manifest.json"
check "manifest: grid, brick size and one entry per brick" jq -e --slurpfile j "$TMP/job.json" '
    .brick_size == 16 and .grid.dims == $j[0].stats.dims and .grid.voxel_size == $j[0].stats.voxel_size and
    (.bricks | length) == ($j[0].stats.bricks | length) and
    all(.bricks[]; (.url | startswith("/v1/jobs/" + $j[0].id + "/result/brick_")) and (.index_offset | length) == 3)' "$TMP/manifest.json"
total=0 bad=0
while read -r url ox oy oz dx dy dz; do
    api GET "$url"
    [[ $STATUS == 200 ]] || bad=$((bad + 1))
    "$VX_TOOLS/vdbinfo" "$BODY" >"$TMP/bi.json" || bad=$((bad + 1))
    a=$(jq -r '.grids[0].active_voxels' "$TMP/bi.json")
    total=$((total + a))
    if ((a > 0)); then
        jq -e ".grids[0].bbox[0][0] >= $ox and .grids[0].bbox[0][1] >= $oy and .grids[0].bbox[0][2] >= $oz and
               .grids[0].bbox[1][0] < $ox + $dx and .grids[0].bbox[1][1] < $oy + $dy and .grids[0].bbox[1][2] < $oz + $dz and
               .grids[0].metadata.brick_offset == [$ox,$oy,$oz]" "$TMP/bi.json" >/dev/null || bad=$((bad + 1))
    fi
done < <(jq -r '.bricks[] | [.url, .offset[], .dims[]] | map(tostring) | join(" ")' "$TMP/manifest.json")
check "manifest: every brick file downloads and holds its voxels in its box ($bad bad)" test "$bad" -eq 0
check "manifest: the bricks hold the one job's voxels ($total)" test "$total" = "$WHOLE_INSIDE"

# vdb_index_base: one brick of the grid above as its own job, written in the
# whole grid's index space (the manifest's brick files' layout).
read -r bx by bz < <(jq -r '.bricks[1].index_offset | map(tostring) | join(" ")' "$TMP/manifest.json")
read -r dx dy dz < <(jq -r '.bricks[1].dims | map(tostring) | join(" ")' "$TMP/manifest.json")
G=$(jq -c '.grid' "$TMP/manifest.json")
run_job voxelize "$B" "$(jq -nc --argjson g "$G" --argjson o "[$bx,$by,$bz]" --argjson d "[$dx,$dy,$dz]" \
    '{grid: {origin: $g.origin, voxel_size: $g.voxel_size, dims: $d, index_offset: $o}, format: "vdb",
      vdb_grid: "bool", bricks: {size: 0}, vdb_index_base: $g.index_offset}')"
job_ok "one brick with vdb_index_base"
get_result "" "$TMP/based.vdb"
"$VX_TOOLS/vdbinfo" "$TMP/based.vdb" >"$TMP/based.json"
api GET "$(jq -r '.bricks[1].url' "$TMP/manifest.json")"
"$VX_TOOLS/vdbinfo" "$BODY" >"$TMP/b1.json"
check "vdb_index_base: the brick's voxels at its place in the grid's index space, as the manifest's brick file" \
    bash -c "jq -e --slurpfile m '$TMP/b1.json' '.grids[0] | .active_voxels == \$m[0].grids[0].active_voxels and .bbox == \$m[0].grids[0].bbox and .transform == \$m[0].grids[0].transform' '$TMP/based.json'"

# Errors.
bad() {
    api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":$2}"
    expect_error "$1" 422 invalid_params
    check "$1: message has '$3'" bash -c "jq -r .error.message '$BODY' | grep -qF -- '$3'"
}
bad "size not a multiple of 8" '{"bricks":{"size":12}}' "multiple of 8"
bad "negative size" '{"bricks":{"size":-8}}' "params.bricks.size"
bad "size too large" '{"bricks":{"size":16392}}' "params.bricks.size"
bad "brick over one job" '{"grid":{"origin":[0,0,0],"voxel_size":1,"dims":[4096,4096,4096]},"bricks":{"size":4096}}' "over one job"
bad "size not a number" '{"bricks":{"size":"big"}}' "params.bricks.size"
bad "bricks not an object" '{"bricks":64}' "params.bricks"
bad "unknown brick field" '{"bricks":{"edge":64}}' "edge"
bad "bricks of a dense format" '{"bricks":{"size":64},"format":"raw8"}' 'params.format "vdb"'
bad "merge false without bricks" '{"merge":false}' "params.merge false needs params.bricks"
bad "manifest of level sets" '{"bricks":{"size":64},"merge":false,"vdb_grid":"level_set"}' "fog or bool"
bad "dense format past one job" '{"resolution":4096,"format":"raw1"}' "2048^3 for one job"
bad "vdb_index_base off the leaf grid" '{"grid":{"origin":[0,0,0],"voxel_size":0.1,"dims":[8,8,8],"index_offset":[4,0,0]},"bricks":{"size":0},"vdb_index_base":[0,0,0]}' "multiple of 8"
bad "vdb_index_base with a dense format" '{"grid":{"origin":[0,0,0],"voxel_size":0.1,"dims":[8,8,8]},"bricks":{"size":0},"format":"raw8","vdb_index_base":[0,0,0]}' 'params.format "vdb"'
bad "vdb_index_base past 32-bit coordinates" '{"grid":{"origin":[0,0,0],"voxel_size":0.1,"dims":[16,16,16],"index_offset":[2147483640,0,0]},"bricks":{"size":0},"vdb_index_base":[0,0,0]}' "outside +-2^30"
bad "vdb_index_base far below" '{"grid":{"origin":[0,0,0],"voxel_size":0.1,"dims":[16,16,16],"index_offset":[0,-1099511627776,0]},"bricks":{"size":0},"vdb_index_base":[0,0,0]}' "axis 1"
bad "a box past 1e30" '{"grid":{"origin":[0,0,0],"voxel_size":1e300,"dims":[4,4,4],"index_offset":[1099511627773,0,0]}}' "outside +-1e30"
# every voxel's index within 2^40, not only the first: the last brick of
# a box from 2^40 - 7 was an index_offset past it, the job failed after
# its first brick (bricked or one job alike: 422 at submission)
bad "a box past index 2^40" '{"grid":{"origin":[0,0,0],"voxel_size":0.5,"dims":[9,6,7],"index_offset":[1099511627772,0,0]},"bricks":{"size":8}}' "index_offset[0] + dims[0] - 1 is 1099511627780"
bad "one job past index 2^40" '{"grid":{"origin":[0,0,0],"voxel_size":0.5,"dims":[9,6,7],"index_offset":[0,0,1099511627772]},"format":"raw1"}' "within +-2^40"
bad "an origin of 1e308" '{"grid":{"origin":[1e308,0,0],"voxel_size":1,"dims":[4,4,4]}}' "outside +-1e30"
# Voxels so small that the bunny reaches 10^19 of them from the origin:
# no engine can run it (the cpu and winding ones failed the job
# invalid_params, peel too_many_layers). At 1e-15 it is 1.8e14 of them,
# under 2^50, and cpu runs it.
for extra in '' ',"method":"cpu"' ',"method":"peel"' ',"inside":"winding"'; do
    bad "voxels of 1e-20$extra" '{"grid":{"origin":[0.1,0.2,0.3],"voxel_size":1e-20,"dims":[2,2,2]},"format":"summary"'"$extra"'}' "more than 2^50 voxels"
done
run_job voxelize "$B" '{"grid":{"origin":[-0.02,0.1,0],"voxel_size":1e-15,"dims":[2,2,2]},"format":"summary","method":"cpu"}'
job_ok "voxels of 1e-15 inside the bunny"
check "voxels of 1e-15 inside the bunny: all 8 set (got $(st voxels_inside))" test "$(st voxels_inside)" = 8
# The GL methods' float positions: the faces the box's rays cross lie
# 5e4 voxels away at 1e-6 and 5e11 at 1e-13, past the 2^15 where they are
# exact: refused (peel set 0 of these 8 voxels at 1e-13, scan 1 to 4 at
# 1e-12); cpu runs them. At 1e-5 (5e3 voxels) every method runs.
tiny() { echo "{\"grid\":{\"origin\":[-0.02,0.1,0],\"voxel_size\":$1,\"dims\":[2,2,2]},\"format\":\"summary\"$2}"; }
for m in peel scan slice; do
    for h in 1e-13 1e-6; do
        run_job voxelize "$B" "$(tiny $h ",\"method\":\"$m\"")"
        check "voxels of $h, $m: failed invalid_params on the faces past 2^15 voxels ($(jq -c .error "$TMP/job.json"))" \
            jq -e '.state == "failed" and .error.code == "invalid_params" and (.error.message | test("more than 2\\^15 voxels away.*method cpu"))' "$TMP/job.json"
    done
done
for m in cpu peel scan slice; do
    for h in 1e-13 1e-6 1e-5; do
        [[ $m != cpu && $h != 1e-5 ]] && continue
        run_job voxelize "$B" "$(tiny $h ",\"method\":\"$m\"")"
        job_ok "voxels of $h, $m"
        check "voxels of $h, $m: all 8 set (got $(st voxels_inside))" test "$(st voxels_inside)" = 8
    done
done
bad "more than 65,536 bricks" '{"grid":{"origin":[0,0,0],"voxel_size":0.01,"dims":[16384,2048,512]},"bricks":{"size":8}}' "over the 65536 a grid may have"
bad "vdb_index_base without a grid" '{"resolution":32,"bricks":{"size":0},"vdb_index_base":[0,0,0]}' "params.grid"

# An origin 16 digits long (1e12 - 0.125 less one ulp, 1.2e-4): the centres
# of slab 0 sit 1/2048 voxel outside the box [1e12, 1e12 + 2.9] x
# [1e12, 1e12 + 3]^2 (beyond the 2^-20-voxel snap of a crossing). The job,
# its bricks, its echo and reuse must all keep that double (cJSON's printer
# gave 15 digits, 999999999999.875: bricks set the slab, and reuse answered
# the other job).
box_obj "$TMP/box3.obj" 1e12 1e12 1e12 1000000000002.9 1000000000003 1000000000003
upload "$TMP/box3.obj"
near='{"origin":[999999999999.8749,999999999999.9,999999999999.9],"voxel_size":0.25,"dims":[16,16,16]}'
for size in 0 8; do
    run_job voxelize "$MESH_ID" "{\"grid\":$near,\"vdb_grid\":\"bool\",\"bricks\":{\"size\":$size}}"
    job_ok "origin of 16 digits, bricks $size"
    check "origin of 16 digits, bricks $size: 11 x 12 x 12 voxels (got $(st voxels_inside))" test "$(st voxels_inside)" = 1584
    check "origin of 16 digits, bricks $size: echoed exactly" jq -e '.params.grid.origin[0] == 999999999999.8749 and .stats.origin[0] == 999999999999.8749' "$TMP/job.json"
done
NEAR=$JOB
run_job voxelize "$MESH_ID" '{"grid":{"origin":[999999999999.875,999999999999.9,999999999999.9],"voxel_size":0.25,"dims":[16,16,16]},"vdb_grid":"bool","bricks":{"size":8}}'
check "origin 999999999999.875: 12 x 12 x 12 voxels, another job" jq -e --arg j "$NEAR" '.id != $j and .stats.voxels_inside == 1728' "$TMP/job.json"
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"voxelize\",\"reuse\":true,\"params\":{\"grid\":$near,\"vdb_grid\":\"bool\",\"bricks\":{\"size\":8}}}"
cp "$BODY" "$TMP/job.json"
check "reuse of the 16-digit origin answers its own job" jq -e --arg j "$NEAR" '.id == $j' "$TMP/job.json"
stop_daemon

# Admission follows one brick: under 64M a 1024^3 box is refused as one
# job and accepted as bricks of 128 (then canceled).
start_daemon --max-job-memory 64M || exit 1
upload "$BUNNY"
B=$MESH_ID
box='{"origin":[-0.1,0.03,-0.07],"voxel_size":0.0002,"dims":[1024,1024,1024]}'
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"grid\":$box,\"vdb_grid\":\"bool\",\"bricks\":{\"size\":0}}}"
expect_error "one job over the memory limit" 422 invalid_params
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"grid\":$box,\"vdb_grid\":\"bool\",\"bricks\":{\"size\":128}}}"
expect_status "bricks of 128 under the memory limit" 202
JOB=$(jqb .id)
api DELETE "/v1/jobs/$JOB"
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"grid\":$box,\"vdb_grid\":\"bool\",\"bricks\":{\"size\":1024}}}"
expect_error "one brick over the memory limit" 422 invalid_params
check "message names the brick" bash -c "jq -r .error.message '$BODY' | grep -qF 'brick needs about'"
stop_daemon
finish
