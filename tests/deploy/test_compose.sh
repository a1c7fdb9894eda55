#!/usr/bin/env bash
# docker-compose.yaml, read offline (no container engine is run here: the
# image itself is built and started by test_container.sh):
# - the single node is the default service; the cluster (PostgreSQL, MinIO,
#   its bucket, two replicas) is the "cluster" profile;
# - the replicas' database URL names the postgres service with its user,
#   password and database; their blob store names the minio service and the
#   bucket minio-bucket makes, with MinIO's root credentials;
# - they wait for a healthy database and a made bucket, and differ in name,
#   host port and volume;
# - each replica's environment and command are options voxeld accepts
#   (its configuration is loaded: --list-egl-devices).
source "$(dirname "$0")/../integration/lib.sh"
F=$VX_SOURCE_DIR/docker-compose.yaml
python3 - "$F" >"$TMP/compose.json" <<'PY' || { echo "cannot read $F"; exit 1; }
import json, sys, yaml
print(json.dumps(yaml.safe_load(open(sys.argv[1]))))
PY
q() { jq -e "$1" "$TMP/compose.json" >/dev/null 2>&1; }
check "the single node is the default service (no profile), on 8080" \
    q '.services.voxeld | (.profiles == null) and (.ports | any(test(":8080:8080$")))'
for s in postgres minio minio-bucket voxeld-1 voxeld-2; do
    check "$s is in the cluster profile" q ".services[\"$s\"].profiles == [\"cluster\"]"
done
for r in voxeld-1 voxeld-2; do
    R=".services[\"$r\"]"
    check "$r: its database is the postgres service, with its user, password and db" q \
        "(.services.postgres.environment) as \$p | $R.environment.VOXELD_DATABASE == \"postgresql://\(\$p.POSTGRES_USER):\(\$p.POSTGRES_PASSWORD)@postgres:5432/\(\$p.POSTGRES_DB)\""
    check "$r: its blob store is minio's bucket that minio-bucket makes" q \
        "$R.environment.VOXELD_BLOB_STORE as \$u | (\$u | startswith(\"s3://voxeld/\")) and (\$u | test(\"endpoint=http://minio:9000\")) and (.services[\"minio-bucket\"].command[0] | test(\"mc mb --ignore-existing local/voxeld\"))"
    check "$r: MinIO's root credentials" q \
        "(.services.minio.environment) as \$m | $R.environment.AWS_ACCESS_KEY_ID == \$m.MINIO_ROOT_USER and $R.environment.AWS_SECRET_ACCESS_KEY == \$m.MINIO_ROOT_PASSWORD"
    check "$r: waits for a healthy database and a made bucket" q \
        "$R.depends_on.postgres.condition == \"service_healthy\" and $R.depends_on[\"minio-bucket\"].condition == \"service_completed_successfully\" and (.services.postgres.healthcheck.test | length > 0)"
    check "$r: builds the image" q "$R.build == \".\" and $R.image == \"voxeld\""
done
check "the replicas differ in name, host port and volume" q \
    '[.services["voxeld-1","voxeld-2"] | [.command[1], .ports[0], .volumes[0]]] | .[0] as $a | .[1] as $b | all(range(3); $a[.] != $b[.])'
check "every named volume is declared" q \
    '[.services[].volumes[]? | split(":")[0]] - (.volumes | keys) == []'

# Each replica's options, as the container gets them, are accepted.
for r in voxeld-1 voxeld-2; do
    mapfile -t envs < <(jq -r ".services[\"$r\"].environment | to_entries[] | \"\(.key)=\(.value)\"" "$TMP/compose.json")
    mapfile -t args < <(jq -r ".services[\"$r\"].command[]" "$TMP/compose.json")
    check "$r: voxeld accepts its environment and command" \
        env "${envs[@]}" "$VOXELD" --data-dir "$TMP/d-$r" "${args[@]}" --list-egl-devices
done
finish
