/* What pg.c's statements share with the other pg_*.c files: the handle
 * and the statement runners. */
#ifndef VX_PG_INT_H
#define VX_PG_INT_H

#include <pthread.h>

#include <libpq-fe.h>

#include "jobs/pg.h"

struct vx_pg {
    vx_pg_desc desc; /* defaults filled; url points at url below */
    char *url;
    char replica[128];
    PGconn *conn; /* NULL while disconnected */
    pthread_mutex_t lock;
    double next_try; /* monotonic: no connection attempt before */
    double backoff;  /* the wait after the next failed attempt */
    int listening;   /* LISTEN again after a reconnection */
    int missed;      /* reconnected while listening: notifications may be lost */
};

/* Takes pg->lock, waiting at most desc.lock_wait_s when it is set (the
 * handle HTTP threads use: a statement waiting on a database that does not
 * answer held every HTTP thread behind it, /livez's too); 0, or -1 with a
 * 503 database_unavailable in err. */
int pg_lock(vx_pg *pg, vx_err *err);
/* pg_run_locked under pg_lock. */
PGresult *pg_run(vx_pg *pg, int retry, const char *sql, int n, const char *const *vals,
                 vx_err *err);
/* Runs sql (n text params; n = 0 allows several statements) and returns
 * its result (PQclear it) or NULL with err; the caller holds pg->lock.
 * retry: when the connection was lost, once more on a new one (for
 * statements that may run twice). */
PGresult *pg_run_locked(vx_pg *pg, int retry, const char *sql, int n, const char *const *vals,
                        vx_err *err);
/* Runs a statement whose result is not needed. */
int pg_exec_locked(vx_pg *pg, int retry, const char *sql, int n, const char *const *vals,
                   vx_err *err);

#endif
