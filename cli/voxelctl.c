/* voxelctl: command line (see usage() and docs/man/voxelctl.1). */
#include <ctype.h>
#include <curl/curl.h>
#include <errno.h>
#include <limits.h>
#include <getopt.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "ctl.h"

static void usage(FILE *out)
{
    fprintf(
        out,
        "usage: voxelctl [--server URL] [--token T] [--local] [--json] [-q] COMMAND ...\n"
        "\n"
        "Jobs (upload FILE, or use a mesh id; follow the job; download its result):\n"
        "  voxelize FILE [-r N] [-f vdb|binvox|raw8|raw1|vox|nrrd|npy|summary] [-o OUT]\n"
        "                            (summary: the job's stats as JSON, to OUT or stdout)\n"
        "  render FILE [-r N] [-o OUT]        gregory FILE [-f obj|ply|drc|glb] [-o OUT]\n"
        "  catmull-clark FILE [-f obj|ply|drc|glb] [-o OUT]   preview FILE [-o OUT]\n"
        "    -r, --resolution N      voxelize's resolution, render's N\n"
        "    -f, --format F          the output format\n"
        "    -p, --param KEY=VALUE   a job parameter (VALUE as JSON if the whole of it\n"
        "                            parses, else a string; KEY.SUB for nested objects);\n"
        "                            repeatable, applied after --params\n"
        "    --params JSON           parameters as one JSON object\n"
        "    -o, --output FILE       where the primary result goes (- = stdout; a device\n"
        "                            or FIFO is written in place; default: the server's\n"
        "                            file name)\n"
        "    --no-wait               print the job id and exit\n"
        "  Ctrl-C stops waiting, not the job: it says the job id to cancel.\n"
        "Other commands:\n"
        "  upload FILE               store a mesh, print its id\n"
        "  (FILE: - is standard input; stdin, a FIFO or a device is read whole first)\n"
        "  jobs [--state S] [--newest] [--limit N] [--after ID]  (--newest: newest first)\n"
        "  meshes [--limit N] [--after ID]\n"
        "  get JOB [-o FILE] [--name OUTPUT]  show a job; with -o or --name wait for it\n"
        "                            to finish, then download that output, or the\n"
        "                            result as a job command does (every frame)\n"
        "  cancel JOB                cancel a queued or running job (a finished one: error)\n"
        "  delete JOB                delete a finished job and its results (or cancel it)\n"
        "Options:\n"
        "  --server URL   the voxeld to talk to (default $VOXELD_URL or http://127.0.0.1:8080)\n"
        "  --token T      bearer token (default $VOXELD_TOKEN)\n"
        "  --local        start a private voxeld for this command (no server needed)\n"
        "  --json         print the server's JSON on stdout\n"
        "  -q, --quiet    no progress on stderr\n"
        "  -h, --help     this text          --version   voxelctl's version\n"
        "A 429 or 503 with Retry-After (queue full, busy, restarting) is sent again for\n"
        "up to 2 minutes; a server that stops answering while a job is followed (after\n"
        "it answered) is asked again for 2 minutes.\n"
        "Exit status: 0 done, 1 the server or the job failed, 2 bad usage.\n");
}

/* Sets params[key] (dots: nested objects) to value as JSON, else a string. */
static int set_param(cJSON *params, const char *kv)
{
    const char *eq = strchr(kv, '=');
    if (!eq || eq == kv) return -1;
    char key[256];
    snprintf(key, sizeof key, "%.*s", (int)(eq - kv), kv);
    /* JSON only when the whole value is (30deg is the string "30deg") */
    cJSON *v = cJSON_ParseWithOpts(eq + 1, NULL, 1);
    if (cJSON_IsNumber(v) && !isfinite(v->valuedouble)) {
        fprintf(stderr, "voxelctl: -p %s: not a finite number\n", kv);
        cJSON_Delete(v);
        return -2;
    }
    if (!v) v = cJSON_CreateString(eq + 1);
    cJSON *o = params;
    char *k = key, *dot;
    while ((dot = strchr(k, '.'))) {
        *dot = 0;
        cJSON *sub = cJSON_GetObjectItemCaseSensitive(o, k);
        if (sub && !cJSON_IsObject(sub)) { /* -p camera=orbit -p camera.fov=10 */
            fprintf(stderr, "voxelctl: -p %s: %.*s was given a value that is not an object\n", kv,
                    (int)(dot - key), kv);
            cJSON_Delete(v);
            return -2;
        }
        if (!sub) sub = cJSON_AddObjectToObject(o, k);
        o = sub;
        k = dot + 1;
    }
    cJSON_DeleteItemFromObjectCaseSensitive(o, k);
    cJSON_AddItemToObject(o, k, v);
    return 0;
}

