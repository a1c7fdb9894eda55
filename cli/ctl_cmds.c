/* voxelctl's commands (ctl.h): upload, submit, follow, download; lists,
 * get and cancel. Human output goes to stderr (progress) and stdout
 * (tables); --json prints the server's JSON on stdout instead. */
#include <ctype.h>
#include <curl/curl.h>
#include <errno.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "ctl.h"
#include "util/json.h"
#include "util/name.h"

static const char *str(const cJSON *o, const char *k)
{
    const char *s = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, k));
    return s ? s : "";
}

/* str() to be shown on a terminal: control bytes as '?' (ctl_printable),
 * in one of four buffers used in turn (four to a line at most). */
static const char *shown(const cJSON *o, const char *k)
{
    static char buf[4][512];
    static int next;
    char *b = buf[next++ % 4];
    return ctl_printable(str(o, k), b, sizeof buf[0]);
}

static double num(const cJSON *o, const char *k)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
    return cJSON_IsNumber(v) ? v->valuedouble : 0;
}

static int terminal(const char *state)
{
    return !strcmp(state, "succeeded") || !strcmp(state, "failed") || !strcmp(state, "canceled");
}

static void print_json(const cJSON *doc)
{
    char *t = vx_json_print(doc, 0);
    if (t) printf("%s\n", t);
    free(t);
}

/* The Content-Type of a mesh file, from its extension. */
static const char *mesh_type(const char *path)
{
    static const struct {
        const char *ext, *type;
    } types[] = {
        {"obj", "model/obj"},        {"bpt", "model/x-bpt"}, {"drc", "model/x-draco"},
        {"stl", "model/stl"},        {"ply", "model/x-ply"}, {"glb", "model/gltf-binary"},
        {"gltf", "model/gltf+json"}, {"off", "model/x-off"},
    };
    const char *dot = strrchr(path, '.');
    if (dot && !strchr(dot, '/'))
        for (size_t i = 0; i < sizeof types / sizeof types[0]; i++)
            if (!strcasecmp(dot + 1, types[i].ext)) return types[i].type;
    return "application/octet-stream";
}

/* s is n hex digits (a mesh id 64, a job id 32: what the server makes) */
static int hex_id(const char *s, size_t n)
{
    size_t k = strlen(s);
    for (size_t i = 0; i < k; i++)
        if (!isxdigit((unsigned char)s[i])) return 0;
    return k == n;
}

static int is_mesh_id(const char *s)
{
    return hex_id(s, 64);
}

/* "&KEY=VALUE" (VALUE %-escaped) when v is set, else "". Owned. */
static char *query_arg(const char *key, const char *v)
{
    char *e = v ? curl_easy_escape(NULL, v, 0) : NULL;
    size_t n = e ? strlen(key) + strlen(e) + 3 : 1;
    char *q = malloc(n);
    if (q) snprintf(q, n, "%s%s%s%s", e ? "&" : "", e ? key : "", e ? "=" : "", e ? e : "");
    curl_free(e);
    return q;
}

static void catch_signals(const char *jid);
static char g_spool[4200];

/* Copies standard input ("-"), a FIFO or a character device into a new
 * temporary file (its name into spool): an upload needs the length first.
 * 0, or 1 said on stderr (spool then holds no file). */
static int spool_stream(const char *file, char *spool, size_t n)
{
    const char *dir = getenv("TMPDIR");
    snprintf(spool, n, "%s/voxelctl-upload-XXXXXX", dir && *dir ? dir : "/tmp");
    catch_signals(NULL); /* Ctrl-C while reading or sending: the spool goes */
    int fd = mkstemp(spool);
    if (fd >= 0) snprintf(g_spool, sizeof g_spool, "%s", spool);
    if (fd < 0) {
        fprintf(stderr, "voxelctl: cannot make a file to hold %s: %s\n",
                strcmp(file, "-") ? file : "standard input", strerror(errno));
        spool[0] = 0;
        return 1;
    }
    FILE *in = strcmp(file, "-") ? fopen(file, "rb") : stdin;
    FILE *to = fdopen(fd, "wb");
    int bad = !in || !to, rerr = 0;
    char buf[1 << 16];
    size_t got;
    while (!bad && (got = fread(buf, 1, sizeof buf, in)) > 0)
        bad = fwrite(buf, 1, got, to) != got;
    if (in && ferror(in)) bad = rerr = 1;
    int e = errno;
    if (to ? fclose(to) != 0 : (close(fd), 0)) bad = 1, e = errno;
    if (in && in != stdin) fclose(in);
    if (bad) {
        fprintf(stderr, "voxelctl: %s %s: %s\n", rerr || !in ? "cannot read" : "cannot hold",
                strcmp(file, "-") ? file : "standard input", strerror(e));
        unlink(spool);
        spool[0] = g_spool[0] = 0;
    }
    return bad;
}

