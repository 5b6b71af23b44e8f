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

A chunk file is untrusted when read back (docs/security.md): it carries the spec's hash, its index
and the SHA-256 of its arrays (members ``_spec``, ``_k``, ``_sha256``); a chunk that is not a
regular file, is larger than ``chunk_bytes``, declares arrays larger than that in its zip
directory, holds objects, fails to load or does not match is recomputed, and one line on stderr
says so. Writers never follow links: a link or special file at ``spec.json`` or the chunk folder
is refused (``OutputError``).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage.atomic import write_atomic
from fault_tolerance.storage.budget import npz_members
from fault_tolerance.storage.folder_io import is_regular, open_regular, refuse_link

Chunk = dict[str, np.ndarray]

#: Default bound of one chunk's arrays (decompressed) [bytes]; callers pass a tighter one.
MAX_CHUNK_BYTES = 256 * 1024 * 1024
#: Members a chunk file carries besides the chunk's arrays (its identity and checksum).
CHUNK_TAGS = ("_spec", "_k", "_sha256")


def spec_hash(spec: dict) -> str:
    """Short SHA-256 of the spec's canonical JSON (the name of its chunk folder)."""
    text = json.dumps(spec, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def chunk_folder(folder: str | Path, spec: dict) -> Path:
    """Folder of the finished chunks of ``spec`` inside an output folder."""
    return Path(folder) / f"chunks-{spec_hash(spec)}"


def chunk_digest(chunk: Chunk) -> str:
    """SHA-256 of a chunk's arrays: each name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(chunk):
        a = np.ascontiguousarray(chunk[name])
        h.update(f"{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _save(path: Path, chunk: Chunk, tag: str, k: int) -> None:
    """Write one chunk atomically (a temporary file, then a rename) with its identity and checksum.

    The rename replaces whatever entry is at ``path`` (a link is replaced, never followed).
    """
    if any(name in CHUNK_TAGS for name in chunk):
        raise InvalidInput(f"a chunk's arrays may not be named {list(CHUNK_TAGS)}")
    tags = {"_spec": np.array(tag), "_k": np.array(k), "_sha256": np.array(chunk_digest(chunk))}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as fh:
            arrays = cast(
                dict[str, Any], {**chunk, **tags}
            )  # str keys: the stub fears allow_pickle
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _load(path: Path, tag: str, k: int, limit: int) -> Chunk | None:
    """The chunk at ``path`` if it is whole and belongs to this spec and index; else None."""
    if not os.path.lexists(path):
        return None
    why = _refusal(path, tag, k, limit)
    if isinstance(why, str):
        print(f"fault-tolerance: chunk {path} {why}; computing it again", file=sys.stderr)
        return None
    return why


def _refusal(path: Path, tag: str, k: int, limit: int) -> Chunk | str:
    """The verified chunk, or why it is refused (module doc)."""
    if not is_regular(path):
        return "is not a regular file (a link, FIFO or device)"
    size = os.lstat(path).st_size
    if size > limit + 4096:
        return f"has {size:,} bytes, more than its spec allows ({limit:,})"
    try:
        npz_members(path, limit + 4096)  # the zip directory's sizes, before decompressing
        with os.fdopen(open_regular(path), "rb") as fh, np.load(fh, allow_pickle=False) as z:
            data = {name: z[name] for name in z.files}
    except (OSError, ValueError, EOFError, InvalidInput) as err:
        return f"cannot be read ({' '.join(str(err).split())[:120]})"
    tags = {name: data.pop(name, None) for name in CHUNK_TAGS}
    if any(v is None or v.shape != () for v in tags.values()):
        return "carries no spec hash, index and checksum (an older or foreign file)"
    if str(tags["_spec"]) != tag or tags["_k"].dtype.kind not in "iu" or int(tags["_k"]) != k:
        return "belongs to another spec or chunk"
    if str(tags["_sha256"]) != chunk_digest(data):
        return "does not match its checksum (altered or damaged)"
    return data


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


#: How long a Dask scheduler is given to answer and to have a worker [s].
CONNECT_TIMEOUT = 10.0
#: How long a lost scheduler is waited for before the sweep gives up [s].
LOST_TIMEOUT = 10.0
#: Accepted scheduler addresses: ``tcp://HOST:PORT`` (or ``tls://``), HOST a name or IPv4/[IPv6].
SCHEDULER_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):(\d{1,5})$")


def check_scheduler(address: str) -> str:
    """``address`` if it is ``tcp://HOST:PORT`` (or ``tls://``) with a port 1-65535; else InvalidInput."""
    m = SCHEDULER_ADDRESS.match(address or "")
    if m is None or not 0 < int(m.group(3)) < 65536:
        raise InvalidInput(
            f"--scheduler {address!r} is not a Dask scheduler address; write tcp://HOST:PORT "
            "(or tls://HOST:PORT), e.g. tcp://10.0.0.5:8786"
        )
    return address


def _connect(Client, scheduler: str):
    """``Client(scheduler)`` within :data:`CONNECT_TIMEOUT`, else ``TimeoutError``.

    A service that is not a scheduler (an HTTP server) makes Dask retry its handshake for ever.
    """
    import threading

    box: list = []

    def connect() -> None:
        try:
            box.append(Client(scheduler, timeout=f"{CONNECT_TIMEOUT:g}s"))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            box.append(exc)

    t = threading.Thread(target=connect, daemon=True, name="dask-connect")
    t.start()
    t.join(CONNECT_TIMEOUT + 5.0)
    if not box:
        raise TimeoutError(f"no Dask handshake within {CONNECT_TIMEOUT:g} s")
    if isinstance(box[0], BaseException):
        raise box[0]
    return box[0]


def client_for(workers: int, scheduler: str | None):
    """A dask.distributed Client: the given scheduler, or an embedded loopback LocalCluster.

    A given scheduler must answer within :data:`CONNECT_TIMEOUT` and have a worker within as
    long again, else :class:`~.errors.InvalidInput` (one line).
    """
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        check_scheduler(scheduler)
        try:
            client = _connect(Client, scheduler)
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, a handshake that fails
            raise InvalidInput(
                f"cannot reach a Dask scheduler at {scheduler} within {CONNECT_TIMEOUT:g} s "
                f"({type(exc).__name__}: {' '.join(str(exc).split())[:100]}); start one with "
                "`dask scheduler` and workers with `dask worker tcp://HOST:PORT`"
            ) from None
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
        except Exception:  # noqa: BLE001 - TimeoutError, or the scheduler went away
            client.close()
            raise InvalidInput(
                f"the Dask scheduler at {scheduler} has no worker after {CONNECT_TIMEOUT:g} s; "
                "start one with `dask worker " + scheduler + " --nthreads 1`"
            ) from None
        return client
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
    chunk_bytes: int = MAX_CHUNK_BYTES,
) -> list[Chunk]:
    """Results of ``compute(spec, k)`` for ``k < n_chunks``, in order (module doc).

    ``chunk_bytes`` bounds one chunk's arrays [bytes]: a stored chunk declaring more is recomputed.

    Raises:
        InvalidInput: ``workers`` is negative, or the scheduler cannot be reached.
        OutputError: a link or special file where the chunks or ``spec.json`` would be written.
    """
    if int(workers) != workers or workers < 0:
        raise InvalidInput(f"workers must be an integer >= 0 (0: serial), got {workers}")
    if scheduler:
        check_scheduler(scheduler)  # before any folder or progress bar
    results: dict[int, Chunk] = {}
    cdir, made, tag = None, False, spec_hash(spec)
    if folder is not None:
        cdir, made = _open_chunk_folder(folder, spec)
        for k in range(n_chunks):
            if (c := _load(cdir / f"chunk-{k:05d}.npz", tag, k, chunk_bytes)) is not None:
                results[k] = c
    todo = [k for k in range(n_chunks) if k not in results]
    bar = _bar(n_chunks, progress, desc, n_chunks - len(todo))
    saved = []

    def finished(k: int, chunk: Chunk) -> None:
        results[k] = chunk
        if cdir is not None:
            _save(cdir / f"chunk-{k:05d}.npz", chunk, tag, k)
            saved.append(k)
        bar.update(1)

    try:
        if todo and workers == 0 and not scheduler:
            for k in todo:
                finished(k, compute(spec, k))
        elif todo:
            _run_dask(compute, spec, todo, workers, scheduler, finished)
    except BaseException:
        if made and not saved and cdir is not None:  # nothing finished: leave no stray folder
            shutil.rmtree(cdir, ignore_errors=True)
        raise
    finally:
        bar.close()
    return [results[k] for k in range(n_chunks)]


