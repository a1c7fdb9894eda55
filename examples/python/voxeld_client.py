#!/usr/bin/env python3
"""A small voxeld client using only the Python standard library.

As a module:

    from voxeld_client import Client
    c = Client("http://127.0.0.1:8080", token=None)
    mesh = c.upload("bunny.obj")["id"]
    job = c.submit(mesh, "voxelize", {"resolution": 128, "format": "binvox"})
    for event in c.events(job["id"]):          # Server-Sent Events
        print(event["state"], event["progress"])
    c.download(job["id"], "bunny.binvox")

As a program:

    voxeld_client.py [--server URL] [--token T] KIND FILE [-p KEY=VALUE ...] [-o OUT]

The server and token default to $VOXELD_URL and $VOXELD_TOKEN. Errors from
the server raise VoxeldError with its code and message; a server that cannot
be reached (or drops the connection) raises VoxeldError with status 0 and
code "unreachable", a download cut short status 0 and code "incomplete".
A 429 or 503 with Retry-After (queue full, busy, restarting: nothing was
done) is sent again after the seconds it says, for up to retry_for seconds
(120; 0: never); wait() rides out a server that restarts for as long. A
job submission goes with an Idempotency-Key (random unless given): when
its answer is lost (the connection reset or closed after it was sent) it
is sent again with the key, every 2 s for as long, and the job the first
one queued answers it.
"""
import argparse
import binascii
import http.client
import json
import os
import stat
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request

MESH_TYPES = {".obj": "model/obj", ".bpt": "model/x-bpt", ".drc": "model/x-draco",
              ".stl": "model/stl", ".ply": "model/x-ply", ".glb": "model/gltf-binary",
              ".gltf": "model/gltf+json", ".off": "model/x-off"}
TERMINAL = ("succeeded", "failed", "canceled")


class VoxeldError(Exception):
    """An error answer: status, code and message from {"error": {...}}."""

    def __init__(self, status, code, message, retry_after=None):
        super().__init__("%s (%s, HTTP %d)" % (message, code, status))
        self.status, self.code, self.message = status, code, message
        self.retry_after = retry_after  # seconds, from Retry-After; None without one
        self.refused = False  # unreachable: no connection was made


