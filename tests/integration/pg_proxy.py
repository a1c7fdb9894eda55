#!/usr/bin/env python3
"""A TCP proxy in front of a PostgreSQL unix socket that can lose answers,
for the cluster tests: the mode is read from MODE_FILE at every chunk.

usage: pg_proxy.py PORT SOCKET MODE_FILE
  pass     forward both ways
  armdown  forward; once a client sends a job's completion (UPDATE ... SET
           state = 'succeeded'), it goes through, then every answer is
           dropped and 0.5 s later every connection is closed and new ones
           refused (mode down): a commit whose answer is lost with the
           database
  down     close every connection, refuse new ones
Prints "ready" once listening."""
import socket
import sys
import threading

port, sock_path, mode_file = int(sys.argv[1]), sys.argv[2], sys.argv[3]
lock = threading.Lock()
conns = []


def mode():
    try:
        with open(mode_file) as f:
            return f.read().strip()
    except OSError:
        return "pass"


def set_mode(m):
    with open(mode_file, "w") as f:
        f.write(m)


def close_all():
    with lock:
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        conns.clear()


def go_down():
    set_mode("down")
    close_all()


def pump(src, dst, to_server):
    try:
        while True:
            d = src.recv(65536)
            if not d:
                break
            m = mode()
            if m == "down":
                break
            if m == "oneway" and not to_server:
                continue  # the answer is lost
            # (one way before the completion goes on: its answer could come
            # back through the other thread before the mode changed)
            if m == "armdown" and to_server and b"SET state = 'succeeded'" in d:
                set_mode("oneway")
                threading.Timer(0.5, go_down).start()
            dst.sendall(d)
    except OSError:
        pass
    for s in (src, dst):
        try:
            s.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass


srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
srv.bind(("127.0.0.1", port))
srv.listen(64)
print("ready", flush=True)
while True:
    c, _ = srv.accept()
    if mode() == "down":
        c.close()
        continue
    u = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        u.connect(sock_path)
    except OSError:
        c.close()
        continue
    with lock:
        conns.extend([c, u])
    threading.Thread(target=pump, args=(c, u, True), daemon=True).start()
    threading.Thread(target=pump, args=(u, c, False), daemon=True).start()