/* Uploads file ("-": standard input), named by its base name where the
 * server takes it as a mesh name (vx_name_ok; else unnamed): its mesh id
 * into id[65], and with --json and `echo` the server's Mesh on stdout. 0 or
 * the exit status. */
static int upload(ctl *c, const char *file, char *id, int echo)
{
    char spool[4096] = "";
    struct stat sb;
    if (!strcmp(file, "-") ||
        (stat(file, &sb) == 0 && (S_ISFIFO(sb.st_mode) || S_ISCHR(sb.st_mode))))
        if (spool_stream(file, spool, sizeof spool)) return 1;
    ctl_buf b = {0};
    const char *base = strrchr(file, '/') ? strrchr(file, '/') + 1 : file;
    int named = strcmp(file, "-") && vx_name_ok(base, strlen(base));
    char *q = named ? query_arg("name", base) : NULL, path[400];
    snprintf(path, sizeof path, "/v1/meshes%s%s", q ? "?" : "", q ? q + 1 : "");
    free(q);
    long st = ctl_http(c, "POST", path, mesh_type(file), NULL, spool[0] ? spool : file, &b, NULL,
                       NULL, 0);
    if (spool[0]) unlink(spool);
    g_spool[0] = 0;
    int rc = 0;
    cJSON *doc = st == 200 || st == 201 ? cJSON_Parse(b.p) : NULL;
    if (!doc) {
        rc = ctl_http_fail("upload", st, &b);
    } else if (!is_mesh_id(str(doc, "id"))) { /* never a path put in a request */
        fprintf(stderr, "voxelctl: upload: the server's answer has no mesh id (HTTP %ld)\n", st);
        rc = 1;
    } else {
        snprintf(id, 65, "%s", str(doc, "id"));
    }
    if (doc && echo && c->json) print_json(doc);
    cJSON_Delete(doc);
    free(b.p);
    return rc;
}

/* ---- progress ----------------------------------------------------------- */

typedef struct follow {
    ctl *c;
    char state[16];
    int tenth;    /* the last tenth of progress reported (plain lines) */
    int answered; /* the server has answered during this command */
} follow;

static void on_job(void *ud, const cJSON *job)
{
    follow *f = ud;
    f->answered = 1;
    if (f->c->quiet) return;
    const char *state = str(job, "state");
    double p = num(job, "progress");
    p = p >= 0 && p <= 1 ? p : p > 1 ? 1 : 0; /* the server's number: NaN, 1e20 */
    if (f->c->progress_tty) {
        int w = 30, k = (int)(p * w + 0.5);
        fprintf(stderr, "\r%-9s [%.*s%*s] %3d%%", shown(job, "state"), k,
                "##############################", w - k, "", (int)(p * 100 + 0.5));
        if (terminal(state)) fputc('\n', stderr);
        fflush(stderr);
    } else if (strcmp(state, f->state) || (int)(p * 10) > f->tenth) {
        fprintf(stderr, "%s %s %d%%\n", shown(job, "id"), shown(job, "state"),
                (int)(p * 100 + 0.5));
    }
    snprintf(f->state, sizeof f->state, "%s", state);
    f->tenth = (int)(p * 10);
}

/* 1 when b holds a JSON error whose code is code. */
static int error_code_is(const ctl_buf *b, const char *code)
{
    cJSON *doc = b->p ? cJSON_Parse(b->p) : NULL;
    const char *got = str(cJSON_GetObjectItemCaseSensitive(doc, "error"), "code");
    int is = !strcmp(got, code);
    cJSON_Delete(doc);
    return is;
}

/* Follows job jid to its end: the event stream, or ?wait polling when the
 * server has no stream (and while it holds --max-waits requests already,
 * 503 too_many_waits: plain GETs 2 s apart). A server that stops answering
 * (restarting: no connection, or 503 while it starts) after it answered
 * during this command (answered: already before) is asked again for 2
 * minutes: a job it requeued goes on after a restart. One that never
 * answered is no server there: said at once. The last Job (owned), or
 * NULL (printed). */
