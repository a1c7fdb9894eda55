#!/usr/bin/env bash
# deploy/kubernetes, offline (issue #15): every overlay is rendered with
# `kubectl kustomize` (which reads files only; no cluster is ever contacted:
# KUBECONFIG points at an empty file), every object is validated against the
# Kubernetes and KEDA schemas (tools/k8s-validate), and the properties that
# matter are asserted on the rendered objects: probes on the daemon's own
# routes and port, the GPU request and --require-gpu on nvidia, a grace
# period at least the job timeout, the KEDA trigger (min replicas >= 1), the
# security context, LP_NUM_THREADS within the CPU request (llvmpipe would
# size itself to the node) and that every reference resolves. Each single-replica
# overlay's options (ConfigMap + container env + args) are then given to the
# real voxeld here (llvmpipe): cpu must become ready, nvidia must answer
# /readyz 503 naming the software renderer. A corrupted render must fail
# validation (the validator is not a no-op).
# Exit 77 (skipped) without kubectl (Kustomize v4+), node, or
# tools/k8s-validate/node_modules (scripts/install-deps.sh).
source "$(dirname "$0")/../integration/lib.sh"

K8S=$VX_SOURCE_DIR/deploy/kubernetes
VALIDATOR=$VX_SOURCE_DIR/tools/k8s-validate
for tool in node jq curl; do
    if ! command -v "$tool" >/dev/null; then
        echo "SKIP: $tool is not installed"
        exit 77
    fi
done
export KUBECONFIG=$TMP/no-kubeconfig
: >"$KUBECONFIG"
# kubectl's built-in Kustomize (v4+: `labels`, components), else a standalone one.
KVER=$(kubectl version --client 2>/dev/null | sed -n 's/^Kustomize Version: v\([0-9]*\).*/\1/p')
if [[ -n "$KVER" && "$KVER" -ge 4 ]]; then
    KUSTOMIZE=(kubectl kustomize)
elif command -v kustomize >/dev/null && [[ $(kustomize version 2>/dev/null | sed -n 's/^v\{0,1\}\([0-9]*\).*/\1/p' | head -n 1) -ge 4 ]] 2>/dev/null; then
    KUSTOMIZE=(kustomize build)
else
    echo "SKIP: no kubectl with Kustomize v4+ nor kustomize v4+ (Debian 12's kubernetes-client 1.20 has v2)"
    exit 77
fi
if [[ ! -d "$VALIDATOR/node_modules/kubernetes-models" ]]; then
    echo "SKIP: $VALIDATOR/node_modules is missing (scripts/install-deps.sh runs npm ci there)"
    exit 77
fi

# The daemon's flags, as environment variable names (voxeld --help lists them).
FLAGS_ENV=$("$VOXELD" --help | sed -n 's/^  --\([a-z0-9-]*\) .*/\1/p' |
    tr 'a-z-' 'A-Z_' | sed 's/^/VOXELD_/' | sort -u)
# Flags of the database mode (issue #15) that the manifests already set;
# until they exist voxeld ignores these variables (README "Kubernetes").
PENDING_ENV="VOXELD_DATABASE VOXELD_BLOB_STORE"
check "voxeld --help lists its flags" test "$(wc -l <<<"$FLAGS_ENV")" -gt 20
check "the daemon serves /livez and /readyz" grep -q '"/livez"' "$VX_SOURCE_DIR/daemon/request.c"