static int is_job_kind(const char *s)
{
    static const char *kinds[] = {"voxelize", "render", "gregory", "catmull-clark", "preview"};
    for (size_t i = 0; i < sizeof kinds / sizeof kinds[0]; i++)
        if (!strcmp(s, kinds[i])) return 1;
    return 0;
}

typedef struct args {
    const char *out, *name, *state, *after, *resolution, *format;
    int limit, no_wait, local, newest, server_given;
    cJSON *params;
    const char **kv; /* the -p KEY=VALUEs, applied after every --params */
    int nkv;
    unsigned given;      /* the command options given (OPT_ bits) */
    const char *seen[7]; /* for each OPT_ bit, the first option given of it */
} args;

/* Notes option name (as in --help) given for the group of bit. */
static void mark(args *a, unsigned bit, const char *name)
{
    int b = __builtin_ctz(bit);
    if (!(a->given & bit)) a->seen[b] = name;
    a->given |= bit;
}

/* Options that belong to some commands only. */
enum {
    OPT_JOB = 1,
    OPT_OUT = 2,
    OPT_NAME = 4,
    OPT_STATE = 8,
    OPT_PAGE = 16,
    OPT_RES = 32, /* -r: voxelize's resolution, render's N */
    OPT_FMT = 64  /* -f: the kinds with a format parameter */
};

/* Reads the options (anywhere on the line); the rest stay in argv[optind..]. */
/* s as a whole number in lo..hi (lo > 0), or 0 when it is not one. */
static long whole(const char *s, long lo, long hi)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    return errno || end == s || *end || v < lo || v > hi ? 0 : v;
}

