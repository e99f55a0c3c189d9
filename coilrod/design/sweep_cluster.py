"""Sweeps on a Dask cluster: the scheduler's address checked and connected to, and the points
run there.  dask is imported only here (the ``cluster`` extra)."""

from __future__ import annotations

import socket
from collections.abc import Callable

from ..scene.parse import SceneError

__all__ = ["connect", "run_on_cluster", "CONNECT_TIMEOUT"]


def _one_line(text) -> str:
    return " ".join(str(text).split())


#: Seconds to wait for the scheduler's port to answer, before dask is asked to connect.
CONNECT_TIMEOUT = 10.0


def _check_address(address: str) -> None:
    """A scheduler address dask can read, whose host is known and whose port answers."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port
    from distributed.comm.registry import backends

    example = "e.g. tcp://10.0.0.5:8786"
    if not address.strip():
        raise SceneError(f"scheduler: expected the address of a Dask scheduler, {example}")
    try:
        scheme, location = parse_address(address)
        if scheme not in backends:
            raise ValueError(f"unknown scheme {scheme!r}; known: {', '.join(sorted(backends))}")
        if scheme in ("tcp", "tls", "ws", "wss"):
            host, port = parse_host_port(location)
    except ValueError as exc:
        raise SceneError(f"scheduler {address}: not an address, {example} ({exc})") from None
    if scheme not in ("tcp", "tls", "ws", "wss"):
        return
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT).close()
    except socket.gaierror:
        raise SceneError(f"scheduler {address}: unknown host {host!r}") from None
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise SceneError(
            f"scheduler {address}: cannot connect ({why}); is a Dask scheduler running there "
            "(dask scheduler) and its port open?"
        ) from None


def _identify(address: str):
    """What answers at ``address`` to dask's "identity" request (a dict for a scheduler)."""
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from distributed.comm import connect

    async def ask():
        comm = await connect(address, timeout=CONNECT_TIMEOUT)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await asyncio.wait_for(comm.read(), CONNECT_TIMEOUT)
        finally:
            await comm.close()

    with ThreadPoolExecutor(1) as thread:  # its own event loop, also under a running one
        return thread.submit(asyncio.run, ask()).result()


def connect(address: str):
    """A dask Client of the scheduler at ``address``; SceneError if it cannot be reached."""
    try:
        from distributed import Client
    except ImportError:
        raise SceneError(
            f"scheduler {address}: running on a Dask cluster needs dask.distributed "
            "(pip install 'coilrod[cluster]')"
        ) from None
    _check_address(address)
    if address.startswith("tcp://") or "://" not in address:
        try:
            identity = _identify(address)
            what = f"a dask {identity.get('type')}" if isinstance(identity, dict) else "no reply"
        except Exception as exc:  # whatever answered, it does not speak dask
            identity, what = None, f"no dask handshake: {type(exc).__name__}"
        if not isinstance(identity, dict) or identity.get("type") != "Scheduler":
            raise SceneError(
                f"scheduler {address}: not a Dask scheduler ({what}); give the address "
                "'dask scheduler' prints"
            )
    try:
        return Client(address, set_as_default=False)
    except Exception as exc:
        raise SceneError(
            f"scheduler {address}: cannot connect ({_one_line(exc) or type(exc).__name__})"
        ) from None


def run_on_cluster(client, fn: Callable, tasks, done: Callable) -> None:
    """Run ``fn(*args)`` on the cluster for every ``(point, args)`` of ``tasks``; call
    ``done(point, result)`` as they finish (``result`` is the exception of a task that could not
    run: a worker died, or could not import coilrod).  Ctrl-C cancels the tasks left."""
    from distributed import as_completed

    futures = {client.submit(fn, *args, pure=False): point for point, args in tasks}
    try:
        for future in as_completed(list(futures), loop=client.loop):
            try:
                result = future.result()
            except Exception as exc:
                result = exc
            done(futures[future], result)
    except BaseException:
        client.cancel(list(futures))
        raise
