/* Server-Sent Events of job state and progress (events.h). All stream
 * fields are under vx_events.lock; the content reader (an HTTP thread),
 * the poller and the response's free callback take it. */
#include "events.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "conns.h"
#include "http_int.h"
#include "util/clock.h"
#include "util/fsutil.h"
#include "util/json.h"

#define POLL_S 0.1 /* progress is coalesced to this period */

typedef struct vx_stream {
    struct vx_stream *next;
    vx_events *ev;
    struct MHD_Connection *conn;
    char jid[33];
    /* what the last event sent said */
    char state[16];
    double progress;
    int cancel_requested, attempts;
    unsigned seq;
    /* buffered: the bytes being sent, and the newest event after them */
    char *out;
    size_t out_len, out_pos;
    char *pending;
    int ended;       /* nothing follows what is buffered */
    int suspended;   /* the reader found nothing and suspended the connection */
    double last_out; /* monotonic: the last bytes handed out */
} vx_stream;

struct vx_events {
    vx_jobs *jobs;
    size_t max_streams, n;
    double keepalive_s;
    pthread_mutex_t lock;
    pthread_cond_t cond; /* CLOCK_MONOTONIC: a new stream, a job change, stopping */
    vx_stream *list;
    pthread_t poller;
    int poller_started;
    int stopping, exit;
};

/* "event: job\nid: N\ndata: JSON\n\n" for doc, and what it says into s.
 * Returns the text (owned) or NULL. */
static char *format_event(vx_stream *s, const cJSON *doc, int *terminal)
{
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(doc, "state"));
    snprintf(s->state, sizeof s->state, "%s", state ? state : "");
    s->progress = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(doc, "progress"));
    s->cancel_requested = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(doc, "cancel_requested"));
    s->attempts = (int)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(doc, "attempts"));
    *terminal = !strcmp(s->state, "succeeded") || !strcmp(s->state, "failed") ||
                !strcmp(s->state, "canceled");
    char *json = vx_json_print(doc, 0);
    if (!json) return NULL;
    size_t n = strlen(json) + 64;
    char *text = malloc(n);
    if (text) snprintf(text, n, "event: job\nid: %u\ndata: %s\n\n", ++s->seq, json);
    free(json);
    return text;
}

/* 1 when doc says something the last event did not. */
static int news(const vx_stream *s, const cJSON *doc)
{
    const char *state = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(doc, "state"));
    double p = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(doc, "progress"));
    int cr = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(doc, "cancel_requested"));
    int at = (int)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(doc, "attempts"));
    return !state || strcmp(state, s->state) || p != s->progress || cr != s->cancel_requested ||
           at != s->attempts;
}

/* Buffers text (owned): sent next if nothing is being sent, else it
 * replaces the newest pending event. Lock held. */
static void push_locked(vx_stream *s, char *text)
{
    if (!text) return;
    if (s->out_pos >= s->out_len) {
        free(s->out);
        s->out = text;
        s->out_len = strlen(text);
        s->out_pos = 0;
    } else {
        free(s->pending);
        s->pending = text;
    }
}

static void wake_locked(vx_stream *s)
{
    if (!s->suspended) return;
    s->suspended = 0;
    MHD_resume_connection(s->conn);
}

/* The content reader (the connection's HTTP thread). */
static ssize_t reader(void *cls, uint64_t pos, char *buf, size_t max)
{
    vx_stream *s = cls;
    vx_events *ev = s->ev;
    pthread_mutex_lock(&ev->lock);
    if (s->out_pos >= s->out_len && s->pending) {
        free(s->out);
        s->out = s->pending;
        s->pending = NULL;
        s->out_len = strlen(s->out);
        s->out_pos = 0;
    }
    ssize_t n;
    if (s->out_pos < s->out_len) {
        size_t k = s->out_len - s->out_pos;
        if (k > max) k = max;
        memcpy(buf, s->out + s->out_pos, k);
        s->out_pos += k;
        s->last_out = vx_mono();
        n = (ssize_t)k;
    } else if (s->ended) {
        n = MHD_CONTENT_READER_END_OF_STREAM;
    } else {
        /* Nothing to send: park the connection until the poller has news. */
        s->suspended = 1;
        MHD_suspend_connection(s->conn);
        n = 0;
    }
    pthread_mutex_unlock(&ev->lock);
    return n;
}

/* The response is gone (sent, or its connection closed): forget s. */
static void stream_free(void *cls)
{
    vx_stream *s = cls;
    vx_events *ev = s->ev;
    pthread_mutex_lock(&ev->lock);
    vx_stream **pp = &ev->list;
    while (*pp && *pp != s)
        pp = &(*pp)->next;
    if (*pp) {
        *pp = s->next;
        ev->n--;
    }
    pthread_mutex_unlock(&ev->lock);
    free(s->out);
    free(s->pending);
    free(s);
}

/* One poll of stream s; lock held. */
static void poll_stream(vx_events *ev, vx_stream *s, double now)
{
    if (s->ended) {
        wake_locked(s);
        return;
    }
    /* a client gone between events: the stream ends now, not at the next
     * keepalive's failed write (its slot of --max-event-streams with it) */
    if (s->suspended && vx_conns_peer_gone(s->conn)) {
        s->ended = 1;
        wake_locked(s);
        return;
    }
    vx_err err;
    vx_err_clear(&err);
    cJSON *doc = vx_jobs_get(ev->jobs, s->jid, NULL, &err);
    /* The database down a while (cluster mode): the stream waits, kept
     * alive, and goes on when it answers again. */
    int transient = !doc && (err.kind == VX_EUNAVAIL || err.kind == VX_EOVERLOAD);
    if (!doc && !transient) {
        s->ended = 1; /* dropped from the history */
    } else if (doc && news(s, doc)) {
        int terminal = 0;
        push_locked(s, format_event(s, doc, &terminal));
        if (terminal) s->ended = 1;
    } else if (s->out_pos >= s->out_len && !s->pending && now - s->last_out >= ev->keepalive_s) {
        push_locked(s, strdup(": keepalive\n\n"));
        s->last_out = now;
    }
    cJSON_Delete(doc);
    if (s->out_pos < s->out_len || s->pending || s->ended) wake_locked(s);
}