static cJSON *follow_job(ctl *c, const char *jid, int answered)
{
    follow f = {.c = c, .tenth = -1, .answered = answered};
    long st;
    cJSON *job = ctl_http_events(c, jid, on_job, &f, &st);
    if (st) f.answered = 1;
    if (job && terminal(str(job, "state"))) return job;
    cJSON_Delete(job);
    char path[160];
    time_t lost = 0; /* when the server stopped answering */
    int plain = 0;   /* the server's waits were full: ask without one */
    for (;;) {
        ctl_buf b = {0};
        snprintf(path, sizeof path, plain ? "/v1/jobs/%s" : "/v1/jobs/%s?wait=30", jid);
        /* said below, and tried again here (no answer yet: ctl_http says it) */
        c->quiet_transport = f.answered;
        c->no_retry = 1;
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        st = ctl_http(c, "GET", path, NULL, NULL, NULL, &b, NULL, NULL, 0);
        c->quiet_transport = c->no_retry = 0;
        if (st < 0 && !f.answered) {
            free(b.p);
            return NULL;
        }
        f.answered = 1;
        if (st == 503 && !plain && error_code_is(&b, "too_many_waits")) {
            free(b.p);
            lost = 0;
            plain = 1;
            sleep(2);
            continue;
        }
        plain = 0;
        if (st < 0 || st == 502 || st == 503 || st == 504) {
            free(b.p);
            if (ctl_local_interrupted()) pause(); /* the signal ends the process */
            time_t now = time(NULL);
            if (!lost) {
                lost = now;
                char why[300];
                if (st < 0)
                    snprintf(why, sizeof why, "%s", ctl_http_error);
                else
                    snprintf(why, sizeof why, "HTTP %ld", st);
                if (c->progress_tty && !c->quiet) fputc('\n', stderr);
                fprintf(stderr,
                        "voxelctl: no answer about job %s from %s (%s); asking again for 2 "
                        "minutes\n",
                        jid, c->server, why);
            } else if (now - lost > 120) {
                fprintf(stderr,
                        "voxelctl: no answer for 2 minutes: job %s may still run (voxelctl get "
                        "%s)\n",
                        jid, jid);
                return NULL;
            }
            sleep(2);
            continue;
        }
        lost = 0;
        job = st == 200 ? cJSON_Parse(b.p) : NULL;
        if (job && (strcmp(str(job, "id"), jid) != 0 ||
                    !cJSON_IsString(cJSON_GetObjectItemCaseSensitive(job, "state")))) {
            cJSON_Delete(job); /* not this job (said as not the JSON expected) */
            job = NULL;
        }
        if (!job) {
            ctl_http_fail("job", st, &b);
            free(b.p);
            return NULL;
        }
        free(b.p);
        on_job(&f, job);
        if (terminal(str(job, "state"))) return job;
        cJSON_Delete(job);
        /* a server that answers ?wait at once (--request-timeout 0) is
         * asked once a second, not as fast as it answers */
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double took = (double)(t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) / 1e9;
        if (took < 1) usleep((useconds_t)((1 - took) * 1e6));
    }
}

/* ---- where a result goes ------------------------------------------------ */

/* The part file being written, the upload spool and the job being waited
 * for, for a signal that ends the process: the files are removed, the job
 * named. */
static char g_part[4200], g_jid[40];
static volatile sig_atomic_t g_job_ended; /* g_jid has ended: its result is downloading */

static void say(const char *s)
{
    ssize_t w = write(2, s, strlen(s));
    (void)w;
}

void ctl_cmds_remove_temp(void)
{
    if (g_part[0]) unlink(g_part);
    if (g_spool[0]) unlink(g_spool);
}

static void on_signal(int sig)
{
    ctl_cmds_remove_temp();
    if (g_jid[0] && g_job_ended) {
        say("\nvoxelctl: download interrupted; job ");
        say(g_jid);
        say(" has ended (voxelctl get ");
        say(g_jid);
        say(" -o FILE fetches its result)\n");
    } else if (g_jid[0]) {
        say("\nvoxelctl: interrupted; job ");
        say(g_jid);
        say(" goes on (voxelctl cancel ");
        say(g_jid);
        say(" stops it)\n");
    }
    signal(sig, SIG_DFL);
    raise(sig);
}

static void catch_signals(const char *jid)
{
    snprintf(g_jid, sizeof g_jid, "%s", jid ? jid : "");
    g_job_ended = 0;
    static const int sigs[] = {SIGINT, SIGTERM, SIGHUP};
    for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++)
        signal(sigs[i], on_signal);
}

