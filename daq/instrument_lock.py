"""One process at a time on each instrument of a lab bench: a lock per instrument address.

Two processes could drive one rig. A ``biafc check --move`` in a second terminal, a second
``run_protocol``, or the bench window beside a headless run would each open the same
instruments. On Linux a serial port opens twice without complaint (pyserial does not lock it),
and VISA shares a USB or LAN instrument between sessions. So the second process's commands mix
with the running scan's: the stage moves under a measurement, the generator is set to another
amplitude, a serial reply goes to the wrong process. The scan's data are then wrong, and
nothing says so.

:func:`lock_instruments` takes a lock per address before :func:`daq.connect.connect_bench` opens
anything: the generator's VISA resource, the vibrometer's and the stage's ports, the DAQ device.
A second process is refused in one line naming the instrument and the process that holds it
(exit status 2). The locks are those of the run files (:class:`daq.store.lock.RunFileLock`):
a lock left by a process that no longer runs is taken over. They live in the user's cache
folder (``<cache_dir>/instruments``), so they guard the processes of one user account. One
process may connect its bench again (the bench window reconnecting): the locks count its
connections. A simulated bench is never locked: its instruments are its process's own.
"""

from __future__ import annotations

import hashlib
import ipaddress
import os
import re
import socket
import threading
from pathlib import Path
from typing import Any

from daq.store.lock import FileInUse, LockNotWritable, RunFileLock, command_shown

__all__ = ["InstrumentInUse", "InstrumentLocks", "canonical", "lock_instruments"]

#: this process's held locks: lock path -> the lock and the connections that hold it
_HELD: dict[Path, tuple[RunFileLock, int]] = {}
_GUARD = threading.Lock()


class InstrumentInUse(RuntimeError):
    """Another live process holds an instrument of the bench (the message is one line)."""


class _InstrumentLock(RunFileLock):
    """A run file's lock, worded for an instrument."""

    def __init__(self, path: Path, what: str) -> None:
        super().__init__(path)
        self.what = what

    def _in_use(self, other: dict[str, Any]) -> str:
        return (
            f"{self.what} is in use by process {other.get('pid')} on {other.get('host', '?')} "
            f"(since {other.get('since')}: {command_shown(other)}); wait for it to "
            "end or stop it"
        )


def _drop(path: Path) -> None:
    """One connection of this process lets ``path`` go; the last removes the lock file.
    Call with ``_GUARD`` held."""
    lock, count = _HELD.pop(path)
    if count > 1:
        _HELD[path] = (lock, count - 1)
    else:
        lock.release()


def _folder() -> Path:
    from instruments.user_cache import cache_dir

    return cache_dir() / "instruments"


def canonical(address: str) -> str:
    """One spelling per device, so that two bench files naming one port or card differently
    take one lock (a second reader: ``COM3`` and ``ASRL3::INSTR``, ``/dev/ttyUSB0`` and
    ``ASRL/dev/ttyUSB0::INSTR``, ``Dev1`` and ``dev1`` took two): a VISA serial resource is
    its port (``ASRLn`` is ``COMn``), a LAN instrument its host's address (board number and
    protocol left out; a host name resolved as the connect will resolve it), a USB one its
    vendor, product and serial (ids as numbers), a serial device path its real path, and
    anything else (an NI device name) is upper-cased (VISA and NI names are
    not case sensitive)."""
    a = address.strip()
    m = re.fullmatch(r"ASRL(.+?)(::INSTR)?", a, flags=re.IGNORECASE)
    if m is not None:
        port = m.group(1)
        a = f"COM{port}" if port.isdigit() else port
    if a.startswith("/"):
        return os.path.realpath(a)  # a device path (a /dev/serial/by-id link is its tty)
    tcp = re.fullmatch(r"TCPIP\d*::([^:]+)(::.*)?", a, flags=re.IGNORECASE)
    if tcp is not None:  # one instrument whatever the protocol (INSTR, inst0, hislip, SOCKET)
        return f"TCPIP::{_host_address(tcp.group(1))}"
    usb = re.fullmatch(r"USB\d*::([^:]+)::([^:]+)::([^:]+)(::.*)?", a, flags=re.IGNORECASE)
    if usb is not None:  # vendor and product as numbers (0x0957 is 2391), and the serial
        try:
            vendor, product = int(usb.group(1), 0), int(usb.group(2), 0)
        except ValueError:
            return a.upper()
        return f"USB::{vendor}::{product}::{usb.group(3).upper()}"
    return a.upper()


