#!/usr/bin/env bash
# Formats every C/C++ file of the tree with the repo's .clang-format
# (clang-format 14, Debian 12), or with --check fails listing the files
# whose formatting differs (scripts/check.sh runs that first).
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.c' '*.h' '*.cc' '*.hh' '*.cpp' '*.hpp')
if [[ "${1:-}" == "--check" ]]; then
    bad=()
    for f in "${files[@]}"; do
        clang-format --dry-run -Werror "$f" >/dev/null 2>&1 || bad+=("$f")
    done
    if ((${#bad[@]})); then
        echo "format: ${#bad[@]} files differ from .clang-format (run scripts/format.sh):" >&2
        printf '  %s\n' "${bad[@]}" >&2
        exit 1
    fi
    echo "format: ${#files[@]} files clean"
else
    clang-format -i "${files[@]}"
fi
