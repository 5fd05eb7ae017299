"""Where tasks run: a local process pool (the default) or a Dask cluster.

Both give futures that report to one queue when done, so the experiment's main loop
(the only writer of the ledger) takes results in completion order whatever runs them.
Tasks are pure functions of their arguments, so the results do not depend on this choice
or on the number of workers. ``check_scheduler`` refuses a Dask address that cannot work
before any work starts.
"""

from __future__ import annotations

import asyncio
import multiprocessing
import os
import queue
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

from harness.errors import InputError, describe

#: Dask's schemes for a scheduler reached over the network; tls and wss encrypt.
SCHEMES = ("tcp", "tls", "ws", "wss")
#: How long a connection to a scheduler may take (the Client's own timeout too).
CONNECT_TIMEOUT = "10s"


class Executor:
    """submit(fn, *args, tag=...) and next_done() -> (tag, future); close(cancel)."""

    description = ""

    def __init__(self):
        self._done: queue.Queue = queue.Queue()
        self.pending = 0

    def submit(self, fn, *args, tag=None):
        future = self._submit(fn, *args)
        self.pending += 1
        future.add_done_callback(lambda f: self._done.put((tag, f)))
        return future

    def next_done(self):
        """The next finished task's tag and future (blocks; wakes up for Ctrl-C)."""
        while True:
            try:
                tag, future = self._done.get(timeout=0.5)
            except queue.Empty:
                continue
            self.pending -= 1
            return tag, future

    def _submit(self, fn, *args):  # pragma: no cover - abstract
        raise NotImplementedError

    def close(self, cancel: bool = False) -> None:  # pragma: no cover - abstract
        raise NotImplementedError


class LocalExecutor(Executor):
    """A pool of worker processes on this machine (started by forkserver: clean workers
    without the parent's threads; each keeps its imports and caches between tasks).
    Each worker ends as soon as this process ends, killed or not (harness.isolation's
    die_with), so a kill -9 of the run leaves no worker behind."""

    def __init__(self, workers: int):
        from harness.isolation import die_with

        super().__init__()
        self.workers = workers
        self.description = f"{workers} local worker process{'es' if workers > 1 else ''}"
        context = multiprocessing.get_context("forkserver")
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=die_with,
                                        initargs=(os.getpid(),))

    def _submit(self, fn, *args):
        return self.pool.submit(fn, *args)

    def close(self, cancel: bool = False) -> None:
        self.pool.shutdown(wait=not cancel, cancel_futures=cancel)


class DaskExecutor(Executor):
    """A Dask cluster at ``address``, or a LocalCluster of ``workers`` single-threaded
    worker processes when the address is ``local``. TLS settings come from Dask's config
    (see check_scheduler)."""

    def __init__(self, address: str, workers: int):
        super().__init__()
        Client, LocalCluster = _distributed()
        self.cluster = None
        if address != "local":
            _connection_args(address)
        try:
            if address == "local":
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None)
                self.client = Client(self.cluster)
                self.description = f"a Dask LocalCluster of {workers} worker process{'es' if workers > 1 else ''}"
            else:
                self.client = Client(address, timeout=CONNECT_TIMEOUT)
                self.description = f"the Dask scheduler at {address}"
        except (OSError, TimeoutError) as exc:
            raise InputError("--scheduler", None, f"cannot reach {address}: {exc}") from None

    def _submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)

    def close(self, cancel: bool = False) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(workers: int | None, scheduler: str | None) -> Executor:
    workers = workers or os.cpu_count() or 1
    return DaskExecutor(scheduler, workers) if scheduler else LocalExecutor(workers)


