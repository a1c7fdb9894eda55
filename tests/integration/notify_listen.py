"""A notification socket like systemd's (NOTIFY_SOCKET): binds SOCK and
appends each datagram's lines to LOG, each after the monotonic time it
came at ("12.345 WATCHDOG=1"), until killed.

usage: notify_listen.py SOCK LOG
"""
import socket
import sys
import time

s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
s.bind(sys.argv[1])
with open(sys.argv[2], "a", buffering=1) as f:
    while True:
        data = s.recv(65536)
        t = time.monotonic()
        for line in data.decode(errors="replace").split("\n"):
            if line:
                f.write(f"{t:.3f} {line}\n")
