"""The machine a benchmark ran on: CPU, library versions, BLAS build and threads, load."""

from __future__ import annotations

import ctypes
import os
import platform
from importlib import metadata
from pathlib import Path

import numpy as np


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _blas_threads() -> list[dict]:
    """Threads of every BLAS library loaded in this process (threadpoolctl, else OpenBLAS' API)."""
    try:
        from threadpoolctl import threadpool_info

        return [
            {
                "library": i.get("internal_api"),
                "path": i.get("filepath"),
                "version": i.get("version"),
                "threads": i.get("num_threads"),
            }
            for i in threadpool_info()
        ]
    except ImportError:
        pass
    out = []
    try:
        paths = {
            line.split()[-1]
            for line in Path("/proc/self/maps").read_text().splitlines()
            if "openblas" in line.lower() and line.split()[-1].startswith("/")
        }
    except OSError:
        paths = set()
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for symbol in (
            "openblas_get_num_threads",
            "openblas_get_num_threads64_",
            "scipy_openblas_get_num_threads64_",
            "scipy_openblas_get_num_threads",
        ):
            fn = getattr(lib, symbol, None)
            if fn is not None:
                fn.restype = ctypes.c_int
                out.append({"library": "openblas", "path": path, "threads": int(fn())})
                break
    return out


def _blas_build(module) -> dict | None:
    try:
        blas = module.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return {"name": blas.get("name"), "version": blas.get("version")}
    except Exception:  # noqa: BLE001 - older versions have no mode="dicts"
        return None


def machine_info() -> dict:
    """CPU, library versions, BLAS build and threads, BLAS-related environment, load."""
    import pinocchio as pin

    from fault_tolerance.version import __version__

    info: dict = {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "fault_tolerance": __version__,
        "numpy": np.__version__,
        "pinocchio": pin.__version__,
        "scipy": _version("scipy"),
        "numba": _version("numba"),
        "quadprog": _version("quadprog"),
        "numpy_blas": _blas_build(np),
        "env": {
            k: v
            for k, v in sorted(os.environ.items())
            if k.startswith(("OPENBLAS_", "OMP_", "MKL_", "BLIS_", "GOTO", "VECLIB_", "NUMBA_"))
        },
        "loadavg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    try:
        import scipy
        import scipy.linalg  # noqa: F401 - load scipy's BLAS so its threads are listed

        info["scipy_blas"] = _blas_build(scipy)
    except ImportError:
        info["scipy"] = None

    info["blas_threads"] = _blas_threads()
    return info