class Client:
    def __init__(self, server=None, token=None, timeout=120, retry_for=120):
        """ValueError for a server that is no http(s) URL or a token that no
        header can carry (a blank or control character)."""
        self.server = (server or os.environ.get("VOXELD_URL") or "http://127.0.0.1:8080").rstrip("/")
        self.token = token if token is not None else os.environ.get("VOXELD_TOKEN")
        self.timeout = timeout
        self.retry_for = retry_for
        if not self.server.lower().startswith(("http://", "https://")):
            raise ValueError("the server wants an http:// or https:// URL, not %r" % self.server)
        if self.token and not all(0x21 <= ord(ch) <= 0x7e for ch in self.token):
            raise ValueError("the token holds a blank or control character, which no header "
                             "can carry")

    def _open(self, method, path, body=None, ctype=None, accept=None, retry=True, key=None):
        """The response of a 2xx; a 429 or 503 with Retry-After is sent
        again for up to retry_for seconds (with retry). key: sent as the
        Idempotency-Key."""
        give_up = time.monotonic() + (self.retry_for if retry else 0)
        while True:
            try:
                return self._open_once(method, path, body, ctype, accept, key)
            except VoxeldError as e:
                # (too_many_waits: the caller asks again without wait)
                if e.status not in (429, 503) or e.retry_after is None or e.code == "too_many_waits":
                    raise
                pause = min(max(e.retry_after, 1), 30)
                if time.monotonic() + pause > give_up:
                    raise
                time.sleep(pause)

    def _open_once(self, method, path, body, ctype, accept, key=None):
        req = urllib.request.Request(self.server + path, data=body, method=method)
        if ctype:
            req.add_header("Content-Type", ctype)
        if key:
            req.add_header("Idempotency-Key", key)
        if accept:
            req.add_header("Accept", accept)
        if self.token:
            req.add_header("Authorization", "Bearer " + self.token)
        try:
            return _OPENER.open(req, timeout=self.timeout)
        except urllib.error.HTTPError as e:
            raw = e.read()
            retry_after = _retry_after(e.headers.get("Retry-After"))
            try:
                err = json.loads(raw)["error"]
                code, message = err["code"], err["message"]
            except (ValueError, KeyError, TypeError):
                code = "http_error"
                message = raw[:200].decode("utf-8", "replace").strip() or \
                    "HTTP %d %s" % (e.code, e.reason or "")
                if 300 <= e.code < 400:
                    message += " (a redirect to %s, not followed)" % e.headers.get("Location")
            raise VoxeldError(e.code, code, message, retry_after) from None
        except urllib.error.URLError as e:
            err = VoxeldError(0, "unreachable", "%s: %s" % (self.server, e.reason))
            # (urllib raises it while connecting and sending: the request was
            # not taken whole; a lost answer comes as what follows)
            err.refused = True
            raise err from None
        except (http.client.HTTPException, OSError) as e:  # reset, timeout, closed early
            raise VoxeldError(0, "unreachable", "%s: %s" % (self.server, e or type(e).__name__)) from None

    def _json(self, method, path, doc=None, key=None):
        """The JSON of a 2xx. With key (an Idempotency-Key), a request
        whose answer was lost after it was sent, before its head or in its
        body, is sent again every 2 s for up to retry_for seconds from the
        loss, and so is one the server refuses after that (restarting)."""
        body = json.dumps(doc).encode() if doc is not None else None
        give_up = None  # set at the first loss
        while True:
            try:
                with self._open(method, path, body, "application/json" if body else None,
                                key=key) as r:
                    try:
                        return _load(r, path)
                    except (http.client.HTTPException, OSError) as e:
                        raise VoxeldError(0, "unreachable", "%s: the answer was cut short: %s"
                                          % (path, e or type(e).__name__)) from None
            except VoxeldError as e:
                if key is None or e.code != "unreachable" or (e.refused and give_up is None):
                    raise
                give_up = give_up or time.monotonic() + self.retry_for
                if time.monotonic() + 2 > give_up:
                    raise
                time.sleep(2)

    def upload(self, path, name=None):
        """Stores a mesh file; returns the Mesh (its "id" names it in jobs).
        The mesh is named after the file (or name) when the server would
        take it as a name (1 to 100 bytes of UTF-8, no control character,
        '/', '\\' or '"', not "." or ".."): result downloads carry it."""
        ctype = MESH_TYPES.get(os.path.splitext(path)[1].lower(), "application/octet-stream")
        with open(path, "rb") as f:
            data = f.read()
        name = os.path.basename(path) if name is None else name
        q = "?name=" + urllib.parse.quote(name, safe="") if _name_ok(name) else ""
        with self._open("POST", "/v1/meshes" + q, data, ctype) as r:
            return _with_id(_load(r, "/v1/meshes"), 64)

    def submit(self, mesh, kind, params=None, idempotency_key=None):
        """Queues a job; returns the Job (the one the key queued before,
        when the same request came with it)."""
        key = idempotency_key or binascii.hexlify(os.urandom(16)).decode()
        return _as_job(self._json("POST", "/v1/jobs",
                                  {"mesh": mesh, "kind": kind, "params": params or {}}, key))

    def job(self, jid, wait=0, progress=None):
        """The Job; wait > 0 holds until it ends (or reaches progress)."""
        q = "?wait=" + _decimal(wait) if wait else ""
        if wait and progress is not None:
            q += "&progress=" + _decimal(progress)
        return _as_job(self._json("GET", "/v1/jobs/" + urllib.parse.quote(jid, safe="") + q))

    def jobs(self, state=None, limit=100):
        q = {"limit": "%d" % limit}
        if state:
            q["state"] = state
        return self._json("GET", "/v1/jobs?" + urllib.parse.urlencode(q))["items"]

    def meshes(self, limit=100):
        return self._json("GET", "/v1/meshes?limit=%d" % limit)["items"]

    def cancel(self, jid):
        """Cancels a queued or running job; a finished one is an error
        (job_finished: cancel never deletes results, delete does)."""
        job = self.job(jid)
        if job["state"] in ("succeeded", "failed", "canceled"):
            raise VoxeldError(409, "job_finished", "job %s has already finished" % jid)
        with self._open("DELETE", "/v1/jobs/" + urllib.parse.quote(jid, safe="")) as r:
            raw = r.read()
            return json.loads(raw) if raw else None  # 204: it finished meanwhile, deleted

    def delete(self, jid):
        """Deletes a finished job and its results (cancels an unfinished one)."""
        with self._open("DELETE", "/v1/jobs/" + urllib.parse.quote(jid, safe="")) as r:
            raw = r.read()
            return json.loads(raw) if raw else None

    def events(self, jid):
        """Yields the Job at each event of GET /v1/jobs/{jid}/events, until it
        ends (or the server closes the stream: a restart; a dropped
        connection raises VoxeldError unreachable)."""
        # (no retry: wait() polls instead when streams are busy, 503)
        with self._open("GET", "/v1/jobs/%s/events" % urllib.parse.quote(jid, safe=""),
                        accept="text/event-stream", retry=False) as r:
            data = []
            while True:
                try:
                    raw = r.readline(_EVENT_MAX)  # (a Job is a few KB: a line is held whole)
                except (http.client.HTTPException, OSError) as e:
                    raise VoxeldError(0, "unreachable", "%s: %s" % (self.server, e or type(e).__name__)) from None
                if not raw:
                    return
                if len(raw) >= _EVENT_MAX and not raw.endswith(b"\n"):
                    raise VoxeldError(0, "bad_answer", "an event line over %d bytes" % _EVENT_MAX)
                line = raw.decode("utf-8", "replace").rstrip("\r\n")
                if not line:
                    if data:
                        try:
                            doc = json.loads("\n".join(data))
                        except ValueError:
                            raise VoxeldError(0, "bad_answer", "an event that is not JSON") from None
                        yield _as_job(doc)
                    data = []
                elif line.startswith("data:"):
                    data.append(line[5:].lstrip(" "))

    def wait(self, jid, on_event=None):
        """Follows the job to its end; returns the last Job. A server that
        stops answering (unreachable, 502, 503, 504: restarting, where the
        job goes on) is asked again for up to retry_for seconds; one that
        holds as many waits as it allows (503 too_many_waits) is asked
        without one, Retry-After seconds apart."""
        last = None
        try:
            for job in self.events(jid):
                last = job
                if on_event:
                    on_event(job)
        except VoxeldError as e:
            if e.status not in (0, 502, 503, 504):
                raise
        lost = None
        while last is None or last["state"] not in TERMINAL:
            t0 = time.monotonic()
            try:
                last = self.job(jid, wait=30)
                lost = None
                # a server that answers ?wait at once (--request-timeout 0)
                # is asked once a second, not as fast as it answers
                if last["state"] not in TERMINAL:
                    time.sleep(max(0.0, 1.0 - (time.monotonic() - t0)))
            except VoxeldError as e:
                if e.code == "too_many_waits":
                    time.sleep(min(max(e.retry_after or 2, 1), 30))
                    last = self.job(jid)
                    lost = None
                    if on_event:
                        on_event(last)
                    continue
                if e.status not in (0, 502, 503, 504):
                    raise
                lost = lost or time.monotonic()
                if time.monotonic() - lost > self.retry_for:
                    raise
                time.sleep(2)
                continue
            if on_event:
                on_event(last)
        return last

    def download(self, jid, out, name=None):
        """Writes the primary result (or output name) to the file out,
        through a temporary file beside it renamed over it once whole: a
        failed or cut-short download (VoxeldError, code "incomplete") leaves
        no file, or the old one."""
        path = "/v1/jobs/%s/result" % urllib.parse.quote(jid, safe="") + \
            ("/" + urllib.parse.quote(name, safe="") if name else "")
        final = os.path.realpath(out)  # a symlink's target is replaced
        try:
            st = os.stat(final)
        except FileNotFoundError:
            st = None
        part = None  # stays None for /dev/null, a FIFO: written in place
        with self._open("GET", path) as r:
            length = r.headers.get("Content-Length")
            coding = r.headers.get("Content-Encoding", "identity").strip().lower()
            # (no Range or Accept-Encoding was sent: anything but the whole
            # file as it is would be saved as the result)
            if r.status != 200 or coding != "identity":
                raise VoxeldError(0, "incomplete", "%s: HTTP %d with Content-Encoding %s, where "
                                  "the whole file as it is was asked for" % (path, r.status, coding))
            if st is None or stat.S_ISREG(st.st_mode):
                fd, part = tempfile.mkstemp(prefix=".voxeld-", suffix=".part",
                                            dir=os.path.dirname(final))
            try:
                if part:
                    os.chmod(part, stat.S_IMODE(st.st_mode) if st else 0o666 & ~_umask())
                got = 0
                with (os.fdopen(fd, "wb") if part else open(final, "wb")) as f:
                    while True:
                        try:
                            chunk = r.read(1 << 16)
                        except (http.client.HTTPException, OSError) as e:
                            raise VoxeldError(0, "incomplete", "%s after %d bytes: %s"
                                              % (path, got, e or type(e).__name__)) from None
                        if not chunk:
                            break
                        f.write(chunk)
                        got += len(chunk)
                if length is not None and length.isdigit() and got != int(length) \
                        and not r.headers.get("Content-Encoding"):
                    raise VoxeldError(0, "incomplete", "%s: %d of %s bytes" % (path, got, length))
                if part:
                    os.replace(part, final)
            except BaseException:
                if part:
                    os.unlink(part)
                raise
        return out


