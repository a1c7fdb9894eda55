# box_obj FILE X0 Y0 Z0 X1 Y1 Z1: writes an axis-aligned box as 6 quads.
box_obj() {
    local f=$1 x0=$2 y0=$3 z0=$4 x1=$5 y1=$6 z1=$7
    cat >"$f" <<OBJ
v $x0 $y0 $z0
v $x1 $y0 $z0
v $x1 $y1 $z0
v $x0 $y1 $z0
v $x0 $y0 $z1
v $x1 $y0 $z1
v $x1 $y1 $z1
v $x0 $y1 $z1
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
OBJ
}
# tet_obj FILE SCALE: a tetrahedron, edges SCALE along the axes from 0.
tet_obj() {
    printf 'v %s 0 0\nv 0 %s 0\nv 0 0 %s\nv 0 0 0\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n' "$2" "$2" "$2" >"$1"
}