def check_scheduler(address: str | None) -> str | None:
    """Refuse (InputError naming --scheduler) a --scheduler that cannot work, before any
    work starts; return a warning to show, or None. None (the local pool) passes;
    ``local`` (a Dask LocalCluster) needs Dask installed; any other address must read as
    SCHEME://HOST:PORT (SCHEME one of SCHEMES; a bare HOST:PORT takes Dask's default
    scheme, tcp) with a host a client can reach (not a wildcard such as 0.0.0.0, which a
    scheduler listens on), Dask's TLS settings must load (and exist, for tls:// and
    wss://), and a Dask scheduler must answer there within CONNECT_TIMEOUT (TLS and Dask's
    handshake included). An unencrypted scheme (tcp, ws) to a host that is not this
    machine's loopback gets the warning: whoever reaches that port can run code on the
    workers.

    TLS settings are Dask's own config, read by the Client as well:
    ``distributed.comm.tls.ca-file``, ``.client.cert`` and ``.client.key`` (in a YAML file
    under ~/.config/dask/ or $DASK_CONFIG, or the environment variables
    DASK_DISTRIBUTED__COMM__TLS__CA_FILE, ..._TLS__CLIENT__CERT, ..._TLS__CLIENT__KEY).
    With ``distributed.client.security-loader`` set, the loader supplies them when the
    Client connects, so only the address is checked here.
    """
    if address is None:
        return None
    _distributed()
    if address == "local":
        return None
    scheme, host = _scheme_and_host(address)
    connection_args = _connection_args(address)
    if connection_args is not None:
        try:
            # In a thread of its own: the probe needs an event loop, and the caller may have one.
            with ThreadPoolExecutor(1) as pool:
                pool.submit(asyncio.run, _probe(address, connection_args)).result()
        except Exception as exc:  # noqa: BLE001 - whatever stops the connection, the address is unusable
            raise InputError("--scheduler", None, f"cannot connect to a Dask scheduler at {address}: "
                                                  f"{describe(exc)}") from None
    if scheme in ("tcp", "ws") and not _loopback(host):
        return (f"--scheduler {address} is not encrypted: anyone who can reach {host} on that port can run code "
                f"on the workers; use tls:// with Dask's TLS settings (docs/experiments.md, "
                f"\"Security of a cluster\")")
    return None


#: Addresses a server listens on to accept every interface; no client can connect to them.
WILDCARDS = ("0.0.0.0", "::", "*")


def _scheme_and_host(address: str) -> tuple[str, str]:
    """The scheme and host of SCHEME://HOST:PORT; InputError when it does not parse or
    names a wildcard address."""
    from distributed.comm.addressing import parse_address, parse_host_port

    expected = f"expected 'local' or SCHEME://HOST:PORT with SCHEME one of {', '.join(SCHEMES)}, got '{address}'"
    try:
        scheme, location = parse_address(address)
        host, port = parse_host_port(location)
    except (TypeError, ValueError):
        raise InputError("--scheduler", None, expected) from None
    if scheme not in SCHEMES or not host:
        raise InputError("--scheduler", None, expected)
    if host.strip("[]") in WILDCARDS:
        raise InputError("--scheduler", None, f"'{address}' is a wildcard address, which a scheduler listens on "
                                              "but no client can connect to: give the scheduler's host name or IP")
    if not 1 <= port <= 65535:
        raise InputError("--scheduler", None, f"'{address}': port {port} is out of range [1, 65535]")
    return scheme, host


def _loopback(host: str) -> bool:
    """Whether ``host`` is this machine's loopback (127.0.0.0/8, ::1, or a name that
    resolves only to it)."""
    import ipaddress
    import socket

    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        pass
    try:
        found = {info[4][0] for info in socket.getaddrinfo(host, None)}
    except OSError:
        return False
    return bool(found) and all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in found)


def _distributed():
    """Dask's Client and LocalCluster; InputError when Dask is not installed."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("--scheduler", None, "Dask is not installed (pip install 'gpis-harness[cluster]')") \
            from None
    return Client, LocalCluster


def _connection_args(address: str) -> dict | None:
    """The Client's connection arguments for ``address`` (its TLS context from Dask's
    config), or None when a security loader will supply them; InputError for an address
    that does not parse, or TLS settings that are missing or do not load."""
    import dask
    from distributed.security import Security

    scheme, _ = _scheme_and_host(address)
    if dask.config.get("distributed.client.security-loader", None):
        return None
    try:
        connection_args = Security().get_connection_args("client")
    except Exception as exc:  # noqa: BLE001 - a missing or unreadable certificate, a bad TLS version
        raise InputError("--scheduler", None, f"Dask's TLS settings (distributed.comm.tls) do not load: "
                                              f"{describe(exc)}") from None
    if scheme in ("tls", "wss") and connection_args["ssl_context"] is None:
        raise InputError("--scheduler", None, f"'{address}' needs Dask's TLS settings: "
                         "distributed.comm.tls.ca-file and distributed.comm.tls.client.cert (and .client.key "
                         "unless the key is in the cert file), in Dask's config or as "
                         "DASK_DISTRIBUTED__COMM__TLS__CA_FILE, DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT, "
                         "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY")
    return connection_args


async def _probe(address: str, connection_args: dict) -> None:
    """Connect to the scheduler (TLS and Dask's handshake included) and hang up."""
    from distributed.comm import connect

    comm = await connect(address, timeout=CONNECT_TIMEOUT, **connection_args)
    await comm.close()