def _open_chunk_folder(folder: str | Path, spec: dict) -> tuple[Path, bool]:
    """The chunk folder of ``spec`` (created if absent: ``made``), with its ``spec.json``."""
    refuse_link(folder, folder=True)
    cdir = refuse_link(chunk_folder(folder, spec), folder=True)
    made = not os.path.lexists(cdir)
    cdir.mkdir(parents=True, exist_ok=True)
    try:
        write_atomic(cdir / "spec.json", json.dumps(spec, sort_keys=True, indent=1, default=str))
    except BaseException:
        if made:
            shutil.rmtree(cdir, ignore_errors=True)
        raise
    return cdir, made


def _run_dask(compute, spec, todo, workers, scheduler, finished) -> None:
    with _quiet_dask():  # a lost scheduler is our one line, not Dask's logged tracebacks
        _run_on(compute, spec, todo, workers, scheduler, finished)


@contextlib.contextmanager
def _quiet_dask():
    """Dask's loggers silenced; restored when the block ends normally.

    After a lost scheduler the client's reconnect task may still log while the process ends.
    Dask sets its loggers' levels when it is imported, so it is imported first.
    """
    import distributed.client  # noqa: F401 - creates and configures the loggers

    names = [n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]
    logs = [logging.getLogger(n) for n in ["distributed", *names]]
    levels = [log.level for log in logs]
    for log in logs:
        log.setLevel(logging.CRITICAL + 1)
    yield
    for log, level in zip(logs, levels, strict=True):
        log.setLevel(level)