# ---- the validator rejects what is invalid -------------------------------------------
mapfile -t OVERLAYS < <(for d in "$K8S"/overlays/*/; do basename "$d"; done | LC_ALL=C sort)
check "overlays cpu, nvidia, cpu-cluster, nvidia-cluster exist (${OVERLAYS[*]})" \
    test "${OVERLAYS[*]}" = "cpu cpu-cluster nvidia nvidia-cluster"
"${KUSTOMIZE[@]}" "$K8S/overlays/cpu" >"$TMP/cpu.yaml" 2>"$TMP/kustomize.err"
sed 's/containerPort: 8080/containerPort: http/' "$TMP/cpu.yaml" >"$TMP/broken-port.yaml"
sed 's/^  replicas: 1$/  replicas: one/' "$TMP/cpu.yaml" >"$TMP/broken-replicas.yaml"
sed 's/^kind: PodDisruptionBudget$/kind: PodDisruptionBudgett/' "$TMP/cpu.yaml" >"$TMP/broken-kind.yaml"
for b in port replicas kind; do
    check "the corruption ($b) changed the render" bash -c "! cmp -s '$TMP/cpu.yaml' '$TMP/broken-$b.yaml'"
    rc=0
    node "$VALIDATOR/validate.mjs" "$TMP/broken-$b.yaml" >"$TMP/broken-$b.out" 2>&1 || rc=$?
    check "a render with a broken $b fails validation (rc $rc)" test "$rc" -eq 1
    check "... naming the object" grep -q '^INVALID' "$TMP/broken-$b.out"
done
cat >"$TMP/broken-keda.yaml" <<'EOF'
apiVersion: keda.sh/v1alpha1
kind: ScaledObject
metadata:
  name: x
spec:
  minReplicaCount: "one"
  triggers: []
EOF
rc=0
node "$VALIDATOR/validate.mjs" "$TMP/broken-keda.yaml" >/dev/null 2>&1 || rc=$?
check "an invalid KEDA ScaledObject (no scaleTargetRef, string count) fails validation" test "$rc" -eq 1

# ---- every overlay ------------------------------------------------------------------
# q OVERLAY FILTER: jq over the overlay's objects (a JSON array), -e.
q() { jq -e "$2" "$TMP/$1.json" >/dev/null 2>&1; }
DEPLOY='(.[] | select(.kind == "Deployment"))'
CTR="($DEPLOY | .spec.template.spec.containers[0])"
# The container's environment, from the ConfigMaps it reads and its env.
CENV="(. as \$all | $CTR | ([.envFrom[]?.configMapRef.name // empty] as \$cms
  | [\$all[] | select(.kind == \"ConfigMap\" and (.metadata.name | IN(\$cms[]))) | .data // {}] | add)
  + ([.env[]? | select(.value) | {(.name): .value}] | add // {}))"

for o in "${OVERLAYS[@]}"; do
    rc=0
    "${KUSTOMIZE[@]}" "$K8S/overlays/$o" >"$TMP/$o.yaml" 2>"$TMP/$o.err" || rc=$?
    check "$o: ${KUSTOMIZE[*]} renders it (rc $rc: $(head -c 200 "$TMP/$o.err"))" test "$rc" -eq 0
    rc=0
    node "$VALIDATOR/validate.mjs" --json "$TMP/$o.json" "$TMP/$o.yaml" >"$TMP/$o.valid" 2>&1 || rc=$?
    check "$o: every object is valid ($(grep -m1 INVALID "$TMP/$o.valid"))" test "$rc" -eq 0
    for kind in ConfigMap Secret Service Deployment PodDisruptionBudget; do
        check "$o: has a $kind" q "$o" "any(.[]; .kind == \"$kind\")"
    done
    check "$o: one Deployment with one container" q "$o" "([.[] | select(.kind == \"Deployment\")] | length) == 1 and ($DEPLOY | .spec.template.spec.containers | length) == 1"

    # Probes on the daemon's routes, on the port it listens on: the
    # ConfigMap's VOXELD_LISTEN, as the image's ENTRYPOINT flags are replaced.
    check "$o: the command is voxeld alone (no ENTRYPOINT --listen/--data-dir over the ConfigMap)" \
        q "$o" "$CTR | .command == [\"voxeld\"] and ((.args // []) | all(test(\"^--(listen|data-dir)\") | not))"
    PORT=$(jq -r "$CENV | .VOXELD_LISTEN // \"\" | capture(\":(?<p>[0-9]+)\$\").p" "$TMP/$o.json" 2>/dev/null)
    check "$o: VOXELD_LISTEN listens on all addresses (got $(jq -r "$CENV | .VOXELD_LISTEN" "$TMP/$o.json"))" \
        q "$o" "$CENV | .VOXELD_LISTEN | test(\"^(0\\\\.0\\\\.0\\\\.0|\\\\[::\\\\]):[0-9]+\$\")"
    for p in livenessProbe:/livez readinessProbe:/readyz startupProbe:/livez; do
        probe=${p%%:*} path=${p#*:}
        check "$o: $probe is GET $path" q "$o" "$CTR | .$probe.httpGet.path == \"$path\""
        check "$o: $probe's port is the daemon's ($PORT)" q "$o" \
            "$CTR | .$probe.httpGet.port as \$pp | [.ports[] | select(.name == \$pp or .containerPort == \$pp) | .containerPort] == [$PORT]"
    done
    # The endpoints drop a terminating pod some seconds after its SIGTERM;
    # voxeld closes its port at SIGTERM, so the pod waits first.
    check "$o: a preStop sleep of 5 s or more, within the grace period" q "$o" \
        "($DEPLOY | .spec.template.spec.terminationGracePeriodSeconds) as \$g | $CTR | .lifecycle.preStop.exec.command | .[0] == \"sleep\" and (.[1] | tonumber) >= 5 and (.[1] | tonumber) < \$g"
    check "$o: the startup probe allows at least a minute" q "$o" \
        "$CTR | .startupProbe | (.periodSeconds // 10) * (.failureThreshold // 3) >= 60"
    check "$o: the Service targets that port" q "$o" \
        "(.[] | select(.kind == \"Service\") | .spec.ports[0].targetPort) as \$t | $CTR | [.ports[] | select(.name == \$t or .containerPort == \$t) | .containerPort] == [$PORT]"
    check "$o: the Service and the PDB select the pods" q "$o" \
        "($DEPLOY | .spec.template.metadata.labels) as \$l | all(.[] | select(.kind == \"Service\" or .kind == \"PodDisruptionBudget\") | (.spec.selector.matchLabels // .spec.selector) | to_entries[]; \$l[.key] == .value)"

    # Grace period >= the job timeout (flag over environment, default 600).
    TIMEOUT=$(jq -r "$CENV | .VOXELD_JOB_TIMEOUT // \"600\"" "$TMP/$o.json")
    ARGT=$(jq -r "$CTR | .args // [] | (index(\"--job-timeout\") as \$i | if \$i then .[\$i + 1] else empty end)" "$TMP/$o.json")
    TIMEOUT=${ARGT:-$TIMEOUT}
    check "$o: terminationGracePeriodSeconds >= the job timeout ($TIMEOUT s)" q "$o" \
        "$DEPLOY | .spec.template.spec.terminationGracePeriodSeconds >= ($TIMEOUT | tonumber)"

    # Options: every VOXELD_ variable is a flag (or a pending database-mode one).
    for k in $(jq -r "$CENV | keys[] | select(startswith(\"VOXELD_\"))" "$TMP/$o.json"); do
        check "$o: $k is a voxeld flag" bash -c "grep -qx '$k' <<<'$FLAGS_ENV' || [[ ' $PENDING_ENV ' == *' $k '* ]]"
    done

    # Resources and security context.
    check "$o: memory requested and limited, CPU requested" q "$o" \
        "$CTR | .resources.requests.memory and .resources.limits.memory and .resources.requests.cpu"
    # llvmpipe sizes its thread pool from the node's CPUs, not the pod's
    # share: every overlay bounds it to at most the CPUs the pod requests.
    LP=$(jq -r "$CENV | .LP_NUM_THREADS // \"unset\"" "$TMP/$o.json")
    check "$o: LP_NUM_THREADS ($LP) is a whole number from 1 to the CPU request" q "$o" \
        "($CTR | .resources.requests.cpu | tostring | if endswith(\"m\") then (.[:-1] | tonumber) / 1000 else tonumber end) as \$cpu | $CENV | .LP_NUM_THREADS | test(\"^[1-9][0-9]*\$\") and (tonumber <= \$cpu)"
    check "$o: non-root, no privilege escalation, capabilities dropped, read-only root" q "$o" \
        "($DEPLOY | .spec.template.spec.securityContext.runAsNonRoot == true) and ($CTR | .securityContext | .allowPrivilegeEscalation == false and .readOnlyRootFilesystem == true and (.capabilities.drop | index(\"ALL\")))"
    for dir in VOXELD_DATA_DIR VOXELD_CACHE_DIR; do
        D=$(jq -r "$CENV | .$dir // empty" "$TMP/$o.json")
        check "$o: $dir ($D) is a writable volume" q "$o" \
            "$CTR | any(.volumeMounts[]; .mountPath == \"$D\" and (.readOnly | not))"
    done
    check "$o: /tmp is a writable volume (read-only root)" q "$o" "$CTR | any(.volumeMounts[]; .mountPath == \"/tmp\")"
    TOKEN_FILE=$(jq -r "$CENV | .VOXELD_TOKEN_FILE // empty" "$TMP/$o.json")
    check "$o: the token file ($TOKEN_FILE) is a Secret's key" q "$o" \
        ". as \$all | ($DEPLOY | .spec.template.spec) as \$s | \$s.containers[0].volumeMounts[] | select(.mountPath as \$m | \"$TOKEN_FILE\" | startswith(\$m + \"/\")) | .name as \$v | \$s.volumes[] | select(.name == \$v) | .secret | .secretName as \$n | (.items[]? | select(.path == (\"$TOKEN_FILE\" | split(\"/\") | last)) | .key) as \$k | any(\$all[]; .kind == \"Secret\" and .metadata.name == \$n and (.data[\$k] != null))"
    check "$o: every ConfigMap/Secret/PVC the pod names is in the render" q "$o" \
        ". as \$all | ($DEPLOY | .spec.template.spec) | [(.containers[0].envFrom[]? | (.configMapRef.name // .secretRef.name)), (.volumes[] | (.secret.secretName // .persistentVolumeClaim.claimName // empty))] | all(. as \$n | any(\$all[]; .metadata.name == \$n))"

    # GPU or not.
    if [[ $o == nvidia* ]]; then
        check "$o: limits nvidia.com/gpu to 1 (one pod per GPU)" q "$o" \
            "$CTR | (.resources.limits[\"nvidia.com/gpu\"] | tostring) == \"1\" and ((.resources.requests[\"nvidia.com/gpu\"] // 1) | tostring) == \"1\""
        check "$o: NVIDIA_DRIVER_CAPABILITIES has graphics (EGL) and compute" q "$o" \
            "$CENV | .NVIDIA_DRIVER_CAPABILITIES | split(\",\") | index(\"graphics\") and index(\"compute\")"
        check "$o: --require-gpu yes (or VOXELD_REQUIRE_GPU)" q "$o" \
            "($CTR | .args // [] | (index(\"--require-gpu\") as \$i | \$i and (.[\$i + 1] | IN(\"yes\", \"true\", \"1\")))) or ($CENV | .VOXELD_REQUIRE_GPU // \"\" | IN(\"yes\", \"true\", \"1\"))"
    else
        check "$o: asks for no GPU" q "$o" "$CTR | (.resources.limits[\"nvidia.com/gpu\"] == null)"
    fi

    # Cluster (database mode, KEDA) or one replica on the local store.
    if [[ $o == *-cluster ]]; then
        SO='(.[] | select(.kind == "ScaledObject"))'
        check "$o: has a KEDA ScaledObject" q "$o" "any(.[]; .kind == \"ScaledObject\" and .apiVersion == \"keda.sh/v1alpha1\")"
        check "$o: minReplicaCount >= 1" q "$o" "$SO | .spec.minReplicaCount >= 1"
        check "$o: maxReplicaCount >= minReplicaCount" q "$o" "$SO | .spec.maxReplicaCount >= .spec.minReplicaCount"
        check "$o: it scales the Deployment" q "$o" \
            "($DEPLOY | .metadata.name) as \$d | $SO | .spec.scaleTargetRef | .name == \$d and .kind == \"Deployment\""
        check "$o: one postgresql trigger counting queued + running jobs" q "$o" \
            "$SO | .spec.triggers | length == 1 and .[0].type == \"postgresql\" and (.[0].metadata.query | test(\"FROM vx_jobs \") and test(\"'queued'\") and test(\"'running'\")) and (.[0].metadata.targetQueryValue | tonumber > 0)"
        check "$o: the trigger's connectionFromEnv comes from a Secret the container reads" q "$o" \
            ". as \$all | ($SO | .spec.triggers[0].metadata.connectionFromEnv) as \$e | $CTR | [.envFrom[]?.secretRef.name // empty] | any(. as \$n | \$all[] | select(.kind == \"Secret\" and .metadata.name == \$n) | .data[\$e] != null)"
        for k in VOXELD_DATABASE AWS_ACCESS_KEY_ID AWS_SECRET_ACCESS_KEY; do
            check "$o: $k comes from a Secret" q "$o" \
                ". as \$all | $CTR | [.envFrom[]?.secretRef.name // empty] | any(. as \$n | \$all[] | select(.kind == \"Secret\" and .metadata.name == \$n) | .data.$k != null)"
        done
        check "$o: VOXELD_BLOB_STORE is set (ConfigMap)" q "$o" "$CENV | .VOXELD_BLOB_STORE | startswith(\"s3://\")"
        check "$o: no replicas in the Deployment (KEDA's HPA sets them; an apply would undo a scale-out)" q "$o" \
            "$DEPLOY | .spec | has(\"replicas\") | not"
        check "$o: no PVC, a rolling update" q "$o" \
            "(any(.[]; .kind == \"PersistentVolumeClaim\") | not) and ($DEPLOY | .spec.strategy.type == \"RollingUpdate\")"
        if [[ $o == nvidia-* ]]; then
            # every GPU is taken by a pod: a surge pod would stay Pending
            check "$o: the rolling update takes an old pod first (no surge pod waiting for a GPU)" q "$o" \
                "$DEPLOY | .spec.strategy.rollingUpdate | .maxSurge == 0 and .maxUnavailable == 1"
        else
            check "$o: the rolling update surges (no gap)" q "$o" \
                "$DEPLOY | .spec.strategy.rollingUpdate | .maxSurge == 1 and .maxUnavailable == 0"
        fi
        check "$o: no cooldownPeriod (KEDA uses it only to scale to zero)" q "$o" \
            "$SO | (.spec.cooldownPeriod == null) and .spec.minReplicaCount >= 1"
    else
        check "$o: no ScaledObject (one replica on the local store)" q "$o" "any(.[]; .kind == \"ScaledObject\") | not"
        check "$o: one replica, Recreate (voxeld locks its data dir)" q "$o" \
            "$DEPLOY | .spec.replicas == 1 and .spec.strategy.type == \"Recreate\""
        D=$(jq -r "$CENV | .VOXELD_DATA_DIR" "$TMP/$o.json")
        check "$o: the data dir is the PVC" q "$o" \
            "($DEPLOY | .spec.template.spec) as \$s | \$s.containers[0].volumeMounts[] | select(.mountPath == \"$D\") | .name as \$v | \$s.volumes[] | select(.name == \$v) | .persistentVolumeClaim.claimName as \$c | \$c != null"
    fi
done

# ---- a user's overlay sets the image as the README says ----------------------------------
mkdir -p "$TMP/my-overlay"
cat >"$TMP/my-overlay/kustomization.yaml" <<EOF
resources:
  - $(realpath --relative-to="$TMP/my-overlay" "$K8S/overlays/nvidia")
images:
  - name: $(sed -n 's/^ *kustomize edit set image \([^=]*\)=.*/\1/p' "$K8S/README.md" | head -n 1)
    newName: myreg.example/team/voxeld
    newTag: "1.2.3"
EOF
"${KUSTOMIZE[@]}" "$TMP/my-overlay" >"$TMP/my-overlay.yaml" 2>&1
check "the README's image override takes ($(grep -m1 'image:' "$TMP/my-overlay.yaml"))" \
    grep -q '^ *image: myreg.example/team/voxeld:1.2.3$' "$TMP/my-overlay.yaml"

# ---- the options of the single-replica overlays, given to the real voxeld -----------------
# The pod's environment (ConfigMap + env) and args, with the paths and the
# port moved into this test's temp dir; the token decoded from the Secret.
POD_OVERRIDES=()
run_pod_options() {
    local o=$1
    local dir=$TMP/pod-$o
    mkdir -p "$dir"
    jq -r ". as \$all | ($DEPLOY | .spec.template.spec) as \$s | \$s.volumes[] | select(.secret) | .secret.secretName as \$n | \$all[] | select(.kind == \"Secret\" and .metadata.name == \$n) | .data.token" \
        "$TMP/$o.json" | tr -d '\n' | base64 -d >"$dir/token"
    local envs=() args=()
    mapfile -t envs < <(jq -r "$CENV | to_entries[] | \"\(.key)=\(.value)\"" "$TMP/$o.json")
    mapfile -t args < <(jq -r "$CTR | .args // [] | .[]" "$TMP/$o.json")
    # The pod's variables for this one start (start_daemon's own --listen,
    # --data-dir, --workers and --http-threads flags win over them).
    local kv ok=0
    for kv in "${envs[@]}" "${POD_OVERRIDES[@]}"; do export "${kv?}"; done
    export VOXELD_CACHE_DIR="$dir/cache" VOXELD_TOKEN_FILE="$dir/token" MESA_SHADER_CACHE_DIR="$dir/cache/mesa"
    DATA=$dir/data
    start_daemon "${args[@]}" && ok=1
    for kv in "${envs[@]}" "${POD_OVERRIDES[@]}"; do unset "${kv%%=*}"; done
    unset VOXELD_CACHE_DIR VOXELD_TOKEN_FILE MESA_SHADER_CACHE_DIR
    check "$o: voxeld starts with the pod's options" test "$ok" -eq 1
    [[ $ok -eq 1 ]] || return
    TOKEN=$(cat "$dir/token")
}
run_pod_options cpu
if [[ -n "$PID" ]]; then
    api GET /readyz
    expect_status "cpu: the pod's /readyz on llvmpipe" 200
    api GET /livez
    expect_status "cpu: the pod's /livez" 200
    api GET /v1/info
    expect_status "cpu: /v1/info with the Secret's token" 200
    CPU_TIMEOUT=$(jq -r "$CENV | .VOXELD_JOB_TIMEOUT // \"600\"" "$TMP/cpu.json")
    check "cpu: the daemon's job timeout is the ConfigMap's ($CPU_TIMEOUT s, which the grace period covers)" \
        jq -e --argjson t "$CPU_TIMEOUT" '.limits.job_timeout_s == $t' "$BODY"
    check "cpu: auth is on" jq -e '.auth == true' "$BODY"
    TOKEN=
    api GET /v1/info
    expect_status "cpu: /v1/info without the token" 401
    stop_daemon
fi
# The cpu-cluster pod's options, its Secret's placeholders (the database, the
# bucket) pointed at a PostgreSQL started here and a shared dir: the pod is
# ready with the database.
PGSH="$VX_SOURCE_DIR/tests/support/pg.sh"
if [[ -x /usr/lib/postgresql/15/bin/initdb ]]; then
    PGDIR=$(mktemp -d /tmp/vxpg.XXXXXX)
    if PGURL=$(bash "$PGSH" start "$PGDIR"); then
        check "cpu-cluster: the Secret holds VOXELD_DATABASE" q cpu-cluster \
            '. as $all | [$all[] | select(.kind == "Secret") | .data.VOXELD_DATABASE // empty] | length == 1'
        POD_OVERRIDES=("VOXELD_DATABASE=$PGURL" "VOXELD_BLOB_STORE=file://$TMP/pod-shared")
        mkdir -p "$TMP/pod-shared"
        run_pod_options cpu-cluster
        POD_OVERRIDES=()
        if [[ -n "$PID" ]]; then
            api GET /readyz
            expect_status "cpu-cluster: the pod's /readyz with the database" 200
            check "cpu-cluster: readyz names the database and the file store" \
                jq -e '.database.ok == true and .blob_store.backend == "file"' "$BODY"
            stop_daemon
            # The KEDA query on the tables the daemon made (it stopped:
            # nobody claims these rows): a queued and a
            # running job, and a bricked parent waiting for its 2 queued
            # bricks count 4 (the parent is no work yet); once the bricks
            # succeeded, 3 (the parent's merge is).
            KQ=$(jq -r "$SO | .spec.triggers[0].metadata.query" "$TMP/cpu-cluster.json")
            psql "$PGURL" -qAtc "INSERT INTO vx_jobs (id, kind, state, max_attempts, children, parent_id) VALUES
                ('$(printf 'a%.0s' {1..32})', 'voxelize', 'queued', 3, 0, NULL),
                ('$(printf 'b%.0s' {1..32})', 'voxelize', 'running', 3, 0, NULL),
                ('$(printf 'c%.0s' {1..32})', 'voxelize', 'queued', 3, 2, NULL),
                ('$(printf 'c%.0s' {1..31})1', 'voxelize', 'queued', 3, 0, '$(printf 'c%.0s' {1..32})'),
                ('$(printf 'c%.0s' {1..31})2', 'voxelize', 'queued', 3, 0, '$(printf 'c%.0s' {1..32})')" >/dev/null 2>&1
            n1=$(psql "$PGURL" -qAtc "$KQ" 2>&1)
            psql "$PGURL" -qAtc "UPDATE vx_jobs SET state = 'succeeded' WHERE parent_id IS NOT NULL" >/dev/null 2>&1
            n2=$(psql "$PGURL" -qAtc "$KQ" 2>&1)
            check "cpu-cluster: the KEDA query counts runnable work (4 then 3: got $n1, $n2)" test "$n1,$n2" = "4,3"
        fi
        bash "$PGSH" stop "$PGDIR" >/dev/null 2>&1
    else
        check "PostgreSQL for the cpu-cluster pod starts" false
    fi
    rm -rf "$PGDIR"
else
    echo "note: no PostgreSQL server: the cpu-cluster pod's options are not run"
fi
# On a machine whose EGL has only Mesa's software device (this one), the
# nvidia pod's options must make it unready; with a GPU that part is skipped.
if "$VOXELD" --list-egl-devices 2>/dev/null | awk '$2 == "nvidia" || $2 == "hardware" {f = 1} END {exit !f}'; then
    echo "note: this machine's EGL has a hardware device: the nvidia pod's refusal is not run"
else
    run_pod_options nvidia
    if [[ -n "$PID" ]]; then
        api GET /readyz
        expect_status "nvidia: the pod's /readyz on llvmpipe (--require-gpu)" 503
        check "nvidia: the reason names the software renderer" \
            jq -e '.checks.gpu == false and (.reason | test("llvmpipe|softpipe|swrast"; "i"))' "$BODY"
        api GET /livez
        expect_status "nvidia: /livez stays 200 (not restarted, only unready)" 200
        stop_daemon
    fi
fi
finish
