"""A rig's `--lcm-url`, checked whole before the run, and its bus opened without LCM's chatter.

LCM's C library prints its own messages on stderr and the Python binding only says "Couldn't
create LCM" (DrakeLcm not even that: it runs on without a bus): `udpm://999.1.1.1:99999`
printed `Error: Bad multicast IP address` and the run sent its 81 commands into nothing. So
the URL is checked here first, then opened once with stderr captured, and what LCM said is
folded into one line.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from collections.abc import Callable
from typing import IO, TypeVar

LCM_PROVIDERS = ("memq", "udpm", "mpudpm", "tcpq", "file")  # what LCM's C library provides
UDPM_OPTIONS = {"ttl": (0, 255), "recv_buf_size": (1, 2**31 - 1)}  # name: (least, most)
_HOST = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,252})")
T = TypeVar("T")


def lcm_url_problem(url: str) -> str | None:
    """Why `url` cannot be a rig's LCM bus, or None: a provider of LCM's; udpm:// and
    mpudpm:// a multicast IPv4 address (224.0.0.0 to 239.255.255.255), a port 1 to 65535 and
    the options ttl (0 to 255) and recv_buf_size; memq:// nothing more; tcpq:// a host and a
    port; file:// refused (a log is not a live bus)."""
    provider, sep, rest = url.partition("://")
    if not sep or provider not in LCM_PROVIDERS:
        return (f"is not an LCM URL: expected PROVIDER://... with a provider of "
                f"{', '.join(LCM_PROVIDERS)}")
    if provider == "file":
        return ("a log file is not a bus: the rig needs a live one (udpm://ADDRESS:PORT, or "
                "memq:// with --sim-rig); --log names the log to write")
    target, _, query = rest.partition("?")
    if provider == "memq":
        return "memq:// takes no address or options" if rest else None
    if provider == "tcpq":
        if query:
            return "tcpq:// takes no options"
        host, colon, port = target.rpartition(":")
        if not colon or not _HOST.fullmatch(host):
            return "expected tcpq://HOST:PORT"
        return _port_problem(port)
    if target:  # udpm, mpudpm: LCM's default address and port when none is given
        address, colon, port = target.partition(":")
        problem = _multicast_problem(address) or (_port_problem(port) if colon else None)
        if problem:
            return problem
    for option in query.split("&") if query else ():
        name, equals, value = option.partition("=")
        if name not in UDPM_OPTIONS or not equals:
            return (f"unknown option {option!r}: {provider}:// takes "
                    f"{' and '.join(f'{k}=N' for k in UDPM_OPTIONS)}")
        least, most = UDPM_OPTIONS[name]
        if not (value.isascii() and value.isdigit() and least <= int(value) <= most):
            return f"{name} must be a whole number from {least} to {most:,}, got {value!r}"
    return None


def _multicast_problem(address: str) -> str | None:
    parts = address.split(".")
    if (len(parts) != 4 or not all(p.isascii() and p.isdigit() and len(p) <= 3 for p in parts)
            or any(int(p) > 255 for p in parts)):
        return f"{address!r} is not an IPv4 address"
    if not 224 <= int(parts[0]) <= 239:
        return f"{address!r} is not a multicast address (224.0.0.0 to 239.255.255.255)"
    return None


def _port_problem(port: str) -> str | None:
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        return f"the port must be a whole number from 1 to 65535, got {port!r}"
    return None


def _scratch_file() -> IO[bytes]:
    """An anonymous file: in memory where the system makes one (Linux's memfd), so that no
    temporary folder is needed (with none usable, every rig-run ended in "error: (file): No
    usable temporary directory found"), else a temporary file."""
    if hasattr(os, "memfd_create"):
        with contextlib.suppress(OSError):
            return os.fdopen(os.memfd_create("rbp-lcm-said"), "w+b")
    return tempfile.TemporaryFile()


def quietly(make: Callable[[], T]) -> tuple[T | None, str]:
    """(make(), '') or (None, what it printed) if it raised RuntimeError: LCM's C library
    writes to file descriptor 2, which is captured into an anonymous file while it runs."""
    sys.stderr.flush()
    saved = os.dup(2)
    with _scratch_file() as said:
        os.dup2(said.fileno(), 2)
        try:
            return make(), ""
        except RuntimeError as e:
            failed = str(e)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        said.seek(0)
        text = " ".join(said.read(2000).decode(errors="replace").split())
    return None, text or failed


def open_problem(url: str) -> str | None:
    """Why LCM cannot open `url` (what it printed, in one line), or None."""
    import lcm

    bus, said = quietly(lambda: lcm.LCM(url))
    if bus is None:
        return f"LCM cannot open it: {said}"
    del bus  # closes it: the run opens its own
    return None
