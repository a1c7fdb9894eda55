/* The mesh catalog in PostgreSQL (pg.h, vx_pg_mesh_*): the table vx_meshes
 * says which meshes exist for the API of every replica; the blob store
 * holds their bytes. A deleted mesh keeps its row (deleted set) until no
 * unfinished job names it; then vx_pg_mesh_purge removes row and bytes
 * together, under an advisory lock that uploads of the same id share. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jobs/pg_int.h"
#include "util/log.h"
#include "util/json.h"

/* The advisory lock of mesh $1 (uploads take it shared, the purge alone). */
#define MESH_LOCK_KEY "hashtextextended('vx_mesh:' || $1, 0)"

int vx_pg_mesh_lock(vx_pg *pg, const char *id, vx_err *err)
{
    const char *vals[] = {id};
    if (pg_lock(pg, err)) return -1;
    int rc =
        pg_exec_locked(pg, 1, "SELECT pg_advisory_lock_shared(" MESH_LOCK_KEY ")", 1, vals, err);
    pthread_mutex_unlock(&pg->lock);
    return rc;
}

void vx_pg_mesh_unlock(vx_pg *pg, const char *id)
{
    const char *vals[] = {id};
    pthread_mutex_lock(&pg->lock);
    /* A lost connection released it already: nothing to say then. */
    pg_exec_locked(pg, 0, "SELECT pg_advisory_unlock_shared(" MESH_LOCK_KEY ")", 1, vals, NULL);
    pthread_mutex_unlock(&pg->lock);
}

int vx_pg_mesh_put(vx_pg *pg, const char *id, const cJSON *meta, int *existed, cJSON **stored,
                   vx_err *err)
{
    *existed = 0;
    if (stored) *stored = NULL;
    char *text = vx_json_print(meta, 0);
    if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    const char *vals[] = {id, text};
    if (pg_lock(pg, err)) {
        cJSON_free(text);
        return -1;
    }
    /* A live row stays as it is (the first upload's name wins, as on one
     * node); a deleted one comes back with this upload's metadata. */
    PGresult *r = pg_run_locked(
        pg, 1,
        "WITH old AS (SELECT deleted FROM vx_meshes WHERE id = $1)"
        " INSERT INTO vx_meshes AS m (id, format, bytes, triangles, meta)"
        " VALUES ($1, $2::json ->> 'format', coalesce(($2::json ->> 'bytes')::bigint, 0),"
        "  ($2::json ->> 'triangles')::bigint, $2::json)"
        " ON CONFLICT (id) DO UPDATE SET"
        "  meta = CASE WHEN m.deleted IS NULL THEN m.meta ELSE EXCLUDED.meta END,"
        "  format = CASE WHEN m.deleted IS NULL THEN m.format ELSE EXCLUDED.format END,"
        "  created = CASE WHEN m.deleted IS NULL THEN m.created ELSE now() END, deleted = NULL"
        " RETURNING meta::text, (SELECT count(*) FROM old WHERE deleted IS NULL)",
        2, vals, err);
    pthread_mutex_unlock(&pg->lock);
    cJSON_free(text);
    if (!r) return -1;
    *existed = atoi(PQgetvalue(r, 0, 1)) > 0;
    if (stored) *stored = cJSON_Parse(PQgetvalue(r, 0, 0));
    PQclear(r);
    return 0;
}

int vx_pg_mesh_get(vx_pg *pg, const char *id, cJSON **meta, vx_err *err)
{
    *meta = NULL;
    const char *vals[] = {id};
    PGresult *r = pg_run(
        pg, 1, "SELECT meta::text FROM vx_meshes WHERE id = $1 AND deleted IS NULL", 1, vals, err);
    if (!r) return -1;
    int got = PQntuples(r) == 1;
    if (got && !(*meta = cJSON_Parse(PQgetvalue(r, 0, 0)))) {
        got = vx_err_set(err, VX_EINTERNAL, "database_error", "mesh %s: unreadable metadata", id);
    }
    PQclear(r);
    return got;
}

int vx_pg_mesh_delete(vx_pg *pg, const char *id, vx_err *err)
{
    const char *vals[] = {id};
    PGresult *r = pg_run(pg, 1,
                         "UPDATE vx_meshes SET deleted = now() WHERE id = $1 AND deleted"
                         " IS NULL RETURNING id",
                         1, vals, err);
    if (!r) return -1;
    int n = PQntuples(r);
    PQclear(r);
    if (n != 1) return vx_err_set(err, VX_ENOTFOUND, "mesh_not_found", "no mesh with id %.80s", id);
    return 0;
}

