"""Where tasks run: a local process pool (the default) or a Dask cluster.

Both give futures that report to one queue when done, so the experiment's main loop
(the only writer of the ledger) takes results in completion order whatever runs them.
Tasks are pure functions of their arguments, so the results do not depend on this choice
or on the number of workers.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
from concurrent.futures import ProcessPoolExecutor

from harness.errors import InputError


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
    without the parent's threads; each keeps its imports and caches between tasks)."""

    def __init__(self, workers: int):
        super().__init__()
        self.workers = workers
        self.description = f"{workers} local worker process{'es' if workers > 1 else ''}"
        context = multiprocessing.get_context("forkserver")
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=context)

    def _submit(self, fn, *args):
        return self.pool.submit(fn, *args)

    def close(self, cancel: bool = False) -> None:
        self.pool.shutdown(wait=not cancel, cancel_futures=cancel)


class DaskExecutor(Executor):
    """A Dask cluster at ``address``, or a LocalCluster of ``workers`` single-threaded
    worker processes when the address is ``local``."""

    def __init__(self, address: str, workers: int):
        super().__init__()
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise InputError("--scheduler", None, "Dask is not installed (pip install 'gpis-harness[cluster]')") \
                from None
        self.cluster = None
        try:
            if address == "local":
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None)
                self.client = Client(self.cluster)
                self.description = f"a Dask LocalCluster of {workers} worker process{'es' if workers > 1 else ''}"
            else:
                self.client = Client(address, timeout="10s")
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
