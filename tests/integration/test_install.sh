#!/usr/bin/env bash
# cmake --install into a temp prefix: voxeld, voxelctl, the unit (ExecStart at
# the prefix), the example config, the man pages (which document every flag
# of --help), and the installed voxelctl --local finding the installed voxeld.
source "$(dirname "$0")/lib.sh"
BUILD=$(dirname "$VOXELD")
P=$TMP/prefix
cmake --install "$BUILD" --prefix "$P" >"$TMP/install.log" 2>&1
rc=$?
check "cmake --install exits 0 ($(tail -n 1 "$TMP/install.log"))" test $rc -eq 0
for f in bin/voxeld bin/voxelctl lib/systemd/system/voxeld.service \
    share/doc/voxeld/voxeld.conf.example share/doc/voxeld/systemd/dropin-config.conf \
    share/doc/voxeld/examples/voxeld_client.py share/man/man8/voxeld.8 share/man/man1/voxelctl.1; do
    check "installed $f" test -s "$P/$f"
    # what `xargs rm < install_manifest.txt` removes
    check "install_manifest.txt lists $f" grep -qx "$P/$f" "$BUILD/install_manifest.txt"
done
extra=$(cd "$P" && find . -type f \( -name 'test_*' -o -name '*bench*' -o -name 'fuzz_*' -o -name '*.a' \
    -o -name '*.so*' -o -name '*.h' -o -name 'pngstat' -o -name 'params_spec' \) | tr '\n' ' ')
check "no tests, benchmarks, tools or libraries installed ($extra)" test -z "$extra"
check "the unit runs the installed voxeld" grep -qx "ExecStart=$P/bin/voxeld --listen 127.0.0.1:8080" "$P/lib/systemd/system/voxeld.service"
check "the drop-in runs the installed voxeld" grep -qx "ExecStart=$P/bin/voxeld --config /etc/voxeld/voxeld.conf" "$P/share/doc/voxeld/systemd/dropin-config.conf"
check "installed voxeld --version" sh -c "'$P/bin/voxeld' --version | grep -q '^voxeld '"
check "installed voxelctl --version" sh -c "'$P/bin/voxelctl' --version | grep -q '^voxelctl '"

# The man pages render and name every option --help lists.
if command -v man >/dev/null; then
    for m in man8/voxeld.8 man1/voxelctl.1; do
        MANWIDTH=80 man --warnings -l "$P/share/man/$m" >"$TMP/man.txt" 2>"$TMP/man.err"
        check "$m renders without warnings ($(head -c 200 "$TMP/man.err"))" sh -c "test -s '$TMP/man.txt' && test ! -s '$TMP/man.err'"
    done
fi
missing=
for flag in $("$VOXELD" --help | grep -oE '^  --[a-z-]+' | tr -d ' '); do
    grep -qF -- "$(sed 's/-/\\-/g' <<<"$flag")" "$P/share/man/man8/voxeld.8" || missing+=" $flag"
done
check "voxeld.8 documents every flag of voxeld --help (missing:$missing)" test -z "$missing"
missing=
for flag in $("$P/bin/voxelctl" --help | grep -oE -- '--[a-z-]+' | sort -u); do
    grep -qF -- "$(sed 's/-/\\-/g' <<<"$flag")" "$P/share/man/man1/voxelctl.1" || missing+=" $flag"
done
check "voxelctl.1 documents every option of voxelctl --help (missing:$missing)" test -z "$missing"

# The installed client finds the installed daemon for --local.
cd "$TMP"
mkdir -p ltmp
TMPDIR=$TMP/ltmp "$P/bin/voxelctl" --local --quiet preview "$VX_MESH_DIR/suzanne.obj" -p width=32 -p height=32 -o p.png 2>ctl.err
check "installed voxelctl --local ($(cat ctl.err))" sh -c "head -c 8 p.png | od -An -c | grep -q 'P   N   G'"
finish