static int read_options(ctl *c, args *a, int argc, char **argv)
{
    enum {
        O_SERVER = 256,
        O_TOKEN,
        O_LOCAL,
        O_JSON,
        O_QUIET,
        O_PARAMS,
        O_NAME,
        O_STATE,
        O_LIMIT,
        O_AFTER,
        O_NOWAIT,
        O_VERSION,
        O_NEWEST
    };
    static const struct option opts[] = {{"server", required_argument, 0, O_SERVER},
                                         {"token", required_argument, 0, O_TOKEN},
                                         {"local", no_argument, 0, O_LOCAL},
                                         {"json", no_argument, 0, O_JSON},
                                         {"quiet", no_argument, 0, O_QUIET},
                                         {"param", required_argument, 0, 'p'},
                                         {"params", required_argument, 0, O_PARAMS},
                                         {"output", required_argument, 0, 'o'},
                                         {"resolution", required_argument, 0, 'r'},
                                         {"format", required_argument, 0, 'f'},
                                         {"name", required_argument, 0, O_NAME},
                                         {"state", required_argument, 0, O_STATE},
                                         {"limit", required_argument, 0, O_LIMIT},
                                         {"after", required_argument, 0, O_AFTER},
                                         {"no-wait", no_argument, 0, O_NOWAIT},
                                         {"help", no_argument, 0, 'h'},
                                         {"version", no_argument, 0, O_VERSION},
                                         {"newest", no_argument, 0, O_NEWEST},
                                         {0, 0, 0, 0}};
    int ch;
    opterr = 0; /* said below, as voxelctl (getopt named the program's path) */
    while ((ch = getopt_long(argc, argv, ":p:o:r:f:hq", opts, NULL)) != -1) {
        switch (ch) {
        case O_SERVER:
            a->server_given = 1;
            snprintf(c->server, sizeof c->server, "%s", optarg);
            break;
        case O_TOKEN:
            snprintf(c->token, sizeof c->token, "%s", optarg);
            break;
        case O_LOCAL:
            a->local = 1;
            break;
        case O_JSON:
            c->json = 1;
            break;
        case 'q':
        case O_QUIET:
            c->quiet = 1;
            break;
        case 'p': {
            const char **kv = realloc(a->kv, (size_t)(a->nkv + 1) * sizeof *kv);
            if (!kv) return -1;
            a->kv = kv;
            a->kv[a->nkv++] = optarg;
            mark(a, OPT_JOB, "-p");
            break;
        }
        case O_PARAMS: {
            mark(a, OPT_JOB, "--params");
            cJSON *p = cJSON_ParseWithOpts(optarg, NULL, 1), *it;
            if (!cJSON_IsObject(p)) {
                fprintf(stderr, "voxelctl: --params wants a JSON object\n");
                cJSON_Delete(p);
                return -1;
            }
            while ((it = p->child)) {
                cJSON_DetachItemViaPointer(p, it);
                cJSON_DeleteItemFromObjectCaseSensitive(a->params, it->string);
                cJSON_AddItemToObject(a->params, it->string, it);
            }
            cJSON_Delete(p);
            break;
        }
        case 'o':
            if (!*optarg) { /* -o "$UNSET": not the server's name in . */
                fprintf(stderr, "voxelctl: -o wants a file name (- for standard output)\n");
                return -1;
            }
            a->out = optarg;
            mark(a, OPT_OUT, "-o");
            break;
        case 'r':
            /* checked here: the server's own range check (422) would come
             * only after the mesh's upload, and exit 1, not 2 */
            if (!whole(optarg, 1, LONG_MAX)) {
                fprintf(stderr, "voxelctl: -r wants a whole number above 0, not '%s'\n", optarg);
                return -1;
            }
            a->resolution = optarg;
            mark(a, OPT_RES, "-r");
            break;
        case 'f':
            a->format = optarg;
            mark(a, OPT_FMT, "-f");
            break;
        case O_NAME:
            a->name = optarg;
            mark(a, OPT_NAME, "--name");
            break;
        case O_STATE: {
            static const char *const states[] = {"queued", "running", "succeeded", "failed",
                                                 "canceled"};
            size_t i = 0;
            while (i < sizeof states / sizeof *states && strcmp(optarg, states[i]))
                i++;
            if (i == sizeof states / sizeof *states) {
                fprintf(stderr,
                        "voxelctl: --state wants queued, running, succeeded, failed or "
                        "canceled, not '%s'\n",
                        optarg);
                return -1;
            }
            a->state = optarg;
            mark(a, OPT_STATE, "--state");
            break;
        }
        case O_LIMIT:
            if (!(a->limit = (int)whole(optarg, 1, 1000))) {
                fprintf(stderr, "voxelctl: --limit wants a whole number 1..1000, not '%s'\n",
                        optarg);
                return -1;
            }
            mark(a, OPT_PAGE, "--limit");
            break;
        case O_AFTER:
            a->after = optarg;
            mark(a, OPT_PAGE, "--after");
            break;
        case O_NEWEST:
            a->newest = 1;
            mark(a, OPT_STATE, "--newest");
            break;
        case O_NOWAIT:
            a->no_wait = 1;
            mark(a, OPT_JOB, "--no-wait");
            break;
        case 'h':
            usage(stdout);
            exit(0);
        case O_VERSION:
            printf("voxelctl %s\n", VX_VERSION);
            exit(0);
        default: {
            /* optopt: a short option's letter; a long option's value (256
             * on) when it lacks its value or was given one it does not
             * take; 0 for an unknown long option (the word given is
             * argv[optind - 1]) */
            char shrt[3] = {'-', (char)optopt, 0};
            const char *o = optopt > 0 && optopt < 128     ? shrt
                            : optopt == 0 || optopt >= 256 ? argv[optind - 1]
                                                           : "(a byte that is no ASCII letter)";
            fprintf(stderr, "voxelctl: %s '%s' (see voxelctl --help)\n",
                    ch == ':'       ? "a value is missing after"
                    : optopt >= 256 ? "no value is taken by"
                                    : "unknown option",
                    o);
            return -1;
        }
        }
    }
    for (int i = 0; i < a->nkv; i++) {
        int rc = set_param(a->params, a->kv[i]);
        if (rc == -1) fprintf(stderr, "voxelctl: -p wants KEY=VALUE, not '%s'\n", a->kv[i]);
        if (rc) return -1;
    }
    return 0;
}

