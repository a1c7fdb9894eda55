#!/usr/bin/env python3
"""Slow HTTP clients for test_slow_clients.sh (loopback only, bounded in time).

  slow_clients.py drip PORT SECONDS OUT.json [ADDR...]
      From each ADDR (default 127.0.0.2..127.0.0.9) keeps N connections
      (--per-addr, default 8) sending a request head one byte per 0.5 s,
      reconnecting when one is closed, for SECONDS. Writes to OUT.json, per
      connection that was answered or closed: seconds from connect to the
      first byte of the answer (or the close) and the status line. With
      --body each sends an upload's head at once, then its body at 4 KiB/s.
  slow_clients.py stall PORT HEAD_HEX_OR_TEXT SECONDS
      Sends the given request bytes (\\r\\n escapes allowed), then nothing,
      and prints {"seconds": ..., "response": ...} when the server answers
      or closes (or SECONDS pass).
  slow_clients.py stall-all PORT HEAD_HEX_OR_TEXT SECONDS
      The same, but reads every answer until the server closes (or SECONDS
      pass): for requests pipelined in one send.
  slow_clients.py keepalive-drip PORT SECONDS
      One full GET /livez, then the next head one byte per 0.5 s on the same
      connection; prints what came back and when (seconds after the first
      answer).
"""
import json
import socket
import sys
import time

HEAD = b"GET /livez HTTP/1.1\r\nHost: x\r\nX-Drip: " + b"a" * 200 + b"\r\n\r\n"
# --body: an upload's head at once, then its body at 4 KiB/s (over a
# --min-body-rate of 1024, under 16 times it).
UPLOAD = b"POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: model/obj\r\nContent-Length: 100000000\r\n\r\n"


def connect(port, addr):
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind((addr, 0))
    s.settimeout(2)
    s.connect(("127.0.0.1", port))
    s.setblocking(False)
    return s


def drip(port, seconds, out, addrs, per_addr, upload=False):
    conns = []  # [sock, addr, t_connect, offset, answer]
    done = []
    t_end = time.monotonic() + seconds
    for a in addrs:
        for _ in range(per_addr):
            try:
                conns.append([connect(port, a), a, time.monotonic(), 0, b""])
            except OSError:
                conns.append([None, a, time.monotonic(), 0, b""])
    next_byte = time.monotonic()
    while time.monotonic() < t_end:
        # Answers are looked for every 50 ms, head bytes sent every 0.5 s.
        send_now = time.monotonic() >= next_byte
        if send_now:
            next_byte += 0.5
        for c in conns:
            s = c[0]
            if s is None:
                if send_now:
                    try:
                        c[0], c[2], c[3], c[4] = connect(port, c[1]), time.monotonic(), 0, b""
                    except OSError:
                        pass
                continue
            closed = False
            try:
                b = s.recv(4096)
                if b:
                    c[4] += b
                closed = True  # an answer or EOF ends this connection
            except BlockingIOError:
                pass
            except OSError:
                closed = True
            if not closed and send_now and (upload or c[3] < len(HEAD)):
                try:
                    if upload:
                        chunk = UPLOAD if c[3] == 0 else b"# " + b"a" * 2045 + b"\n"
                    else:
                        chunk = HEAD[c[3]:c[3] + 1]
                    s.send(chunk)
                    c[3] += len(chunk)
                except BlockingIOError:
                    pass
                except OSError:
                    closed = True
            if closed:
                line = c[4].split(b"\r\n", 1)[0].decode("latin-1")
                body = c[4].split(b"\r\n\r\n", 1)[1].decode("latin-1") if b"\r\n\r\n" in c[4] else ""
                done.append({"addr": c[1], "seconds": time.monotonic() - c[2], "status_line": line, "body": body})
                s.close()
                c[0] = None
        time.sleep(0.05)
    for c in conns:
        if c[0] is not None:
            c[0].close()
    with open(out, "w") as f:
        json.dump({"answered": done, "open_at_end": sum(1 for c in conns if c[0] is not None)}, f)


