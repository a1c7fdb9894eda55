/* Prometheus metrics: counters and histograms fed by the HTTP layer and the
 * job runner, rendered in the text exposition format (version 0.0.4).
 * Thread-safe. */
#ifndef VX_METRICS_H
#define VX_METRICS_H

#include <stddef.h>
#include <stdint.h>

#include "gl/gl.h"
#include "jobs/jobs.h"

typedef struct vx_metrics_gauges {
    size_t queue_depth, queue_capacity, running, meshes;
    uint64_t results_bytes;
    uint64_t disk_free_bytes, min_free_disk; /* the data dir's file system (UINT64_MAX: unknown,
                                                written NaN), the floor */
    int ready;
    vx_gl_info gl;
    double start_time;
    uint64_t evictions;       /* results removed by the results budget */
    uint64_t gl_context_loss; /* GL contexts lost (and rebuilt or not) */
    /* Cluster mode (--database): this replica's counters, and jobs per
     * (state, kind) in the whole database (ncounts 0 when it did not answer). */
    int cluster;
    vx_jobs_cluster_stats cs;
    const vx_pg_count *counts;
    size_t ncounts;
} vx_metrics_gauges;

/* Sets the job-duration buckets to end at the job timeout (seconds; 0 =
 * the default 600). Called once, before serving. */
void vx_metrics_init(double job_timeout_s);
void vx_metrics_request(const char *route, const char *method, int status, double seconds,
                        uint64_t bytes_in, uint64_t bytes_out);
/* A job finished: run_s and queue_s < 0 when it never ran; code = its
 * error code when it failed (NULL otherwise). */
void vx_metrics_job(const char *kind, const char *state, double run_s, double queue_s,
                    const char *code);
/* Owned text of every family. */
char *vx_metrics_render(const vx_metrics_gauges *g);

#endif