/* -r and -f as the kind's own parameters; 0, or -1 (said) when -p or
 * --params gave the same one. */
static int shortcuts(const char *kind, args *a)
{
    char kv[300];
    const char *res = !strcmp(kind, "render") ? "N" : "resolution";
    const char *key[2] = {res, "format"}, *val[2] = {a->resolution, a->format};
    for (int i = 0; i < 2; i++) {
        if (!val[i]) continue;
        if (cJSON_GetObjectItemCaseSensitive(a->params, key[i])) {
            fprintf(stderr, "voxelctl: -%c and a parameter %s both given: one of them\n",
                    i ? 'f' : 'r', key[i]);
            return -1;
        }
        snprintf(kv, sizeof kv, i ? "%s=\"%s\"" : "%s=%s", key[i], val[i]);
        set_param(a->params, kv);
    }
    return 0;
}

/* A job id as the server makes them (32 lower-case hex digits): never a
 * path of the API (../meshes/ID); anything else is a usage error (2). */
static int hex_ok(const char *s, size_t want)
{
    size_t n = strlen(s), ok = n == want;
    for (size_t i = 0; i < n; i++)
        ok &= (s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f');
    return (int)ok;
}
static int job_id_ok(const char *s)
{
    int ok = hex_ok(s, 32);
    if (!ok) fprintf(stderr, "voxelctl: '%s' is not a job id (32 lower-case hex digits)\n", s);
    return ok;
}

/* The commands: name, arguments, and the command options they take. */
static const struct {
    const char *name;
    int args;
    unsigned opts;
} commands[] = {
    {"voxelize", 1, OPT_JOB | OPT_OUT | OPT_RES | OPT_FMT},
    {"render", 1, OPT_JOB | OPT_OUT | OPT_RES},
    {"gregory", 1, OPT_JOB | OPT_OUT | OPT_FMT},
    {"catmull-clark", 1, OPT_JOB | OPT_OUT | OPT_FMT},
    {"preview", 1, OPT_JOB | OPT_OUT},
    {"upload", 1, 0},
    {"jobs", 0, OPT_STATE | OPT_PAGE},
    {"meshes", 0, OPT_PAGE},
    {"get", 1, OPT_OUT | OPT_NAME},
    {"cancel", 1, 0},
    {"delete", 1, 0},
};

/* Whether the command line fits command k (what does not is said). */
static int fits(int k, const args *a, int n)
{
    const char *cmd = commands[k].name;
    if (n - 1 != commands[k].args) {
        fprintf(stderr, "voxelctl: %s takes %s (see voxelctl --help)\n", cmd,
                commands[k].args ? "one argument" : "no argument");
        return 0;
    }
    for (int b = 0; b < 7; b++)
        if (a->given & ~commands[k].opts & (1u << b)) {
            fprintf(stderr, "voxelctl: %s is not an option of %s (see voxelctl --help)\n",
                    a->seen[b], cmd);
            return 0;
        }
    return 1;
}

static int run(ctl *c, args *a, int n, char **pos)
{
    const char *cmd = pos[0];
    int k = -1;
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(cmd, commands[i].name)) k = (int)i;
    if (k < 0) {
        fprintf(stderr, "voxelctl: no command '%s' (see voxelctl --help)\n", cmd);
        return 2;
    }
    if (!fits(k, a, n)) return 2;
    /* --local's server has the one command's jobs and meshes, and ends
     * with it */
    if (a->local &&
        (a->server_given || a->no_wait || !(is_job_kind(cmd) || !strcmp(cmd, "upload")))) {
        fprintf(stderr,
                "voxelctl: --local starts a private voxeld for one job command (or "
                "upload) and stops it after: not with %s\n",
                a->server_given ? "--server"
                : a->no_wait    ? "--no-wait"
                                : cmd);
        return 2;
    }
    /* --after names an item of the list (never a path of the API) */
    int jobs = !strcmp(cmd, "jobs");
    if (a->after && !hex_ok(a->after, jobs ? 32 : 64)) {
        fprintf(stderr, "voxelctl: --after wants a %s id (%d lower-case hex digits), not '%s'\n",
                jobs ? "job" : "mesh", jobs ? 32 : 64, a->after);
        return 2;
    }
    if (!is_job_kind(cmd) && strcmp(cmd, "upload") && !jobs && strcmp(cmd, "meshes") &&
        !job_id_ok(pos[1]))
        return 2;
    if (c->json && a->out && !strcmp(a->out, "-")) {
        fprintf(stderr, "voxelctl: --json and -o - would both write stdout\n");
        return 2;
    }
    if (is_job_kind(cmd)) {
        if (a->no_wait && a->out) {
            fprintf(stderr, "voxelctl: -o needs the job's result: not with --no-wait (use get)\n");
            return 2;
        }
        if (shortcuts(cmd, a)) return 2;
        if (ctl_out_unwritable(a->out)) return 1;
        const char *fmt =
            cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(a->params, "format"));
        int stats_only = !strcmp(cmd, "voxelize") && fmt && !strcmp(fmt, "summary");
        if (!a->out && !a->no_wait && !stats_only && ctl_cwd_unwritable()) return 1;
        if (a->local && ctl_local_start(c)) return 1;
        cJSON *p = a->params;
        a->params = NULL;
        return ctl_cmd_job(c, cmd, pos[1], p, a->out, a->no_wait);
    }
    if (!strcmp(cmd, "upload"))
        return a->local && ctl_local_start(c) ? 1 : ctl_cmd_upload(c, pos[1]);
    if (jobs) return ctl_cmd_jobs(c, a->state, a->newest, a->limit, a->after);
    if (!strcmp(cmd, "meshes")) return ctl_cmd_meshes(c, a->limit, a->after);
    if (!strcmp(cmd, "get"))
        return ctl_out_unwritable(a->out) || (a->name && !a->out && ctl_cwd_unwritable())
                   ? 1
                   : ctl_cmd_get(c, pos[1], a->name, a->out);
    if (!strcmp(cmd, "cancel")) return ctl_cmd_cancel(c, pos[1]);
    return ctl_cmd_delete(c, pos[1]);
}

