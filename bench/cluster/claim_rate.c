/* Claim rate of the PostgreSQL queue (src/jobs/pg.c): N queued jobs, then
 * C claimer threads (one connection each) drain them, for each C given.
 * Two passes per C: claim only, and claim + complete (a job's whole queue
 * cost: two fenced commits). Prints one line per pass.
 *
 *   claim_rate URL [jobs=2000] [claimers=1,2,4]
 * bench/cluster/claim_rate.sh starts a throw-away server for it. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "jobs/pg.h"
#include "util/clock.h"

typedef struct claimer {
    const char *url;
    int complete, n, errors;
    char name[16];
} claimer;

static vx_pg *open_pg(const char *url, const char *name)
{
    vx_pg_desc d = {.url = url, .replica = name};
    vx_err err = {0};
    vx_pg *pg = vx_pg_open(&d, &err);
    if (!pg) {
        fprintf(stderr, "claim_rate: %s: %s\n", err.code, err.message);
        exit(1);
    }
    return pg;
}

static void *drain(void *ud)
{
    claimer *c = ud;
    vx_pg *pg = open_pg(c->url, c->name);
    cJSON *manifest = cJSON_Parse("{\"outputs\":{}}");
    for (;;) {
        vx_pg_job jb;
        vx_err err = {0};
        int rc = vx_pg_claim(pg, "bench", &jb, &err);
        if (rc <= 0) {
            c->errors += rc < 0;
            break;
        }
        if (c->complete && vx_pg_complete(pg, jb.id, jb.attempt, manifest, &err) != 0) c->errors++;
        c->n++;
        vx_pg_job_clear(&jb);
    }
    cJSON_Delete(manifest);
    vx_pg_close(pg);
    return NULL;
}

/* Queues n jobs in batches of 500 (one transaction each). */
static void fill(vx_pg *pg, int n, int round)
{
    vx_pg_new_job batch[500];
    char ids[500][33];
    cJSON *params = cJSON_Parse("{\"resolution\":256}");
    for (int i = 0; i < n;) {
        int k = 0;
        for (; k < 500 && i < n; k++, i++) {
            snprintf(ids[k], 33, "%08x%08x%08x%08x", (unsigned)getpid(), round, i,
                     (unsigned)(i * 2654435761u));
            batch[k] = (vx_pg_new_job){.id = ids[k], .kind = "bench", .params = params};
        }
        vx_err err = {0};
        if (vx_pg_submit(pg, batch, (size_t)k, &err)) {
            fprintf(stderr, "claim_rate: submit: %s\n", err.message);
            exit(1);
        }
    }
    cJSON_Delete(params);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: claim_rate URL [jobs] [claimers,...]\n");
        return 2;
    }
    const char *url = argv[1];
    int jobs = argc > 2 ? atoi(argv[2]) : 2000;
    char list[64];
    snprintf(list, sizeof list, "%s", argc > 3 ? argv[3] : "1,2,4");
    vx_pg *pg = open_pg(url, "feeder");
    vx_err err = {0};
    if (vx_pg_migrate(pg, &err) < 0) {
        fprintf(stderr, "claim_rate: migrate: %s\n", err.message);
        return 1;
    }
    int round = 0;
    for (char *tok = strtok(list, ","); tok; tok = strtok(NULL, ",")) {
        int nc = atoi(tok);
        if (nc < 1 || nc > 64) continue;
        for (int complete = 0; complete < 2; complete++) {
            fill(pg, jobs, ++round);
            claimer *cs = calloc((size_t)nc, sizeof *cs);
            pthread_t *th = calloc((size_t)nc, sizeof *th);
            double t0 = vx_mono();
            for (int i = 0; i < nc; i++) {
                cs[i] = (claimer){.url = url, .complete = complete};
                snprintf(cs[i].name, sizeof cs[i].name, "c%d", i);
                pthread_create(&th[i], NULL, drain, &cs[i]);
            }
            int total = 0, errors = 0;
            for (int i = 0; i < nc; i++) {
                pthread_join(th[i], NULL);
                total += cs[i].n;
                errors += cs[i].errors;
            }
            double s = vx_mono() - t0;
            printf("claimers=%d mode=%s jobs=%d seconds=%.3f per_s=%.0f errors=%d\n", nc,
                   complete ? "claim+complete" : "claim", total, s, total / s, errors);
            fflush(stdout);
            free(cs);
            free(th);
            if (total != jobs || errors) return 1;
        }
    }
    vx_pg_close(pg);
    return 0;
}
