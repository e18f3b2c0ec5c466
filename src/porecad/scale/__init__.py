"""Scale-out execution: the slab loop on dask, meshes streamed to disk.

* :mod:`porecad.scale.schedulers` - ``threads`` / ``local:N`` / ``tcp://HOST:PORT``.
* :mod:`porecad.scale.run` - the chunk loop with retries, progress and statistics.
* :mod:`porecad.scale.memwatch` - peak memory of the process tree.

The streamed mesh writers live in :mod:`porecad.io.stream_mesh`, the
streamed solid check in :mod:`porecad.mesh.stream_check` and the zarr store of
sampled fields in :mod:`porecad.io.zarr_field`. See ``docs/scale-out.md``.
"""

from .run import ChunkError, run_chunks
from .schedulers import open_scheduler, parse_scheduler

__all__ = ["ChunkError", "open_scheduler", "parse_scheduler", "run_chunks"]