/* The directory of path into dir: "." when it names none. */
static void dir_of(const char *path, char *dir, size_t n)
{
    snprintf(dir, n, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash == dir)
        dir[1] = 0;
    else if (slash)
        *slash = 0;
    else
        snprintf(dir, n, ".");
}

/* The file that -o out writes into final: through a symlink (or a chain of
 * them, a relative one from its own directory) to the target, which may
 * not exist yet (realpath() fails on such a dangling link), else out.
 * 0, or -1 with errno (ELOOP, ENAMETOOLONG). */
static int out_target(const char *out, char *final, size_t n)
{
    char cur[4200], link[4096], dir[4200];
    snprintf(cur, sizeof cur, "%s", out);
    for (int hops = 0;; hops++) {
        char *rp = realpath(cur, NULL);
        if (rp) {
            snprintf(final, n, "%s", rp);
            free(rp);
            return 0;
        }
        ssize_t k = readlink(cur, link, sizeof link);
        if (k < 0) { /* no link: a file to make */
            snprintf(final, n, "%s", cur);
            return 0;
        }
        if (k == (ssize_t)sizeof link || hops == 40) {
            errno = hops == 40 ? ELOOP : ENAMETOOLONG;
            return -1;
        }
        link[k] = 0;
        dir_of(cur, dir, sizeof dir);
        if (link[0] == '/')
            snprintf(cur, sizeof cur, "%s", link);
        else
            snprintf(cur, sizeof cur, "%s/%s", strcmp(dir, "/") ? dir : "", link);
    }
}

/* Makes a part file with mode in dir, its name into part. Its fd, or -1
 * with errno (nothing left). */
static int part_open(const char *dir, mode_t mode, char *part, size_t n)
{
    snprintf(part, n, "%s/.voxelctl-XXXXXX.part", dir);
    int fd = mkstemps(part, 5);
    if (fd >= 0 && fchmod(fd, mode) != 0) {
        int e = errno;
        close(fd);
        unlink(part);
        errno = e;
        fd = -1;
    }
    return fd;
}

/* 0 when a part file can be made in dir (made and removed: access() lets
 * root "write" in /proc), else the errno why not. */
static int dir_refuses(const char *dir)
{
    char part[4300];
    int fd = part_open(dir, 0600, part, sizeof part);
    if (fd < 0) return errno;
    close(fd);
    unlink(part);
    return 0;
}

int ctl_out_unwritable(const char *out)
{
    if (!out || !strcmp(out, "-")) return 0;
    char final[4200], dir[4200];
    if (out_target(out, final, sizeof final)) {
        fprintf(stderr, "voxelctl: -o %s: %s\n", out, strerror(errno));
        return 1;
    }
    struct stat st;
    int exists = stat(final, &st) == 0;
    if (exists && S_ISDIR(st.st_mode)) {
        fprintf(stderr, "voxelctl: -o %s: is a directory\n", out);
        return 1;
    }
    if (exists && access(final, W_OK) != 0) {
        fprintf(stderr, "voxelctl: -o %s: cannot write %s: %s\n", out, final, strerror(errno));
        return 1;
    }
    if (exists && !S_ISREG(st.st_mode)) return 0; /* written in place */
    dir_of(final, dir, sizeof dir);
    int e = dir_refuses(dir);
    if (e) fprintf(stderr, "voxelctl: -o %s: cannot write %s: %s\n", out, dir, strerror(e));
    return e != 0;
}

int ctl_cwd_unwritable(void)
{
    int e = dir_refuses(".");
    if (e)
        fprintf(stderr,
                "voxelctl: cannot write the result in the current directory: %s "
                "(give -o FILE, or -o - for stdout)\n",
                strerror(e));
    return e != 0;
}

/* A result being written: to stdout, in place (out exists and is not a
 * regular file: a device such as /dev/null, a FIFO), or through a part
 * file beside the destination with a name of its own (parallel runs never
 * share one), renamed over it once whole; a symlink is followed to its
 * target, an existing file's mode kept. */
typedef struct sink_file {
    FILE *f;
    int direct;
    char final[4200]; /* "" until known (the server's file name) */
} sink_file;

