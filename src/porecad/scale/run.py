"""The chunk loop on any scheduler: retries, progress, welding in order, statistics.

:func:`run_chunks` submits the slabs of a :class:`~porecad.mesh.polygonise.SlabJob`
to a scheduler (:mod:`porecad.scale.schedulers`) with a bounded window of
chunks in flight, welds the results in slab order exactly as the
single-process :func:`~porecad.mesh.polygonise.polygonise` does, and hands
each welded slab to a consumer (an in-memory collector, or a streamed file
writer and check). A chunk whose task fails is resubmitted up to ``retries``
times; a worker that dies is replaced by the cluster and its chunks are
rescheduled there. A chunk that still fails ends the run with a one-line
:class:`ChunkError`; the callers write outputs atomically, so nothing partial
remains.
"""

from __future__ import annotations

import time

from ..errors import PorecadError
from ..mesh.polygonise import mesh_chunk, total_weight, welded_slabs


class ChunkError(PorecadError):
    """A chunk failed on every attempt (the run was abandoned; nothing written)."""

    exit_code = 5


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class _Retrying:
    """A future that resubmits its chunk when it fails, up to ``retries`` times."""

    def __init__(self, scheduler, job, idx, est, retries, counter):
        self.scheduler, self.job, self.idx, self.est = scheduler, job, idx, est
        self.retries, self.counter = retries, counter
        self.future = scheduler.submit(mesh_chunk, job, idx, est)

    def cancel(self):
        cancel = getattr(self.future, "cancel", None)
        if cancel is not None:
            cancel()

    def result(self):
        attempt = 0
        while True:
            try:
                return self.future.result()
            except PorecadError:
                raise  # a user error (bad input) is not cured by retrying
            except Exception as exc:  # noqa: BLE001 - any failure of a remote task
                if attempt >= self.retries:
                    a, b = self.job.ranges[self.idx]
                    raise ChunkError(f"chunk {self.idx + 1}/{self.job.n_slabs} (planes {a}-{b}) failed "
                                     f"after {attempt + 1} attempt(s): {_one_line(exc)}") from None
                attempt += 1
                self.counter[0] += 1
                self.future = self.scheduler.submit(mesh_chunk, self.job, self.idx, self.est)


def run_chunks(job, scheduler, consume, retries: int = 2, window: int | None = None, progress=None) -> dict:
    """Run every slab of ``job`` on ``scheduler`` and pass the welded slabs to ``consume`` in order.

    Parameters
    ----------
    job : porecad.mesh.polygonise.SlabJob
    scheduler : an entered scheduler of :func:`porecad.scale.open_scheduler`
        Anything with ``submit(fn, *args) -> future`` and ``workers``.
    consume : callable
        ``consume(slab)`` for each :class:`~porecad.mesh.polygonise.WeldedSlab`.
    retries : int
        Extra attempts per failed chunk.
    window : int, optional
        Chunks in flight at most (default ``2 * workers + 1``): memory is
        bounded by the window, not by the mesh.
    progress : callable, optional
        ``progress(done, total)`` after each chunk.

    Returns
    -------
    dict
        ``chunks``, ``planes_per_chunk``, ``retries`` (resubmissions),
        ``workers``, ``scheduler``, ``samples``, ``seconds``,
        ``samples_per_s``, ``inside_fraction``.
    """
    retries = int(retries)
    if retries < 0:
        from ..errors import InputError
        raise InputError(f"retries must be >= 0, got {retries}")
    prepare = getattr(scheduler, "prepare", None)
    if prepare is not None:
        prepare(job)
    workers = scheduler.workers
    window = 2 * workers + 1 if window is None else int(window)
    counter = [0]
    inside = 0.0
    t0 = time.perf_counter()

    def submit(idx, est):
        return _Retrying(scheduler, job, idx, est, retries, counter)

    for slab in welded_slabs(job, submit, window, progress):
        inside += slab.inside_weight
        consume(slab)
    seconds = time.perf_counter() - t0
    samples = len(job.xs) * len(job.ys) * len(job.zs)
    return {"chunks": job.n_slabs, "planes_per_chunk": job.planes, "retries": counter[0],
            "workers": workers, "scheduler": scheduler.name, "samples": samples,
            "seconds": seconds, "samples_per_s": samples / seconds if seconds > 0 else None,
            "inside_fraction": inside / total_weight(job)}
