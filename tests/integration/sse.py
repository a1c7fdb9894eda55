#!/usr/bin/env python3
"""Reads one Server-Sent Events stream (GET /v1/jobs/{id}/events) and prints
what arrived as JSON: {"status", "content_type", "events": [{"event", "id",
"data"}], "comments", "complete", "seconds"}. data is the parsed JSON of each
event's data line(s). complete = the server ended the response (not a
timeout or a reset).

usage: sse.py URL [--token T] [--stall S] [--max-time S] [--ready FILE]
  --stall S    read nothing for S seconds after the head (a slow reader)
  --ready FILE create FILE once the response head has arrived
"""
import argparse
import http.client
import json
import os
import sys
import time
import urllib.parse


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--token")
    ap.add_argument("--stall", type=float, default=0)
    ap.add_argument("--max-time", type=float, default=120)
    ap.add_argument("--ready")
    a = ap.parse_args()
    u = urllib.parse.urlsplit(a.url)
    t0 = time.monotonic()
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=a.max_time)
    headers = {"Accept": "text/event-stream"}
    if a.token:
        headers["Authorization"] = "Bearer " + a.token
    conn.request("GET", u.path + ("?" + u.query if u.query else ""), headers=headers)
    resp = conn.getresponse()
    out = {"status": resp.status, "content_type": resp.getheader("Content-Type"),
           "events": [], "comments": 0, "complete": False}
    if a.ready:
        open(a.ready, "w").close()
    if resp.status != 200:
        out["body"] = resp.read().decode("utf-8", "replace")
        out["complete"] = True
    else:
        if a.stall:
            time.sleep(a.stall)
        cur = {}
        try:
            while time.monotonic() - t0 < a.max_time:
                line = resp.readline()
                if not line:
                    out["complete"] = True
                    break
                line = line.decode("utf-8").rstrip("\r\n")
                if line == "":
                    if cur:
                        cur["data"] = json.loads(cur.get("data", "null"))
                        out["events"].append(cur)
                    cur = {}
                elif line.startswith(":"):
                    out["comments"] += 1
                else:
                    k, _, v = line.partition(":")
                    v = v[1:] if v.startswith(" ") else v
                    if k == "data" and "data" in cur:
                        cur["data"] += "\n" + v
                    else:
                        cur[k] = v
        except (OSError, http.client.HTTPException) as e:
            out["error"] = str(e)
    out["seconds"] = round(time.monotonic() - t0, 3)
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