static int sink_open(sink_file *o, const char *out)
{
    memset(o, 0, sizeof *o);
    if (out && !strcmp(out, "-")) {
        o->f = stdout;
        return 0;
    }
    mode_t mask = umask(0), mode = 0666 & ~mask;
    umask(mask);
    struct stat st;
    if (out) {
        if (out_target(out, o->final, sizeof o->final)) {
            fprintf(stderr, "voxelctl: cannot write %s: %s\n", out, strerror(errno));
            return 1;
        }
        if (stat(o->final, &st) == 0) {
            o->direct = !S_ISREG(st.st_mode);
            mode = st.st_mode & 07777;
        }
    }
    if (o->direct) {
        o->f = fopen(o->final, "wb");
        if (!o->f) fprintf(stderr, "voxelctl: cannot write %s: %s\n", o->final, strerror(errno));
        return o->f ? 0 : 1;
    }
    char dir[4200];
    dir_of(o->final[0] ? o->final : "./result", dir, sizeof dir);
    int fd = part_open(dir, mode, g_part, sizeof g_part);
    if (fd >= 0) o->f = fdopen(fd, "wb");
    if (!o->f) {
        fprintf(stderr, "voxelctl: cannot write in %s: %s\n", dir, strerror(errno));
        if (fd >= 0) {
            close(fd);
            unlink(g_part);
        }
        g_part[0] = 0;
        return 1;
    }
    return 0;
}

/* Ends a result: kept (ok: renamed to final, or name when final is
 * unknown) or discarded. 0, or 1 with the reason printed. */
static int sink_close(sink_file *o, int ok, const char *name)
{
    int rc = 0;
    if (o->f == stdout) {
        if (fflush(stdout) != 0 || ferror(stdout)) {
            if (ok) fprintf(stderr, "voxelctl: writing stdout: %s\n", strerror(errno));
            rc = 1;
        }
        return ok ? rc : 1;
    }
    if (fclose(o->f) != 0 && ok) {
        fprintf(stderr, "voxelctl: writing %s: %s\n", o->direct ? o->final : g_part,
                strerror(errno));
        ok = 0;
    }
    if (!o->final[0]) snprintf(o->final, sizeof o->final, "%s", name);
    if (!o->direct) {
        if (ok && rename(g_part, o->final) != 0) {
            fprintf(stderr, "voxelctl: cannot write %s: %s\n", o->final, strerror(errno));
            ok = 0;
        }
        if (!ok) unlink(g_part);
        g_part[0] = 0;
    }
    return ok ? 0 : 1;
}

/* Downloads the primary result (name NULL) or output name of jid to out
 * (NULL: the server's file name). 0 or the exit status. */
static int download(ctl *c, const char *jid, const char *name, const char *out)
{
    char path[1024], disp[256];
    /* escaped: a name is one path segment (../x, spaces) */
    char *en = name ? curl_easy_escape(NULL, name, 0) : NULL;
    if (name && !en) return 1;
    snprintf(path, sizeof path, "/v1/jobs/%s/result%s%s", jid, en ? "/" : "", en ? en : "");
    curl_free(en);
    sink_file o;
    if (sink_open(&o, out)) return 1;
    ctl_buf b = {0};
    long st = ctl_http(c, "GET", path, NULL, NULL, NULL, &b, o.f, disp, sizeof disp);
    if (st < 0 && ctl_http_write_errno) /* a full disk: the file, not the server */
        fprintf(stderr, "voxelctl: writing %s: %s\n",
                o.f == stdout ? "standard output"
                : o.final[0]  ? o.final
                : disp[0]     ? disp
                              : "the result",
                strerror(ctl_http_write_errno));
    int rc = st == 200 ? 0 : ctl_http_fail("download", st, &b);
    free(b.p);
    if (sink_close(&o, rc == 0, disp[0] ? disp : "result")) return 1;
    if (!rc && o.f != stdout && !c->json && !c->quiet) {
        struct stat sb;
        /* (named as given: o.final is a symlink's target; a device has no size) */
        if (stat(o.final, &sb) == 0 && S_ISREG(sb.st_mode))
            fprintf(stderr, "wrote %s (%lld bytes)\n", out ? out : o.final, (long long)sb.st_size);
    }
    return rc;
}

/* out with "_NNN" (the frame's) put before its extension: spin.png ->
 * spin_007.png; "-" stays stdout. Owned. */