static void *poller_main(void *arg)
{
    vx_events *ev = arg;
    pthread_mutex_lock(&ev->lock);
    while (!ev->exit) {
        double now = vx_mono();
        for (vx_stream *s = ev->list; s; s = s->next)
            poll_stream(ev, s, now);
        struct timespec ts;
        vx_mono_deadline(ev->list ? POLL_S : 1.0, &ts);
        pthread_cond_timedwait(&ev->cond, &ev->lock, &ts);
    }
    pthread_mutex_unlock(&ev->lock);
    return NULL;
}

vx_events *vx_events_start(vx_jobs *jobs, size_t max_streams, double keepalive_s)
{
    vx_events *ev = calloc(1, sizeof *ev);
    if (!ev) return NULL;
    ev->jobs = jobs;
    ev->max_streams = max_streams;
    ev->keepalive_s = keepalive_s > 0 ? keepalive_s : 15;
    pthread_mutex_init(&ev->lock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&ev->cond, &ca);
    pthread_condattr_destroy(&ca);
    if (pthread_create(&ev->poller, NULL, poller_main, ev) != 0) {
        pthread_mutex_destroy(&ev->lock);
        pthread_cond_destroy(&ev->cond);
        free(ev);
        return NULL;
    }
    ev->poller_started = 1;
    return ev;
}

struct MHD_Response *vx_events_open(vx_events *ev, struct MHD_Connection *c, const char *jid,
                                    vx_err *err)
{
    cJSON *doc = vx_jobs_get(ev->jobs, jid, NULL, err);
    if (!doc) return NULL;
    vx_stream *s = calloc(1, sizeof *s);
    if (!s) {
        cJSON_Delete(doc);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    s->ev = ev;
    s->conn = c;
    snprintf(s->jid, sizeof s->jid, "%s", jid);
    int terminal = 0;
    s->out = format_event(s, doc, &terminal);
    cJSON_Delete(doc);
    s->out_len = s->out ? strlen(s->out) : 0;
    s->ended = terminal;
    s->last_out = vx_mono();
    struct MHD_Response *resp =
        s->out ? MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, reader, s, stream_free)
               : NULL;
    if (!resp) {
        free(s->out);
        free(s);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    pthread_mutex_lock(&ev->lock);
    int refuse = ev->stopping ? 1 : ev->n >= ev->max_streams ? 2 : 0;
    if (!refuse) {
        s->next = ev->list;
        ev->list = s;
        ev->n++;
        pthread_cond_signal(&ev->cond);
    }
    pthread_mutex_unlock(&ev->lock);
    if (refuse) {
        MHD_destroy_response(resp); /* frees s through stream_free */
        if (refuse == 1)
            return vx_err_set(err, VX_EUNAVAIL, "not_ready", "the daemon is stopping"), NULL;
        vx_err_set(err, VX_EOVERLOAD, "too_many_streams",
                   "%zu event streams are open, the most --max-event-streams allows (with "
                   "?wait holds, at most half of --max-connections)",
                   ev->max_streams);
        return NULL;
    }
    return resp;
}

void vx_events_job_changed(vx_events *ev, const char *jid)
{
    (void)jid;
    if (!ev) return;
    pthread_mutex_lock(&ev->lock);
    pthread_cond_signal(&ev->cond);
    pthread_mutex_unlock(&ev->lock);
}

size_t vx_events_count(vx_events *ev)
{
    pthread_mutex_lock(&ev->lock);
    size_t n = ev->n;
    pthread_mutex_unlock(&ev->lock);
    return n;
}

void vx_events_quiesce(vx_events *ev)
{
    if (!ev) return;
    pthread_mutex_lock(&ev->lock);
    ev->stopping = 1;
    for (vx_stream *s = ev->list; s; s = s->next) {
        s->ended = 1;
        wake_locked(s);
    }
    pthread_cond_broadcast(&ev->cond);
    pthread_mutex_unlock(&ev->lock);
}

void vx_events_free(vx_events *ev)
{
    if (!ev) return;
    vx_events_quiesce(ev);
    pthread_mutex_lock(&ev->lock);
    ev->exit = 1;
    pthread_cond_broadcast(&ev->cond);
    pthread_mutex_unlock(&ev->lock);
    if (ev->poller_started) pthread_join(ev->poller, NULL);
    pthread_mutex_destroy(&ev->lock);
    pthread_cond_destroy(&ev->cond);
    free(ev);
}

int vx_route_events(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    struct MHD_Response *resp;
    if (!strcmp(r->method, "HEAD")) {
        /* GET's headers: the stream has no length, and HEAD no body */
        cJSON *doc = vx_jobs_get(h->d.jobs, r->id, NULL, &err);
        if (!doc) return vx_resp_err(c, r, &err);
        cJSON_Delete(doc);
        resp = vx_resp_headers_only();
    } else {
        resp = vx_events_open(h->events, c, r->id, &err);
        if (!resp) return vx_resp_err(c, r, &err);
    }
    if (!resp) return MHD_NO;
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, "text/event-stream");
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    MHD_add_response_header(resp, "X-Accel-Buffering", "no"); /* proxies: do not buffer */
    return vx_resp_queue(c, r, 200, resp, 0);
}