int main(int argc, char **argv)
{
    ctl c = {0};
    const char *url = getenv("VOXELD_URL"), *tok = getenv("VOXELD_TOKEN");
    snprintf(c.server, sizeof c.server, "%s", url && *url ? url : "http://127.0.0.1:8080");
    if (tok) snprintf(c.token, sizeof c.token, "%s", tok);
    args a = {.limit = 100, .params = cJSON_CreateObject()};
    if (read_options(&c, &a, argc, argv)) {
        cJSON_Delete(a.params);
        free(a.kv);
        return 2;
    }
    if (optind >= argc) {
        usage(stderr);
        cJSON_Delete(a.params);
        return 2;
    }
    /* Refused at once (exit 2), not after a request: a server that is no
     * http(s) URL, a token a header line cannot carry (a newline in it
     * would start another header; voxeld takes visible ASCII only). */
    if (strncasecmp(c.server, "http://", 7) && strncasecmp(c.server, "https://", 8)) {
        fprintf(stderr, "voxelctl: --server wants an http:// or https:// URL, not '%s'\n",
                c.server);
        cJSON_Delete(a.params);
        free(a.kv);
        return 2;
    }
    for (const char *t = c.token; *t; t++)
        if (*t < 0x21 || *t > 0x7e) {
            fprintf(stderr, "voxelctl: the token (--token or VOXELD_TOKEN) holds a blank or "
                            "control character, which no header can carry\n");
            cJSON_Delete(a.params);
            free(a.kv);
            return 2;
        }
    size_t sl = strlen(c.server);
    while (sl && c.server[sl - 1] == '/')
        c.server[--sl] = 0;
    c.progress_tty = isatty(2);
    if (ctl_http_init()) return 1;
    /* a reader gone from stdout is a write error (exit 1, said), not death
     * by SIGPIPE */
    signal(SIGPIPE, SIG_IGN);
    int rc = run(&c, &a, argc - optind, argv + optind);
    if (a.local) ctl_local_stop();
    cJSON_Delete(a.params);
    free(a.kv);
    curl_global_cleanup();
    /* stdout that could not be written (a full disk, a closed pipe) */
    if ((fflush(stdout) != 0 || ferror(stdout)) && rc == 0) {
        fprintf(stderr, "voxelctl: writing stdout: %s\n", strerror(errno));
        rc = 1;
    }
    return rc;
}