static char *frame_path(const char *out, const char *suffix)
{
    if (!strcmp(out, "-")) return strdup(out);
    const char *slash = strrchr(out, '/'), *dot = strrchr(out, '.');
    size_t at = dot && dot > (slash ? slash + 1 : out) ? (size_t)(dot - out) : strlen(out);
    size_t n = strlen(out) + strlen(suffix) + 1;
    char *p = malloc(n);
    if (p) snprintf(p, n, "%.*s%s%s", (int)at, out, suffix, out + at);
    return p;
}

/* Downloads a finished job's result: the primary output, or for a
 * turntable (outputs image_000, image_001, ... in the job's outputs
 * object, name -> URL, in frame order: a render of frames > 1)
 * every frame of it, each to out with its frame number put in (all to
 * stdout for -o -, as for ffmpeg's image2pipe), or to the server's file
 * names. 0 or the exit status. */
static int download_result(ctl *c, const char *jid, const cJSON *job, const char *out)
{
    const cJSON *outs = cJSON_GetObjectItemCaseSensitive(job, "outputs"), *it;
    const char *first = outs && outs->child && outs->child->string ? outs->child->string : "";
    size_t len = strlen(first);
    if (len < 5 || strcmp(first + len - 4, "_000") != 0) return download(c, jid, NULL, out);
    int rc = 0;
    cJSON_ArrayForEach(it, outs)
    {
        const char *name = it->string ? it->string : "";
        if (rc || strlen(name) != len || strncmp(name, first, len - 3) != 0) continue;
        char *to = out ? frame_path(out, name + len - 4) : NULL;
        rc = out && !to ? 1 : download(c, jid, name, to);
        free(to);
    }
    return rc;
}

/* A job that wrote no file (voxelize's summary): its stats, as JSON, to
 * out (stdout when NULL). 0 or the exit status. */
static int write_stats(const cJSON *job, const char *out)
{
    char *t = vx_json_print(cJSON_GetObjectItemCaseSensitive(job, "stats"), 0);
    if (!t) return 1;
    sink_file o;
    int rc = sink_open(&o, out ? out : "-");
    if (!rc) {
        int ok = fprintf(o.f, "%s\n", t) >= 0;
        rc = sink_close(&o, ok, "stats.json");
    }
    free(t);
    return rc;
}

/* Follows job jid to its end, then writes what it made: output name when
 * given, else the primary output (every frame of a turntable), else the
 * stats of a job that wrote no file; a job that did not succeed is said
 * (exit 1). With --json the last Job goes on stdout. Shared by the job
 * commands and `get`, so both wait and download alike (answered: the
 * server has answered this command already, follow_job). The exit status. */
static int wait_and_fetch(ctl *c, const char *jid, const char *name, const char *out, int answered)
{
    catch_signals(jid);
    cJSON *job = follow_job(c, jid, answered);
    if (!job) return 1;
    g_job_ended = 1;
    int rc = 0;
    const char *state = str(job, "state");
    if (strcmp(state, "succeeded") != 0) {
        const cJSON *e = cJSON_GetObjectItemCaseSensitive(job, "error");
        if (cJSON_IsObject(e))
            fprintf(stderr, "voxelctl: job %s %s: %s (%s)\n", jid, shown(job, "state"),
                    shown(e, "message"), shown(e, "code"));
        else
            fprintf(stderr, "voxelctl: job %s %s (the server gave no error)\n", jid,
                    shown(job, "state"));
        rc = 1;
    } else if (name) {
        rc = download(c, jid, name, out);
    } else if (cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(job, "outputs")) > 0) {
        rc = download_result(c, jid, job, out);
    } else if (!c->json || out) { /* (--json alone: the stats are in the job printed) */
        rc = write_stats(job, out);
    }
    g_jid[0] = 0;
    if (c->json) print_json(job);
    cJSON_Delete(job);
    return rc;
}

/* A random Idempotency-Key (32 hex digits) in out; "" when none can be
 * made (the submission then goes without one). */
static void new_key(char *out, size_t n)
{
    unsigned char r[16];
    out[0] = 0;
    if (n < 2 * sizeof r + 1 || getentropy(r, sizeof r) != 0) return;
    for (size_t i = 0; i < sizeof r; i++)
        snprintf(out + 2 * i, 3, "%02x", r[i]);
}

