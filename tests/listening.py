"""Shared by the binding tests: the TCP sockets a process tree listens on, read from ``/proc`` (Linux only).

A socket is found by its inode: ``/proc/<pid>/fd/*`` links name ``socket:[INODE]`` for every socket a process
holds, and ``/proc/net/tcp`` / ``/proc/net/tcp6`` list every TCP socket of the network namespace with its local
address, state and inode. Nothing is asked of the sockets themselves, so a server cannot answer differently.
"""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path

_LISTEN = "0A"  # TCP_LISTEN in /proc/net/tcp's "st" column


@dataclass(frozen=True, slots=True)
class Listener:
    """One listening TCP socket: its local address and port, the process holding it, the socket's inode."""

    address: str
    port: int
    pid: int
    process: str
    inode: int

    @property
    def loopback(self) -> bool:
        """Bound to 127.0.0.0/8 or ::1 (an IPv4-mapped ``::ffff:127.x.y.z`` counts as its IPv4 address)."""
        ip = ipaddress.ip_address(self.address)
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return ip.is_loopback

    def __str__(self) -> str:
        shown = f"[{self.address}]" if ":" in self.address else self.address
        return f"{self.process} (pid {self.pid}) on {shown}:{self.port}"


def process_tree(root: int) -> list[int]:
    """``root`` and every process descended from it (read from ``/proc/*/stat``)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:  # it ended meanwhile
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])  # the name in parentheses may hold spaces
        children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(children.get(pid, []))
    return out


def _process_name(pid: int) -> str:
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return "?"
    return os.path.basename(argv[0].decode(errors="replace")) or "?"


def _socket_inodes(pids: list[int]) -> dict[int, int]:
    """Socket inode -> the pid holding it, for every socket the processes ``pids`` have open."""
    out: dict[int, int] = {}
    for pid in pids:
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if link.startswith("socket:["):
                out.setdefault(int(link[8:-1]), pid)
    return out


def _address(hex_ip: str) -> str:
    """The address of a ``/proc/net/tcp*`` row: 32-bit words in host (little-endian) order."""
    raw = bytes.fromhex(hex_ip)
    raw = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
    ip = ipaddress.ip_address(raw)
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        return f"::ffff:{ip.ipv4_mapped}"  # an IPv4 address on a dual-stack socket, shown as such
    return str(ip)


def listeners(root: int | None = None) -> list[Listener]:
    """Every TCP socket in LISTEN state held by process ``root`` (default: this one) or its descendants."""
    pids = process_tree(os.getpid() if root is None else root)
    inodes = _socket_inodes(pids)
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for row in Path(table).read_text().splitlines()[1:]:
            f = row.split()
            inode = int(f[9])
            if f[3] != _LISTEN or inode not in inodes:
                continue
            ip, port = f[1].split(":")
            pid = inodes[inode]
            out.append(Listener(_address(ip), int(port, 16), pid, _process_name(pid), inode))
    return sorted(out, key=lambda s: (s.process, s.port))