def stall(port, data, seconds, sent=None, whole=False):
    s = socket.create_connection(("127.0.0.1", port))
    t0 = time.monotonic()
    s.sendall(data)
    if sent:  # the caller waits for this file before it goes on
        open(sent, "w").close()
    s.settimeout(seconds)
    got = b""
    try:
        while True:
            b = s.recv(4096)
            if not b:
                break
            got += b
            if not whole and b"\r\n\r\n" in got:
                head, body = got.split(b"\r\n\r\n", 1)
                n = [int(l.split(b":")[1]) for l in head.split(b"\r\n") if l.lower().startswith(b"content-length:")]
                if n and len(body) >= n[0]:
                    break
    except (socket.timeout, OSError):
        pass
    print(json.dumps({"seconds": time.monotonic() - t0, "response": got.decode("latin-1")}))


def read_slowly(port, path, rate, seconds, addrs, per_addr, small_window=True):
    """GETs path on per_addr connections from each address, each with a
    small receive window (or the kernel's own, which grows to megabytes),
    and reads the answer at `rate` bytes/s for at most `seconds`. Prints,
    for each, the bytes of the body read, the body's length, and when the
    server cut it (null: it did not)."""
    conns = []  # [sock, t_connect, got, cut_at]
    for a in addrs:
        for _ in range(per_addr):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            if small_window:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.bind((a, 0))
            s.settimeout(2)
            s.connect(("127.0.0.1", port))
            s.sendall(b"GET " + path.encode() + b" HTTP/1.1\r\nHost: x\r\n\r\n")
            s.setblocking(False)
            conns.append([s, time.monotonic(), b"", None])
    t0 = last = time.monotonic()
    budget = 0.0
    while time.monotonic() - t0 < seconds:
        time.sleep(0.05)
        # the rate by the clock, not by the passes (a loaded machine's
        # sleeps overrun: 50 ms passes would read less than `rate`)
        now = time.monotonic()
        budget += rate * (now - last)
        last = now
        take = int(budget)
        budget -= take
        for c in conns:
            # cut: reset by the server (what was received before the reset
            # could still be read)
            if c[3] is None and c[0].getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 1)[0] != 1:
                c[3] = time.monotonic() - c[1]
            if c[3] is not None or take <= 0:
                continue
            try:
                b = c[0].recv(take)
                if not b:
                    c[3] = time.monotonic() - c[1]
                c[2] += b
            except BlockingIOError:
                pass
            except OSError:
                c[3] = time.monotonic() - c[1]
    out = []
    for s, _, got, cut in conns:
        s.close()
        head, _, body = got.partition(b"\r\n\r\n")
        n = [int(l.split(b":")[1]) for l in head.split(b"\r\n") if l.lower().startswith(b"content-length:")]
        out.append({"status_line": head.split(b"\r\n")[0].decode("latin-1"), "body_read": len(body),
                    "length": n[0] if n else None, "cut_at": cut})
    print(json.dumps(out))