_EVENT_MAX = 1 << 20


def _load(r, path):
    """The JSON of an answer; VoxeldError bad_answer when it is none."""
    try:
        return json.load(r)
    except ValueError:
        raise VoxeldError(0, "bad_answer", "%s: the answer is not JSON" % path) from None


def _with_id(doc, n):
    """doc when its "id" is n hex digits (what the server makes; it goes into
    later paths), else VoxeldError bad_answer."""
    i = doc.get("id") if isinstance(doc, dict) else None
    if not (isinstance(i, str) and len(i) == n and all(c in "0123456789abcdefABCDEF" for c in i)):
        raise VoxeldError(0, "bad_answer", "the answer has no id of %d hex digits" % n)
    return doc


def _as_job(doc):
    """doc when it is a Job (a hex id, a state), else VoxeldError bad_answer."""
    if not isinstance(_with_id(doc, 32).get("state"), str):
        raise VoxeldError(0, "bad_answer", "the answer is not a Job (no state)")
    return doc


def _fraction(p):
    """A progress from the server as 0..1 (a string, NaN, 1e20: clamped)."""
    return min(max(p, 0.0), 1.0) if isinstance(p, (int, float)) and p == p else 0.0


def _shown(s):
    """The server's text for a terminal: control characters as '?' (an
    escape sequence in a message could clear the screen or retitle it)."""
    return "".join("?" if ord(ch) < 0x20 or 0x7f <= ord(ch) < 0xa0 else ch for ch in str(s))


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    """voxeld answers no redirect: a 3xx is an error (HTTPError), never
    followed (urllib sent the token on to wherever Location pointed)."""

    def redirect_request(self, req, fp, code, msg, headers, newurl):
        return None


