"""Where the chunks run: a thread pool, a local dask cluster or an existing one.

A scheduler spec is one of

``threads`` or ``threads:N``
    A thread pool in this process (the numba kernels release the GIL); the
    default. Needs no dask.
``local:N``
    A ``dask.distributed.LocalCluster`` of ``N`` worker processes with one
    thread each, started for the job and shut down after it.
``tcp://HOST:PORT``
    The scheduler of an existing ``dask.distributed`` cluster. Its workers
    must have porecad installed; output files are written by this process,
    a zarr store by the workers (give a path they all see). Dask exchanges
    pickles with it, so a scheduler can run code here: name only one you
    trust.

A recipe file is not trusted (``docs/security.md``): it may ask only for
``threads`` or ``local:N`` with N at most this machine's cores
(:func:`recipe_scheduler`); a remote scheduler, or more workers, is chosen
on the command line or in Python.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from ..errors import InputError, ResourceError

DASK_HINT = 'pip install "porecad[dask]"'


@dataclass(frozen=True)
class SchedulerSpec:
    """A parsed scheduler spec: ``kind`` is ``threads``, ``local`` or ``tcp``."""

    kind: str
    workers: int | None = None
    address: str | None = None

    def __str__(self):
        if self.kind == "tcp":
            return self.address
        if self.kind == "local":
            return f"local:{self.workers}"
        return "threads" if self.workers is None else f"threads:{self.workers}"


def parse_scheduler(text) -> SchedulerSpec:
    """Parse a scheduler spec (see the module docstring); raise :class:`InputError` if malformed."""
    if text is None:
        return SchedulerSpec("threads")
    s = str(text).strip()
    if s.startswith("tcp://"):
        host, _, port = s[len("tcp://"):].rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise InputError(f"scheduler {s!r}: give tcp://HOST:PORT")
        return SchedulerSpec("tcp", address=s)
    kind, _, n = s.partition(":")
    if kind not in ("threads", "local"):
        raise InputError(f"unknown scheduler {s!r}; use threads, local:N or tcp://HOST:PORT")
    if not n:
        if kind == "local":
            raise InputError("scheduler local:N needs a number of workers, e.g. local:2")
        return SchedulerSpec("threads")
    if not n.isdigit() or not 1 <= int(n) <= 1024:
        raise InputError(f"scheduler {s!r}: the number of workers must be an integer 1-1024")
    return SchedulerSpec(kind, workers=int(n))


def recipe_workers(n: int) -> int:
    """``n`` workers asked for by a recipe file: at most this machine's cores, else an :class:`InputError`."""
    cores = os.cpu_count() or 1
    if n > cores:
        raise InputError(f"a recipe may ask for at most {cores} workers (this machine's cores), got {n}; "
                         "more are chosen on the command line or in Python")
    return n


def recipe_scheduler(text) -> SchedulerSpec:
    """A scheduler asked for by a recipe file: ``threads`` or ``local:N`` (:func:`recipe_workers`), never remote."""
    spec = parse_scheduler(text)
    if spec.kind == "tcp":
        raise InputError(f"a recipe may ask only for threads or local:N, not {spec}: a remote scheduler is chosen "
                         "on the command line or in Python (dask exchanges pickles with it: only one you trust)")
    if spec.workers is not None:
        recipe_workers(spec.workers)
    return spec


@contextlib.contextmanager
def _sigint_blocked():
    """Ignore SIGINT while the local cluster starts its worker processes, which inherit the disposition.

    Ctrl-C goes to the whole foreground process group; with SIGINT ignored
    in the workers (Python keeps an inherited ``SIG_IGN``) only porecad itself
    sees it, stops the job, closes the cluster and prints one line, instead
    of every worker printing a traceback. (A blocked signal mask is not
    enough: the workers are spawned from threads that do not share it.)
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _distributed():
    try:
        import distributed
    except ImportError:
        raise InputError(f"dask schedulers need dask.distributed: {DASK_HINT}") from None
    return distributed


class ThreadScheduler:
    """Chunks on a thread pool of this process."""

    def __init__(self, workers: int):
        self.workers = max(1, int(workers))
        self.name = f"threads:{self.workers}"
        self._pool = None

    def __enter__(self):
        self._pool = ThreadPoolExecutor(max_workers=self.workers)
        return self

    def __exit__(self, *exc):
        self._pool.shutdown(wait=True, cancel_futures=True)
        return False

    def submit(self, fn, *args):
        return self._pool.submit(fn, *args)


class DaskScheduler:
    """Chunks on a ``dask.distributed`` cluster (started locally, or an existing one)."""

    def __init__(self, spec: SchedulerSpec, cluster_kwargs: dict | None = None):
        self.spec = spec
        self.name = str(spec)
        self.cluster_kwargs = dict(cluster_kwargs or {})
        self.client = None
        self._cluster = None

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def __enter__(self):
        distributed = _distributed()
        try:
            if self.spec.kind == "local":
                kw = {"n_workers": self.spec.workers, "threads_per_worker": 1, "processes": True,
                      "dashboard_address": ":0", "silence_logs": logging.ERROR}
                kw.update(self.cluster_kwargs)
                with _sigint_blocked():  # workers inherit the mask: Ctrl-C reaches only this process
                    self._cluster = distributed.LocalCluster(**kw)
                    self.client = distributed.Client(self._cluster)
            else:
                self.client = distributed.Client(self.spec.address, timeout="5s")
        except (OSError, TimeoutError) as exc:
            self.__exit__(None, None, None)
            what = "start a local dask cluster" if self.spec.kind == "local" else \
                f"connect to the dask scheduler at {self.spec.address}"
            raise ResourceError(f"cannot {what}: {' '.join(str(exc).split()) or type(exc).__name__}") from None
        return self

    def __exit__(self, *exc):
        if self.client is not None:
            self.client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None
        return False

    def prepare(self, job) -> None:
        """Refuse, in one line, a job whose field cannot be shipped to the workers."""
        import cloudpickle
        try:
            cloudpickle.dumps(job)
        except Exception as exc:  # noqa: BLE001 - whatever pickling raises
            text = " ".join(str(exc).split())
            raise InputError(f"this job cannot run on dask workers: its field cannot be pickled "
                             f"({type(exc).__name__}: {text}); use the `scheduler` threads") from None

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)


class ClientScheduler(DaskScheduler):
    """Chunks on the cluster of an already open ``distributed.Client`` (kept open)."""

    def __init__(self, client):
        self.client = client
        self.name = f"client:{client.scheduler.address}"
        self._cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def open_scheduler(spec, threads: int | None = None):
    """A scheduler context manager for ``spec`` (a spec string, a :class:`SchedulerSpec` or a Client).

    ``threads`` sizes the default thread pool. Dask schedulers fail with a
    one-line :class:`InputError` naming ``pip install "porecad[dask]"`` when
    dask.distributed is missing.
    """
    if spec is not None and hasattr(spec, "submit") and hasattr(spec, "scheduler_info"):
        return ClientScheduler(spec)
    if not isinstance(spec, SchedulerSpec):
        spec = parse_scheduler(spec)
    if spec.kind == "threads":
        from ..mesh.polygonise import default_threads
        n = spec.workers or threads or default_threads()
        return ThreadScheduler(n)
    _distributed()
    return DaskScheduler(spec)