cJSON *vx_pg_mesh_list(vx_pg *pg, const char *after, int limit, char next[65], vx_err *err)
{
    next[0] = 0;
    if (limit < 1) limit = 1;
    if (limit > 1000) limit = 1000;
    char lim[16];
    snprintf(lim, sizeof lim, "%d", limit + 1);
    const char *vals[] = {after, lim};
    PGresult *r = pg_run(pg, 1,
                         "SELECT id, meta::text FROM vx_meshes WHERE deleted IS NULL AND"
                         " ($1::text IS NULL OR id > $1) ORDER BY id LIMIT $2::integer",
                         2, vals, err);
    if (!r) return NULL;
    cJSON *arr = cJSON_CreateArray();
    int n = PQntuples(r);
    for (int i = 0; arr && i < n && i < limit; i++) {
        cJSON *m = cJSON_Parse(PQgetvalue(r, i, 1));
        if (m && !cJSON_AddItemToArray(arr, m)) cJSON_Delete(m);
    }
    if (n > limit) snprintf(next, 65, "%s", PQgetvalue(r, limit - 1, 0));
    PQclear(r);
    if (!arr) vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    return arr;
}

long vx_pg_mesh_count(vx_pg *pg, vx_err *err)
{
    PGresult *r =
        pg_run(pg, 1, "SELECT count(*) FROM vx_meshes WHERE deleted IS NULL", 0, NULL, err);
    if (!r) return -1;
    long n = atol(PQgetvalue(r, 0, 0));
    PQclear(r);
    return n;
}

int vx_pg_mesh_add_missing(vx_pg *pg, const cJSON *metas, vx_err *err)
{
    char *text = vx_json_print(metas, 0);
    if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    const char *vals[] = {text};
    PGresult *r = pg_run(pg, 1,
                         "INSERT INTO vx_meshes (id, format, bytes, triangles, meta)"
                         " SELECT e ->> 'id', e ->> 'format', coalesce((e ->> 'bytes')::bigint, 0),"
                         "  (e ->> 'triangles')::bigint, e FROM json_array_elements($1::json) e"
                         " WHERE (e ->> 'id') ~ '^[0-9a-f]{64}$'"
                         " ON CONFLICT (id) DO NOTHING",
                         1, vals, err);
    cJSON_free(text);
    if (!r) return -1;
    int n = atoi(PQcmdTuples(r));
    PQclear(r);
    return n;
}

int vx_pg_mesh_purge(vx_pg *pg, int max, vx_pg_purge_fn fn, void *ud, vx_err *err)
{
    char lim[16];
    snprintf(lim, sizeof lim, "%d", max > 0 ? max : 100);
    const char *lv[] = {lim};
    /* Deleted rows that no unfinished job names (its mesh, or among its
     * params: a render's extra meshes). */
#define UNUSED_BY_JOBS                                                                             \
    " NOT EXISTS (SELECT 1 FROM vx_jobs j WHERE j.state IN ('queued', 'running') AND"              \
    "  (j.mesh = m.id OR strpos(j.params::text, m.id) > 0))"
    PGresult *c = pg_run(pg, 1,
                         "SELECT id FROM vx_meshes m WHERE deleted IS NOT NULL AND" UNUSED_BY_JOBS
                         " ORDER BY deleted LIMIT $1::integer",
                         1, lv, err);
    if (!c) return -1;
    int done = 0, rc = 0;
    for (int i = 0; i < PQntuples(c) && !rc; i++) {
        const char *vals[] = {PQgetvalue(c, i, 0)};
        pthread_mutex_lock(&pg->lock);
        /* Uploads of this id hold the lock shared from before their bytes
         * go in until their row is written: once it is ours, no upload is
         * half done, and none starts until the row and bytes are gone. */
        PGresult *r = NULL;
        if (pg_exec_locked(pg, 0, "BEGIN", 0, NULL, err) ||
            pg_exec_locked(pg, 0, "SELECT pg_advisory_xact_lock(" MESH_LOCK_KEY ")", 1, vals,
                           err) ||
            !(r = pg_run_locked(pg, 0,
                                "DELETE FROM vx_meshes m WHERE id = $1 AND deleted IS NOT NULL"
                                " AND" UNUSED_BY_JOBS " RETURNING coalesce(format, '')",
                                1, vals, err))) {
            rc = -1;
        } else if (PQntuples(r) == 1 && fn(ud, vals[0], PQgetvalue(r, 0, 0)) != 0) {
            rc = vx_err_set(err, VX_EIO, "store_failed", "mesh %s: its bytes stay", vals[0]);
        } else if (pg_exec_locked(pg, 0, "COMMIT", 0, NULL, err)) {
            rc = -1;
        } else if (PQntuples(r) == 1) {
            done++;
            vx_log(VX_LOG_INFO, "pg.mesh_purged", "mesh=%s", vals[0]);
        }
        if (rc && pg->conn) pg_exec_locked(pg, 0, "ROLLBACK", 0, NULL, NULL);
        pthread_mutex_unlock(&pg->lock);
        PQclear(r);
    }
#undef UNUSED_BY_JOBS
    PQclear(c);
    return rc ? -1 : done;
}