_OPENER = urllib.request.build_opener(_NoRedirect)


def _retry_after(v):
    """Retry-After's delay-seconds (an HTTP-date too) as seconds, or None."""
    if v is None:
        return None
    v = v.strip()
    if v.isdigit():
        return int(v)
    try:
        import email.utils
        return max(0, int(email.utils.parsedate_to_datetime(v).timestamp() - time.time()))
    except (TypeError, ValueError, IndexError):
        return None


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _decimal(x):
    """x as the plain decimal the server's query parameters take (no
    exponent: 1e+06 is refused), to the microsecond."""
    return ("%.6f" % x).rstrip("0").rstrip(".")


def _param(kv):
    key, sep, value = kv.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError("want KEY=VALUE, not %r" % kv)
    try:
        return key, json.loads(value)
    except ValueError:
        return key, value


def _name_ok(name):
    """The server's rule for mesh names, in short (bidi and other invisible
    format characters are refused too: such a name is simply not sent)."""
    b = name.encode("utf-8", "surrogateescape")
    try:
        b.decode("utf-8")
    except UnicodeDecodeError:
        return False
    bad = set(range(0x20)) | {0x7f, ord("/"), ord("\\"), ord('"')}
    invisible = any(0x80 <= ord(ch) <= 0x9f or ord(ch) in (0x61c, 0xfeff)
                    or 0x200b <= ord(ch) <= 0x200f or 0x202a <= ord(ch) <= 0x202e
                    or 0x2060 <= ord(ch) <= 0x206f for ch in name)
    return 1 <= len(b) <= 100 and name not in (".", "..") and not invisible \
        and not any(c in bad for c in b)


