"""Keep freed heap memory in the process, so a batch step's large temporaries do not page-fault every step.

A batch of 64 worlds makes temporaries of a few hundred kB to a few MB per step (the LIDAR's
beam-primitive pairs, the occupancy grids' marks). glibc's malloc returns freed memory at the top
of its heap to the OS as soon as more than 128 kB is free (``M_TRIM_THRESHOLD``), so the next
step maps the same pages again and page faults cost more than the arithmetic: measured in
docs/simulator.md ("Vector env"), about 1.5x on the native vector env's step. Raising the
threshold keeps up to ``limit`` bytes of freed heap for reuse; the resident size of the process
does not grow beyond its peak.
"""

from __future__ import annotations

import ctypes
import sys

M_TRIM_THRESHOLD = -1
"""glibc's ``mallopt`` parameter number for the trim threshold (malloc.h)."""
DEFAULT_LIMIT = 64 * 1024 * 1024


def keep_freed_memory(limit: int = DEFAULT_LIMIT) -> bool:
    """Raise glibc malloc's trim threshold to ``limit`` bytes for this process; False where there is no glibc (nothing changed)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:  # not glibc (e.g. musl)
        return False
    mallopt = getattr(libc, "mallopt", None)
    if mallopt is None:
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_TRIM_THRESHOLD, int(limit)))