def _run_on(compute, spec, todo, workers, scheduler, finished) -> None:
    client = client_for(max(int(workers), 1), scheduler)
    futures = []
    try:
        futures = client.map(compute, [spec] * len(todo), todo, pure=False)
        index = {f.key: k for f, k in zip(futures, todo, strict=True)}
        _collect(client, futures, index, finished, scheduler)
    finally:
        for f in futures:
            f.cancel()
        cluster = None if scheduler else client.cluster
        client.close()
        if cluster is not None:
            cluster.close()


def _collect(client, futures, index, finished, scheduler) -> None:
    """Hand each future's chunk to ``finished`` as it completes; a lost scheduler is one line."""
    from concurrent.futures import CancelledError

    import distributed.client as dc
    from dask.distributed import wait

    lost = (CancelledError, OSError, getattr(dc, "FuturesCancelledError", CancelledError))
    pending, lost_since = set(futures), None
    where = scheduler or "the local cluster"
    while pending:
        try:
            done, pending = wait(pending, timeout=1.0, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        except lost as err:
            raise _lost(where, err) from None
        for fut in done:
            if fut.status == "error":
                fut.result()  # the chunk's own error, as it is
            try:
                chunk = fut.result()
            except (*lost, TimeoutError) as err:
                raise _lost(where, err) from None
            finished(index[fut.key], chunk)
        if client.status == "running" and not any(f.status == "cancelled" for f in pending):
            lost_since = None
        elif lost_since is None:
            lost_since = time.monotonic()
        elif time.monotonic() - lost_since > LOST_TIMEOUT:
            raise _lost(where, None)


def _lost(where: str, err) -> InvalidInput:
    why = f" ({type(err).__name__})" if err is not None else ""
    return InvalidInput(
        f"lost the Dask scheduler at {where} during the sweep{why}; the finished chunks are kept "
        "and a rerun of the same command resumes from them"
    )