int ctl_cmd_job(ctl *c, const char *kind, const char *src, cJSON *params, const char *out,
                int no_wait)
{
    char mesh[65];
    struct stat sb;
    int rc = 0;
    if (is_mesh_id(src) && stat(src, &sb) != 0)
        snprintf(mesh, sizeof mesh, "%s", src);
    else if ((rc = upload(c, src, mesh, 0)))
        goto done;
    cJSON *req = cJSON_CreateObject();
    cJSON_AddStringToObject(req, "mesh", mesh);
    cJSON_AddStringToObject(req, "kind", kind);
    cJSON_AddItemToObject(req, "params", params);
    params = NULL;
    char *body = vx_json_print(req, 0);
    cJSON_Delete(req);
    ctl_buf b = {0};
    ctl keyed = *c; /* a submission whose answer is lost is sent again under its key */
    new_key(keyed.idem_key, sizeof keyed.idem_key);
    long st =
        ctl_http(&keyed, "POST", "/v1/jobs", "application/json", body, NULL, &b, NULL, NULL, 0);
    free(body);
    cJSON *job = st == 202 || st == 200 ? cJSON_Parse(b.p) : NULL;
    if (!job) rc = ctl_http_fail("submit", st, &b);
    free(b.p);
    if (!job) goto done;
    char jid[40];
    snprintf(jid, sizeof jid, "%s", str(job, "id"));
    if (!hex_id(str(job, "id"), 32)) { /* never a path put in a request ("../../x") */
        fprintf(stderr, "voxelctl: submit: the server's answer has no job id (HTTP %ld)\n", st);
        cJSON_Delete(job);
        rc = 1;
        goto done;
    }
    if (no_wait) {
        if (c->json)
            print_json(job);
        else
            printf("%s\n", jid);
        cJSON_Delete(job);
        goto done;
    }
    cJSON_Delete(job);
    rc = wait_and_fetch(c, jid, NULL, out, 1);
done:
    cJSON_Delete(params);
    return rc;
}

/* GET path; prints the answer as JSON (--json) or through row() for each
 * item of a list page, and when there are more the options of the next
 * page: flags (this page's, to keep its filters and order) and --after.
 * An item row() cannot show (not a job or mesh: a wrong answer) is said,
 * exit 1. The exit status. */
static int list(ctl *c, const char *path, int (*row)(const cJSON *), const char *flags)
{
    ctl_buf b = {0};
    long st = ctl_http(c, "GET", path, NULL, NULL, NULL, &b, NULL, NULL, 0);
    cJSON *doc = st == 200 ? cJSON_Parse(b.p) : NULL;
    int rc = doc ? 0 : ctl_http_fail(path, st, &b);
    free(b.p);
    if (!doc) return rc;
    if (c->json) {
        print_json(doc);
    } else {
        const cJSON *it, *items = cJSON_GetObjectItemCaseSensitive(doc, "items");
        int bad = 0;
        if (flags && !cJSON_IsArray(items)) {
            bad = 1; /* a list page has items */
        } else if (flags) {
            cJSON_ArrayForEach(it, items) bad |= row(it);
        } else {
            bad = row(doc);
        }
        if (bad) {
            fprintf(stderr, "voxelctl: GET %s: HTTP 200, but the answer is not the JSON expected\n",
                    path);
            rc = 1;
        }
        if (flags && !c->quiet && cJSON_IsString(cJSON_GetObjectItemCaseSensitive(doc, "next")))
            fprintf(stderr, "voxelctl: more after these %d: %s--after %s (or --limit up to 1000)\n",
                    cJSON_GetArraySize(items), flags, shown(doc, "next"));
    }
    cJSON_Delete(doc);
    return rc;
}

/* A job's row; 1 (nothing printed) for what is not a job. */
static int job_row(const cJSON *j)
{
    if (!hex_id(str(j, "id"), 32) || !cJSON_IsString(cJSON_GetObjectItemCaseSensitive(j, "state")))
        return 1;
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(j, "error");
    printf("%s  %-13s %-9s %3.0f%%  %s  %s\n", str(j, "id"), shown(j, "kind"), shown(j, "state"),
           num(j, "progress") * 100, shown(j, "created"), shown(e, "code"));
    return 0;
}

/* A mesh's row; 1 (nothing printed) for what is not a mesh. */
static int mesh_row(const cJSON *m)
{
    if (!is_mesh_id(str(m, "id"))) return 1;
    printf("%s  %-6s %10.0f triangles  %s\n", str(m, "id"), shown(m, "format"), num(m, "triangles"),
           shown(m, "name"));
    return 0;
}

