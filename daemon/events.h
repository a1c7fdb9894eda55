/* GET /v1/jobs/{id}/events: a job's state and progress as Server-Sent
 * Events (text/event-stream), until the job ends.
 *
 * Each event is `event: job`, `id: N` and `data:` the Job JSON object that
 * GET /v1/jobs/{id} answers, on one line, then a blank line. One is sent at
 * connect and one on every change of state, progress, cancel_requested or
 * attempts; the stream ends after the event that carries a terminal state.
 * `: keepalive` comment lines keep idle streams open.
 *
 * No HTTP thread ever blocks on a stream: the response is a libmicrohttpd
 * content reader that hands out what is buffered and otherwise suspends
 * its connection. One poller thread reads the streamed jobs every 100 ms
 * (so progress events are coalesced to at most 10 a second), buffers the
 * new events and resumes the connections that have something to send. A
 * slow reader never makes a stream's buffer grow: each stream holds the
 * event being sent and at most one more, the newest (events are whole
 * snapshots, so a skipped one loses nothing). At most --max-event-streams
 * streams are open at once; the next gets 503 too_many_streams. */
#ifndef VX_EVENTS_H
#define VX_EVENTS_H

#include <microhttpd.h>
#include <stddef.h>

#include "jobs/jobs.h"

typedef struct vx_events vx_events;

/* Starts the poller thread. max_streams bounds the open streams (0 = no
 * stream is allowed), keepalive_s is the idle time before a keepalive
 * comment. Owned; free with vx_events_free. NULL without memory. */
vx_events *vx_events_start(vx_jobs *jobs, size_t max_streams, double keepalive_s);
/* A stream of job jid for connection c, as a response to queue (status
 * 200), its first event buffered. NULL with err: VX_ENOTFOUND
 * job_not_found, VX_EOVERLOAD too_many_streams, VX_EUNAVAIL not_ready
 * (stopping), VX_EINTERNAL. Any HTTP thread. */
struct MHD_Response *vx_events_open(vx_events *ev, struct MHD_Connection *c, const char *jid,
                                    vx_err *err);
/* The jobs hook: job jid changed; its streams get the news now rather
 * than at the next poll. Any thread. */
void vx_events_job_changed(vx_events *ev, const char *jid);
/* The streams open now. */
size_t vx_events_count(vx_events *ev);
/* Ends every stream after what it has buffered, and opens no more (shutdown). */
void vx_events_quiesce(vx_events *ev);
/* Stops the poller (after the HTTP daemon has stopped: no stream is left)
 * and frees ev. */
void vx_events_free(vx_events *ev);

#endif
