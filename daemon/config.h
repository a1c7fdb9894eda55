/* Daemon configuration: defaults, then the config file (--config or
 * $VOXELD_CONFIG), then VOXELD_* environment variables (one per flag, named
 * from the flag table), then command-line flags, each overriding the one
 * before. The config file has
 * one `key = value` per line, the keys being the long flag names without
 * the dashes; `#` starts a comment. */
#ifndef VX_CONFIG_H
#define VX_CONFIG_H

#include <stdint.h>
#include <stdio.h>

/* The largest --max-uri-bytes and --max-header-bytes: what a connection's
 * 256 KiB of libmicrohttpd memory holds of a head with room to spare. */
#define VX_CONFIG_MAX_HEAD ((uint64_t)128 << 10)

#include "util/log.h"
#include "util/path.h"

typedef struct vx_config {
    char listen[256];
    char data_dir[VX_PATH_MAX / 2];
    char cache_dir[VX_PATH_MAX / 2];
    char config_file[VX_PATH_MAX / 2];
    char token_file[VX_PATH_MAX / 2];
    char token[512]; /* read from token_file; empty = no auth */
    int egl_device;  /* -1 = auto */
    vx_log_level log_level;
    int http_threads;
    int workers;
    uint64_t max_upload_bytes;
    uint64_t max_triangles;
    uint64_t max_queued_jobs;
    double job_timeout_s;
    double stop_timeout_s; /* SIGTERM: exit 1 when the jobs have not stopped by then; 0 = wait */
    double gl_stall_timeout_s;   /* /livez 503 after the GL thread is silent this long; 0 = off */
    double request_timeout_s;    /* cap on how long ?wait holds a request */
    double connection_timeout_s; /* idle connections are closed after this */
    double header_timeout_s;   /* accept (or the previous answer) to the end of the head; 0 = off */
    uint64_t min_body_rate;    /* bytes/s a request body must keep up; 0 = off */
    uint64_t min_send_rate;    /* bytes/s a client must read an answer at; 0 = off */
    uint64_t max_uri_bytes;    /* longest request target: a longer one gets 414 */
    uint64_t max_header_bytes; /* largest request head: a larger one gets 431 */
    int reuse_port;            /* SO_REUSEPORT on the listening socket */
    uint64_t max_connections;
    uint64_t max_connections_per_ip;
    uint64_t max_image_pixels;
    uint64_t max_cc_valence; /* gregory approximate-cc: faces around a vertex */
    uint64_t max_job_memory;
    uint64_t keep_memory;     /* freed job memory kept mapped for the next job (main.c) */
    int pretouch_memory;      /* keep_memory mapped and touched at start (main.c) */
    uint64_t brick_threshold; /* voxelize to .vdb bricks grids of more cells by default */
    uint64_t max_json_bytes;
    uint64_t min_free_disk;    /* writes answer 507 below this many free bytes in the data dir */
    uint64_t max_parse_memory; /* reserved by concurrent upload parses; 0 = no limit,
                                  UINT64_MAX = 8 x max_upload_bytes + 256M */
    uint64_t results_max_bytes;
    char blob_store[1024]; /* --blob-store URL; empty = the data dir (local) */
    char blob_credentials[VX_PATH_MAX / 2];
    uint64_t blob_cache_max_bytes; /* s3: local copies kept; 0 = no limit */
    uint64_t blob_part_size;       /* s3: multipart above this */
    double blob_timeout_s;         /* s3: connect timeout and longest stall */
    uint64_t blob_retries;         /* s3: retries of 5xx/connection errors */
    char database[1024];           /* --database postgresql://…; empty = the local journal */
    char replica_name[128];        /* this replica's name; empty = host name:port */
    double lease_ttl_s;            /* cluster mode: lease of a running job */
    int max_attempts;              /* cluster mode: attempts a job gets */
    double retry_backoff_s;        /* cluster mode: wait before attempt 2, doubled per attempt */
    double results_max_age_s;
    uint64_t job_history;
    uint64_t job_history_bytes;
    uint64_t max_event_streams; /* open SSE streams before 503 too_many_streams */
    uint64_t max_waits;         /* ?wait holds at once before 503 too_many_waits */
    double event_keepalive_s;   /* idle time before a ": keepalive" comment */
    char allowed_hosts[1024];   /* comma list of Host names taken besides IPs and localhost ("*" =
                                   any) */
    char cors_origin[1024]; /* comma list of origins a browser may call from ("*" = any); empty = no
                               CORS */
    int gl_debug;
    int require_gpu;  /* a software GL renderer makes the daemon unready, and runs no job */
    int list_devices; /* --list-egl-devices: print and exit */
} vx_config;

/* Fills cfg from defaults, $STATE_DIRECTORY / $CACHE_DIRECTORY, the config
 * file and argv. Returns 0 to run, 1 when the program should exit 0
 * (--help, --version), -1 on a bad option (message printed). */
int vx_config_load(vx_config *cfg, int argc, char **argv);
/* Prints the usage text. */
void vx_config_usage(FILE *out);
/* Splits a listen address, ADDR:PORT or [ADDR]:PORT with PORT a decimal
 * from 0 to 65535 (ADDR may be empty: every interface), into host[256]
 * and port[6]: 0, or -1 when it is not one. */
int vx_config_split_listen(const char *s, char host[256], char port[6]);

#endif
