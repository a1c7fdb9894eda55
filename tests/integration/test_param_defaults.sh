#!/usr/bin/env bash
# Defaults are range-checked at submission (issue #10, defect 7): a job is
# answered 202 only when its normalised params, defaults filled in, are
# what the runner accepts; never 202 and then a run-time invalid_params.
# render with N above 256 and no R had R = 8 N > 2048: 202, then failed
# with "params.R must be in [258, 2048], got 2064".
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon || exit 1
box_obj "$TMP/box.obj" 0 0 0 1 1 1
upload "$TMP/box.obj"
BOX=$MESH_ID
post_render() {
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$BOX\",\"kind\":\"render\",\"params\":$1}"
}

# N = 300: L defaults to 3 (L N <= 1024), R to 2048; with the default
# 4 GiB job memory that is too much: 422 at submission, naming the params.
post_render '{"N":300}'
expect_error "render N=300 without R" 422 invalid_params
check "the 422 names params.R" jq -e '.error.message | test("params\\.R")' "$BODY"

# N = 258, L = 2: fits; 202, and then it runs (R = 2048), not a run-time
# invalid_params. Canceled once it has been running for a moment.
post_render '{"N":258,"L":2}'
expect_status "render N=258 L=2 without R" 202
J=$(jqb .id)
check "normalised R within its range" jq -e '.params.R == 2048 and .params.L == 2' "$BODY"
ran=0
for i in $(seq 1 60); do
    api GET "/v1/jobs/$J"
    st=$(jqb .state)
    [[ "$st" == failed || "$st" == succeeded || "$st" == canceled ]] && break
    if [[ "$st" == running ]]; then ran=$((ran + 1)); [[ $ran -ge 5 ]] && break; fi
    sleep 0.2
done
check "N=258 does not fail when it runs ($(jqb -c .error))" test "$st" = running
api DELETE "/v1/jobs/$J"
wait_job "$J" 60
check "N=258 canceled, not failed ($(jqb -c .error))" jq -e '.state == "canceled"' "$BODY"
stop_daemon
finish