def read_then_reuse(port, path, rate):
    """GETs path on a keep-alive connection with the kernel's own windows,
    reads the whole answer at `rate` bytes/s, then sends GET /livez on the
    same connection. Prints the body's length read and the second answer's
    status line ("" when the server had closed the connection)."""
    s = socket.create_connection(("127.0.0.1", port))
    s.sendall(b"GET " + path.encode() + b" HTTP/1.1\r\nHost: x\r\n\r\n")
    s.settimeout(10)
    got = b""
    while b"\r\n\r\n" not in got:
        b = s.recv(65536)
        if not b:
            break
        got += b
    head, _, body = got.partition(b"\r\n\r\n")
    n = [int(l.split(b":")[1]) for l in head.split(b"\r\n") if l.lower().startswith(b"content-length:")]
    length = n[0] if n else 0
    t0 = last = time.monotonic()
    budget = 0.0
    read = len(body)
    while read < length:
        time.sleep(0.02)
        now = time.monotonic()
        budget += rate * (now - last)
        last = now
        take = int(budget)
        if take <= 0:
            continue
        b = s.recv(min(take, length - read))
        if not b:
            break
        budget -= len(b)
        read += len(b)
    second = b""
    try:
        s.sendall(b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n")
        while b"\r\n" not in second:
            b = s.recv(4096)
            if not b:
                break
            second += b
    except OSError:
        pass
    s.close()
    print(json.dumps({"body_read": read, "length": length, "seconds": round(time.monotonic() - t0, 2),
                      "second": second.split(b"\r\n")[0].decode("latin-1")}))


def keepalive_drip(port, seconds):
    s = socket.create_connection(("127.0.0.1", port))
    s.sendall(b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n")
    s.settimeout(2)
    first = s.recv(4096)
    t0 = time.monotonic()
    s.setblocking(False)
    got, i, next_byte = b"", 0, t0
    while time.monotonic() - t0 < seconds:
        try:
            b = s.recv(4096)
            if not b:
                break
            got += b
            break
        except BlockingIOError:
            pass
        except OSError:
            break
        if time.monotonic() >= next_byte:
            next_byte += 0.5
            try:
                s.send(HEAD[i:i + 1])
                i += 1
            except OSError:
                break
        time.sleep(0.05)
    print(json.dumps({"first": first.decode("latin-1").split("\r\n")[0], "seconds": time.monotonic() - t0,
                      "response": got.decode("latin-1")}))


def per_ip(port, addr, n):
    """n silent connections from addr, then one more that asks for /livez
    (past the per-address limit), read until it closes; then, the n closed,
    /livez again from addr."""
    held = [connect(port, addr) for _ in range(n)]
    time.sleep(0.3)  # accepted and counted before the next one
    s = connect(port, addr)
    s.setblocking(True)
    s.settimeout(5)
    s.sendall(b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n")
    got, closed = b"", False
    try:
        while True:
            b = s.recv(4096)
            if not b:
                closed = True
                break
            got += b
    except (socket.timeout, OSError):
        pass
    s.close()
    for h in held:
        h.close()
    time.sleep(0.3)
    s = connect(port, addr)
    s.setblocking(True)
    s.settimeout(5)
    s.sendall(b"GET /livez HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
    after = b""
    try:
        while True:
            b = s.recv(4096)
            if not b:
                break
            after += b
    except (socket.timeout, OSError):
        pass
    print(json.dumps({"response": got.decode("latin-1"), "closed": closed,
                      "after": after.decode("latin-1").split("\r\n")[0]}))


if __name__ == "__main__":
    cmd, port = sys.argv[1], int(sys.argv[2])
    if cmd == "drip":
        args = sys.argv[3:]
        per = 8
        if "--per-addr" in args:
            k = args.index("--per-addr")
            per = int(args[k + 1])
            del args[k:k + 2]
        upload = "--body" in args
        if upload:
            args.remove("--body")
        addrs = args[2:] or ["127.0.0.%d" % i for i in range(2, 10)]
        drip(port, float(args[0]), args[1], addrs, per, upload)
    elif cmd == "stall":
        stall(port, sys.argv[3].encode().decode("unicode_escape").encode("latin-1"), float(sys.argv[4]),
              sys.argv[5] if len(sys.argv) > 5 else None)
    elif cmd == "stall-all":
        stall(port, sys.argv[3].encode().decode("unicode_escape").encode("latin-1"), float(sys.argv[4]),
              whole=True)
    elif cmd == "per-ip":
        per_ip(port, sys.argv[3], int(sys.argv[4]))
    elif cmd == "read":  # read PORT PATH RATE SECONDS [PER_ADDR ADDR...]
        per = int(sys.argv[6]) if len(sys.argv) > 6 else 1
        read_slowly(port, sys.argv[3], float(sys.argv[4]), float(sys.argv[5]),
                    sys.argv[7:] or ["127.0.0.1"], per)
    elif cmd == "read-big":  # read-big PORT PATH RATE SECONDS: the kernel's windows
        read_slowly(port, sys.argv[3], float(sys.argv[4]), float(sys.argv[5]), ["127.0.0.1"], 1,
                    small_window=False)
    elif cmd == "read-reuse":  # read-reuse PORT PATH RATE
        read_then_reuse(port, sys.argv[3], float(sys.argv[4]))
    elif cmd == "keepalive-drip":
        keepalive_drip(port, float(sys.argv[3]))