#: seconds a LAN instrument's host name may take to resolve for its lock (then the name is
#: the lock's key, as for a name that does not resolve)
LOOKUP_TIMEOUT_S = 2.0


def _host_address(host: str) -> str:
    """A LAN instrument's IPv4 address (the lowest, where a name has several), so that its
    name and its address are one lock; the name upper-cased where it does not resolve (the
    connect then fails on it anyway). A written address is taken as it is."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        pass
    found: list[Any] = []

    def look_up() -> None:
        try:
            found.extend(
                socket.getaddrinfo(host, None, family=socket.AF_INET, type=socket.SOCK_STREAM)
            )
        except (OSError, UnicodeError):
            pass

    # a name server that does not answer must not hold the connect (nor, before the locks'
    # guard was taken after it, every other lock of this process) for its own timeout
    t = threading.Thread(target=look_up, name="biafc-lock-lookup", daemon=True)
    t.start()
    t.join(LOOKUP_TIMEOUT_S)
    addresses = sorted({str(info[4][0]) for info in list(found)}, key=ipaddress.ip_address)
    return addresses[0] if addresses and not t.is_alive() else host.upper()


def _name(address: str) -> str:
    """A file name for an instrument address (readable, and unique by its hash of the
    :func:`canonical` address)."""
    key = canonical(address)
    slug = re.sub(r"[^A-Za-z0-9]+", "_", key).strip("_")[:48] or "instrument"
    return f"{slug}-{hashlib.sha256(key.encode()).hexdigest()[:12]}"


class InstrumentLocks:
    """The locks one connection of a bench holds; :meth:`release` once, when it closes."""

    def __init__(self, paths: list[Path]) -> None:
        self.paths = paths
        self._released = False

    def release(self) -> None:
        with _GUARD:
            if self._released:
                return
            self._released = True
            for path in self.paths:
                _drop(path)


def lock_instruments(addresses: dict[str, str]) -> InstrumentLocks:
    """Lock every instrument of ``addresses`` (role -> address, e.g. ``"generator"`` ->
    ``"USB0::0x0957::0x2807::MY1::INSTR"``) for this process, or raise
    :class:`InstrumentInUse` naming the first one another live process holds (the locks taken
    so far are released)."""
    taken: list[Path] = []
    locks = InstrumentLocks(taken)
    folder = _folder()
    names = {role: _name(address) for role, address in addresses.items()}  # before the guard
    with _GUARD:
        try:
            roles: dict[Path, str] = {}
            for role, address in addresses.items():
                path = folder / names[role]
                if path in roles:  # one bench file naming one device for two roles
                    raise InstrumentInUse(
                        f"the {roles[path]} and the {role} are one device ({address}): give each "
                        "instrument its own address in the bench file"
                    )
                roles[path] = role
                if path in _HELD:
                    lock, count = _HELD[path]
                else:
                    lock, count = _InstrumentLock(path, f"the {role} {address}"), 0
                    try:
                        lock.acquire()
                    except LockNotWritable as exc:  # the cache folder: connect says so
                        raise exc.cause from None
                    except FileInUse as exc:
                        raise InstrumentInUse(str(exc)) from None
                _HELD[path] = (lock, count + 1)
                taken.append(path)
        except BaseException:
            locks._released = True
            for path in taken:
                _drop(path)
            raise
    return locks
