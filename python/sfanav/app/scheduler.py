"""The Dask scheduler of ``sfanav train --scheduler ADDRESS``, reached
within a bounded time or refused in one line.

``dask.distributed.Client(ADDRESS, timeout=...)`` bounds the TCP connection
only: a port that accepts and never answers keeps it waiting for the
handshake with no end, and another service's port (an HTTP server) answers
with bytes that Dask reads as a frame length of exabytes. An address without
a port is refused only inside the Client, whose half-made object then
prints "Exception ignored in Client.__del__" ten seconds later. So
:func:`connect_scheduler` checks first, in this order, and builds the Client
only once a Dask scheduler has answered:

1. the address parses, with a port for the network schemes (``tcp://HOST:PORT``,
   ``tls://``, ``ws://``, ``wss://``; a bare ``HOST:PORT`` is TCP);
2. a TCP connection to it opens ("cannot reach the Dask scheduler at ...");
3. Dask's handshake and an ``identity`` request get a scheduler's answer
   ("no Dask scheduler at ...": nothing answered, or something that is not
   a Dask scheduler).

All within ``SCHEDULER_TIMEOUT`` seconds in all.
"""

from __future__ import annotations

import asyncio
import socket
import time
from typing import Any

from .failures import UsageError

SCHEDULER_TIMEOUT = 5.0
"""Seconds, in all, to reach the Dask scheduler and hear it answer."""


NETWORK_SCHEMES = ("tcp", "tls", "ws", "wss")


def connect_scheduler(address: str, timeout: float = SCHEDULER_TIMEOUT) -> Any:
    """A ``dask.distributed.Client`` of the scheduler at ``address``, or a
    UsageError (one line) when Dask is missing, the address is malformed,
    nothing listens there, or what listens is no Dask scheduler answering
    within ``timeout`` seconds, or it has no workers. The Client is made
    only after the scheduler answered, so a refusal leaves nothing behind
    to clean up."""
    try:
        from distributed import Client
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import get_backend
    except ImportError:
        raise UsageError('--scheduler needs Dask: pip install "sfanav[dask]"') from None
    shown = repr(address) if not address or address != address.strip() or " " in address else address
    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)
        hostport = parse_host_port(loc) if scheme in NETWORK_SCHEMES else None
    except (ValueError, TypeError) as exc:
        raise UsageError(f"--scheduler {shown} is not a Dask scheduler address (tcp://HOST:PORT): {exc}") from None
    deadline = time.monotonic() + timeout
    if hostport is not None:
        host, port = hostport
        if not 0 < port < 65536:
            raise UsageError(f"--scheduler {shown} is not a Dask scheduler address: port {port} is not in 1..65535")
        try:
            socket.create_connection((host, port), timeout=timeout).close()
        except OSError as exc:
            raise UsageError(f"cannot reach the Dask scheduler at {address}: {_reason(exc)}") from None
    answer = _identity(address, max(0.1, deadline - time.monotonic()), timeout)
    if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
        what = answer.get("type") if isinstance(answer, dict) and isinstance(answer.get("type"), str) else None
        raise UsageError(f"no Dask scheduler at {address}: " + (
            f"a Dask {what} answered" if what else "what answers there does not speak Dask"))
    try:
        client = Client(address, timeout=max(1.0, deadline - time.monotonic()), set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise UsageError(f"cannot reach the Dask scheduler at {address}: {_reason(exc)}") from None
    if not client.scheduler_info().get("workers"):
        client.close()
        raise UsageError(f"the Dask scheduler at {address} has no workers")
    return client


def _identity(address: str, budget: float, timeout: float) -> Any:
    """What the Dask server at ``address`` says it is (its ``identity``
    answer), asked within ``budget`` seconds; a UsageError when no Dask
    answer comes."""
    try:
        return asyncio.run(asyncio.wait_for(_ask_identity(address, budget), budget))
    except (asyncio.TimeoutError, TimeoutError):
        raise UsageError(f"no Dask scheduler at {address}: the port accepts connections but no Dask answer came "
                         f"within {timeout:g} s (another service there, or a scheduler that hangs?)") from None
    except Exception as exc:  # noqa: BLE001 - any failure to speak Dask with it: not a scheduler
        raise UsageError(f"no Dask scheduler at {address}: what answers there does not speak Dask "
                         f"({_reason(exc)})") from None


async def _ask_identity(address: str, timeout: float) -> Any:
    from distributed.comm import connect
    from distributed.security import Security

    comm = await connect(address, timeout=timeout, **Security().get_connection_args("client"))
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


def _reason(exc: BaseException) -> str:
    if isinstance(exc, MemoryError):
        return "its answer announced an impossible length"
    msg = " ".join(str(exc).split())
    return msg or type(exc).__name__


__all__ = ["SCHEDULER_TIMEOUT", "connect_scheduler"]