int ctl_cmd_jobs(ctl *c, const char *state, int newest, int limit, const char *after)
{
    char *s = query_arg("state", state), *a = query_arg("after", after);
    char *path = s && a ? malloc(strlen(s) + strlen(a) + 60) : NULL, flags[300];
    int rc = 1;
    if (path) {
        sprintf(path, "/v1/jobs?limit=%d%s%s%s", limit, newest ? "&order=desc" : "", s, a);
        /* (a state is one of a few words: the server refuses others) */
        snprintf(flags, sizeof flags, "%s%s%s%s--limit %d ", newest ? "--newest " : "",
                 state ? "--state " : "", state ? state : "", state ? " " : "", limit);
        rc = list(c, path, job_row, flags);
    }
    free(path);
    free(s);
    free(a);
    return rc;
}

int ctl_cmd_meshes(ctl *c, int limit, const char *after)
{
    char *a = query_arg("after", after);
    char *path = a ? malloc(strlen(a) + 40) : NULL;
    int rc = 1;
    if (path) {
        char flags[40];
        snprintf(flags, sizeof flags, "--limit %d ", limit);
        sprintf(path, "/v1/meshes?limit=%d%s", limit, a);
        rc = list(c, path, mesh_row, flags);
    }
    free(path);
    free(a);
    return rc;
}

static int job_show(const cJSON *j)
{
    if (job_row(j)) return 1;
    const cJSON *o, *outs = cJSON_GetObjectItemCaseSensitive(j, "outputs");
    char k[128], v[512];
    cJSON_ArrayForEach(o, outs) printf("  output %-10s %s\n", ctl_printable(o->string, k, sizeof k),
                                       ctl_printable(cJSON_GetStringValue(o), v, sizeof v));
    return 0;
}

int ctl_cmd_get(ctl *c, const char *jid, const char *name, const char *out)
{
    /* A download waits for the job (an unfinished one has no result yet:
     * 409); showing it does not, it is how its state is looked at. */
    if (out || name) return wait_and_fetch(c, jid, name, out, 0);
    catch_signals(NULL);
    char path[160];
    snprintf(path, sizeof path, "/v1/jobs/%s", jid);
    return list(c, path, job_show, NULL);
}

/* DELETE /v1/jobs/{jid}: cancels a queued or running job, and deletes a
 * finished one with its results. cancel first checks that the job has not
 * finished, so that it never deletes results (a job that ends between the
 * check and the DELETE is deleted: said so). */
static int delete_job(ctl *c, const char *jid, int cancel_only)
{
    char path[160];
    snprintf(path, sizeof path, "/v1/jobs/%s", jid);
    ctl_buf b = {0};
    long st;
    if (cancel_only) {
        st = ctl_http(c, "GET", path, NULL, NULL, NULL, &b, NULL, NULL, 0);
        cJSON *job = st == 200 ? cJSON_Parse(b.p) : NULL;
        int fin = job && terminal(str(job, "state"));
        cJSON_Delete(job);
        if (st != 200 || fin) {
            int rc = st != 200 ? ctl_http_fail("cancel", st, &b) : 1;
            if (fin)
                fprintf(stderr,
                        "voxelctl: cancel: job_finished: job %s has already finished "
                        "(voxelctl delete removes it and its results)\n",
                        jid);
            free(b.p);
            return rc;
        }
        free(b.p);
        b = (ctl_buf){0};
    }
    st = ctl_http(c, "DELETE", path, NULL, NULL, NULL, &b, NULL, NULL, 0);
    cJSON *doc = st == 200 || st == 202 ? cJSON_Parse(b.p) : NULL;
    int rc = doc || st == 204 ? 0 : ctl_http_fail(cancel_only ? "cancel" : "delete", st, &b);
    if (doc && c->json) print_json(doc);
    if (doc && !c->json)
        printf("%s %s\n", jid, st == 202 ? "cancel requested (running)" : shown(doc, "state"));
    if (st == 204 && c->json) printf("{\"id\":\"%s\",\"deleted\":true}\n", jid);
    if (st == 204 && !c->json) printf("%s deleted\n", jid);
    cJSON_Delete(doc);
    free(b.p);
    return rc;
}

int ctl_cmd_cancel(ctl *c, const char *jid)
{
    return delete_job(c, jid, 1);
}

int ctl_cmd_delete(ctl *c, const char *jid)
{
    return delete_job(c, jid, 0);
}

int ctl_cmd_upload(ctl *c, const char *file)
{
    char id[65];
    int rc = upload(c, file, id, 1);
    if (!rc && !c->json) printf("%s\n", id);
    return rc;
}
