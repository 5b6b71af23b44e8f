"""Chunked sweeps, serial or on dask.distributed, resumable from finished chunks on disk.

A sweep is a JSON-able ``spec`` and a top-level function ``compute(spec, k) -> dict of arrays``
for chunks ``k = 0 … n−1``. :func:`run` evaluates every chunk

* serially in this process (``workers=0``),
* on an embedded ``LocalCluster`` of ``workers`` processes on the loopback interface
  (``workers=1``: one worker thread inside this process), or
* on an existing cluster (``scheduler="tcp://HOST:PORT"``; start one with ``dask scheduler`` and
  ``dask worker tcp://HOST:PORT --nthreads 1`` on each machine, with this package installed there).

With ``folder``, every finished chunk is written there atomically (a temporary file renamed into
place) under a name that carries the spec's hash, so a rerun with the same spec loads it instead of
computing it again, and Ctrl-C keeps what finished. Chunks are deterministic (seeded by ``k``), so
the results do not depend on the number of workers or the order they finish in.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import numpy as np

from fault_tolerance.errors import InvalidInput

Chunk = dict[str, np.ndarray]


def spec_hash(spec: dict) -> str:
    """Short SHA-256 of the spec's canonical JSON (the name of its chunk folder)."""
    text = json.dumps(spec, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def chunk_folder(folder: str | Path, spec: dict) -> Path:
    """Folder of the finished chunks of ``spec`` inside an output folder."""
    return Path(folder) / f"chunks-{spec_hash(spec)}"


def _save(path: Path, chunk: Chunk) -> None:
    """Write one chunk atomically: a temporary file in the same folder, then a rename."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **cast(dict[str, Any], chunk))  # str keys: the stub fears allow_pickle
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _load(path: Path) -> Chunk | None:
    try:
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError):
        return None  # a damaged file (not ours: ours are renamed into place whole) is recomputed


def _bar(total: int, enabled: bool, desc: str, initial: int):
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, disable=not enabled, desc=desc, unit="chunk")


#: Environment of the embedded cluster's worker processes (set before they start): one BLAS /
#: OpenMP / numba thread each, as Dask's default, but without Dask's ``MALLOC_TRIM_THRESHOLD_``:
#: any explicit malloc threshold turns off glibc's adaptive mmap threshold, so every temporary
#: array over 128 KiB is mapped and zero-filled afresh by the kernel (26x the page faults of the
#: serial run and ~25 % more CPU per chunk of a planar map; README, "Workspace on two workers").
WORKER_ENVIRON = {
    f"distributed.nanny.pre-spawn-environ.{k}": v
    for k, v in {
        "MALLOC_TRIM_THRESHOLD_": None,
        "OMP_NUM_THREADS": 1,
        "OPENBLAS_NUM_THREADS": 1,
        "MKL_NUM_THREADS": 1,
        "NUMBA_NUM_THREADS": 1,
    }.items()
}
#: Quieter bookkeeping of the embedded cluster (no dashboard is watched): Dask's defaults (a
#: statistical profile of the running task every 10 ms, event-loop health checks every 20 ms,
#: system and memory monitors at 2 and 10 Hz, work stealing) cost ~10 % of a core while the
#: workers compute, taken from the workers on a 2-core machine; these cost ~1 %.
QUIET = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.scheduler.work-stealing": False,
}


def client_for(workers: int, scheduler: str | None):
    """A dask.distributed Client: the given scheduler, or an embedded loopback LocalCluster."""
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="10s")
        except OSError as exc:
            raise InvalidInput(
                f"cannot reach the Dask scheduler at {scheduler} ({exc}); start one with "
                "`dask scheduler` and workers with `dask worker tcp://HOST:PORT`"
            ) from None
    local = {"host": "127.0.0.1"} if workers > 1 else {}  # loopback only; 1 worker: in-process
    with dask.config.set({**WORKER_ENVIRON, **QUIET}):
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=workers > 1,
            dashboard_address="127.0.0.1:0",  # its HTTP server starts anyway: loopback, any port
            silence_logs=40,
            **local,
        )
    return Client(cluster)


def run(
    compute: Callable[[dict, int], Chunk],
    spec: dict,
    n_chunks: int,
    *,
    folder: str | Path | None = None,
    workers: int = 0,
    scheduler: str | None = None,
    progress: bool = False,
    desc: str = "sweep",
) -> list[Chunk]:
    """Results of ``compute(spec, k)`` for ``k < n_chunks``, in order (module doc).

    Raises:
        InvalidInput: ``workers`` is negative, or the scheduler cannot be reached.
    """
    if int(workers) != workers or workers < 0:
        raise InvalidInput(f"workers must be an integer >= 0 (0: serial), got {workers}")
    results: dict[int, Chunk] = {}
    cdir = None
    if folder is not None:
        cdir = chunk_folder(folder, spec)
        cdir.mkdir(parents=True, exist_ok=True)
        (cdir / "spec.json").write_text(json.dumps(spec, sort_keys=True, indent=1, default=str))
        for k in range(n_chunks):
            p = cdir / f"chunk-{k:05d}.npz"
            if p.exists() and (c := _load(p)) is not None:
                results[k] = c
    todo = [k for k in range(n_chunks) if k not in results]
    bar = _bar(n_chunks, progress, desc, n_chunks - len(todo))

    def finished(k: int, chunk: Chunk) -> None:
        results[k] = chunk
        if cdir is not None:
            _save(cdir / f"chunk-{k:05d}.npz", chunk)
        bar.update(1)

    try:
        if todo and workers == 0 and not scheduler:
            for k in todo:
                finished(k, compute(spec, k))
        elif todo:
            _run_dask(compute, spec, todo, workers, scheduler, finished)
    finally:
        bar.close()
    return [results[k] for k in range(n_chunks)]


def _run_dask(compute, spec, todo, workers, scheduler, finished) -> None:
    from dask.distributed import as_completed

    client = client_for(max(int(workers), 1), scheduler)
    futures = []
    try:
        futures = client.map(compute, [spec] * len(todo), todo, pure=False)
        index = {f.key: k for f, k in zip(futures, todo, strict=True)}
        for fut in as_completed(futures):
            finished(index[fut.key], fut.result())
    finally:
        for f in futures:
            f.cancel()
        cluster = None if scheduler else client.cluster
        client.close()
        if cluster is not None:
            cluster.close()
