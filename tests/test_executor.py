"""Where tasks run: a --scheduler that cannot work is refused before any work starts,
with one line naming --scheduler; TLS settings come from Dask's config."""

from __future__ import annotations

import shutil
import socket
import subprocess
import threading
import time

import pytest

from harness import executor
from harness.errors import InputError
from harness.executor import check_scheduler

dask = pytest.importorskip("dask")
pytest.importorskip("distributed")

TLS_KEYS = ("distributed.comm.tls.ca-file", "distributed.comm.tls.client.cert", "distributed.comm.tls.client.key")


@pytest.fixture
def no_tls():
    with dask.config.set({key: None for key in TLS_KEYS}):
        yield


@pytest.fixture
def quick_timeout(monkeypatch):
    monkeypatch.setattr(executor, "CONNECT_TIMEOUT", "0.5s")


def _closed_port() -> int:
    """A port on 127.0.0.1 where nothing listens (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("address", [None, "local"])
def test_the_local_pool_and_a_local_cluster_need_no_address(address):
    check_scheduler(address)


@pytest.mark.parametrize("address, complaint", [
    ("nonsense", "expected 'local' or SCHEME://HOST:PORT with SCHEME one of tcp, tls, ws, wss, got 'nonsense'"),
    ("", "got ''"),
    ("tcp://host:abc", "got 'tcp://host:abc'"),
    ("tcp://:8786", "got 'tcp://:8786'"),
    ("inproc://x", "got 'inproc://x'"),
    ("udp://host:8786", "got 'udp://host:8786'"),
    ("tcp://127.0.0.1:99999", "'tcp://127.0.0.1:99999': port 99999 is out of range [1, 65535]"),
])
def test_an_address_that_does_not_parse_is_refused_in_one_line(address, complaint):
    with pytest.raises(InputError) as err:
        check_scheduler(address)
    assert err.value.source == "--scheduler" and complaint in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("address", ["tcp://0.0.0.0:8786", "tcp://[::]:8786", "tls://0.0.0.0:8786"])
def test_a_wildcard_address_is_refused_at_once(address):
    start = time.monotonic()
    with pytest.raises(InputError, match="is a wildcard address, which a scheduler listens on but no client can "
                                         "connect to"):
        check_scheduler(address)
    assert time.monotonic() - start < 2.0  # no connection tried (it took the 10 s timeout before)


@pytest.mark.parametrize(("host", "loopback"), [("127.0.0.1", True), ("127.3.4.5", True), ("[::1]", True),
                                                ("localhost", True), ("192.0.2.10", False), ("10.1.2.3", False),
                                                ("no-such-host.invalid", False)])
def test_loopback_is_told_apart_from_other_hosts(host, loopback):
    assert executor._loopback(host) is loopback


@pytest.mark.parametrize(("address", "warned"), [("tcp://192.0.2.10:8786", True), ("ws://192.0.2.10:8786", True),
                                                 ("tcp://127.0.0.1:8786", False)])
def test_plain_tcp_beyond_this_machine_gets_one_warning_line(no_tls, monkeypatch, address, warned):
    async def answers(address, connection_args):  # a scheduler is there
        return None

    monkeypatch.setattr(executor, "_probe", answers)
    warning = check_scheduler(address)
    assert (warning is not None) is warned
    if warned:
        assert "\n" not in warning and "not encrypted" in warning and "tls://" in warning and \
            "Security of a cluster" in warning


def test_a_tls_address_without_dask_tls_settings_is_refused(no_tls):
    with pytest.raises(InputError, match="'tls://127.0.0.1:8786' needs Dask's TLS settings: "
                                         "distributed.comm.tls.ca-file and distributed.comm.tls.client.cert"):
        check_scheduler("tls://127.0.0.1:8786")


def test_tls_settings_that_do_not_load_are_refused(tmp_path):
    with dask.config.set({TLS_KEYS[0]: str(tmp_path / "no-ca.pem"), TLS_KEYS[1]: str(tmp_path / "no-cert.pem")}):
        with pytest.raises(InputError, match=r"Dask's TLS settings \(distributed.comm.tls\) do not load: "
                                             "FileNotFoundError"):
            check_scheduler("tls://127.0.0.1:8786")


def test_an_address_where_no_scheduler_answers_is_refused(no_tls, quick_timeout):
    address = f"tcp://127.0.0.1:{_closed_port()}"
    with pytest.raises(InputError, match=f"cannot connect to a Dask scheduler at {address}: "):
        check_scheduler(address)


def test_a_server_that_is_not_a_dask_scheduler_is_refused(no_tls, quick_timeout):
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()

        def hang_up():  # accept and close, as a wrong service would
            for _ in range(20):
                try:
                    conn, _ = server.accept()
                except OSError:
                    return
                conn.close()

        threading.Thread(target=hang_up, daemon=True).start()
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        with pytest.raises(InputError, match=f"cannot connect to a Dask scheduler at {address}"):
            check_scheduler(address)


def test_a_running_scheduler_passes_and_runs_tasks(no_tls):
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                      dashboard_address=None) as cluster:
        assert check_scheduler(cluster.scheduler_address) is None  # loopback: no warning
        pool = executor.DaskExecutor(cluster.scheduler_address, 1)
        try:
            pool.submit(pow, 2, 10, tag="power")
            tag, future = pool.next_done()
            assert (tag, future.result()) == ("power", 1024)
        finally:
            pool.close()


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl to make certificates")
def test_a_tls_scheduler_is_reached_with_the_tls_settings_of_dask_config(tmp_path, monkeypatch):
    """The Client (and the check) read distributed.comm.tls.* from Dask's config, here from
    DASK_ environment variables, as a user would set them."""
    from distributed import LocalCluster, Security

    def openssl(*args):
        subprocess.run(["openssl", *args], cwd=tmp_path, check=True, capture_output=True)

    openssl("req", "-x509", "-nodes", "-newkey", "rsa:2048", "-days", "1", "-keyout", "ca.key", "-out", "ca.pem",
            "-subj", "/CN=test-ca")
    openssl("req", "-nodes", "-newkey", "rsa:2048", "-keyout", "node.key", "-out", "node.csr", "-subj", "/CN=node")
    openssl("x509", "-req", "-in", "node.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out",
            "node.pem", "-days", "1")
    ca, cert, key = (str(tmp_path / f) for f in ("ca.pem", "node.pem", "node.key"))
    security = Security(tls_ca_file=ca, tls_scheduler_cert=cert, tls_scheduler_key=key, tls_worker_cert=cert,
                        tls_worker_key=key, tls_client_cert=cert, tls_client_key=key, require_encryption=True)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tls://", security=security,
                      dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://")
        for name, value in (("CA_FILE", ca), ("CLIENT__CERT", cert), ("CLIENT__KEY", key)):
            monkeypatch.setenv(f"DASK_DISTRIBUTED__COMM__TLS__{name}", value)
        dask.config.refresh()
        try:
            check_scheduler(address)
            pool = executor.DaskExecutor(address, 1)
            pool.submit(pow, 3, 3, tag="cube")
            assert pool.next_done()[1].result() == 27
            pool.close()
        finally:
            monkeypatch.undo()
            dask.config.refresh()