def _unwritable(out):
    """Why download() could not write out (None: it could): a regular file
    goes through a part file beside it, anything else (a device, a FIFO)
    is written in place."""
    final = os.path.realpath(out)
    if os.path.isdir(final):
        return "a directory"
    if os.path.exists(final) and not os.path.isfile(final):
        return None if os.access(final, os.W_OK) else "permission denied"
    where = os.path.dirname(final)
    if not os.path.isdir(where):
        return "no such directory"
    return None if os.access(where, os.W_OK | os.X_OK) else "permission denied"


def main(argv=None):
    ap = argparse.ArgumentParser(description="Run one voxeld job on a mesh file.")
    ap.add_argument("--server")
    ap.add_argument("--token")
    ap.add_argument("kind")
    ap.add_argument("file")
    ap.add_argument("-p", "--param", type=_param, action="append", default=[])
    ap.add_argument("-o", "--output")
    a = ap.parse_args(argv)
    try:
        c = Client(a.server, a.token)
    except ValueError as e:
        print("voxeld_client: %s" % e, file=sys.stderr)
        return 2
    why = _unwritable(a.output) if a.output else None
    if why:  # said before the job runs, not after
        print("voxeld_client: cannot write %s: %s" % (a.output, why), file=sys.stderr)
        return 1
    job = None
    try:
        mesh = c.upload(a.file)["id"]
        job = c.submit(mesh, a.kind, dict(a.param))
        job = c.wait(job["id"], lambda j: print("%s %s %3.0f%%" % (j["id"], _shown(j["state"]),
                                                                 100 * _fraction(j.get("progress"))),
                                               file=sys.stderr))
        if job["state"] != "succeeded":
            e = job.get("error")
            said = "%s (%s)" % (e.get("message"), e.get("code")) if isinstance(e, dict) \
                else "(the server gave no error)"
            print("job %s: %s" % (_shown(job["state"]), _shown(said)), file=sys.stderr)
            return 1
        if a.output and job.get("outputs"):
            c.download(job["id"], a.output)
            print("wrote " + a.output, file=sys.stderr)
        elif a.output:
            print("job %s wrote no file (its results are its stats, printed below): %s not "
                  "written" % (job["id"], a.output), file=sys.stderr)
        print(json.dumps(job))
        return 0
    except VoxeldError as e:
        print("voxeld: %s" % _shown(e), file=sys.stderr)
        return 1
    except OSError as e:  # the mesh file or the output file
        print("voxeld_client: %s" % e, file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C: the job, if submitted, goes on
        if job:
            print("\nvoxeld_client: interrupted; job %s goes on (DELETE /v1/jobs/%s cancels it)"
                  % (job["id"], job["id"]), file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
