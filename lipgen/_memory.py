"""Keep freed memory for reuse while frames are made: no page faults for each frame's large arrays.

glibc's ``malloc`` serves a block of 128 KiB or more (its dynamic threshold grows to at most
32 MiB) by a fresh ``mmap`` and gives it back at ``free``; and it trims the top of the heap
when more than 128 KiB lie free there. A frame of ``lipgen generate`` makes and frees several
arrays of 1-8 MB (the read-back, the resampled and composed images, the sensor noise's draws,
the PNG's buffers), so every frame faults their pages in again and the kernel zeroes them. The
sensor noise of one 640x480 frame (:func:`lipgen.rig.noise.add_rounded_gaussian`) took 9-11 ms of
CPU so against 4.2 ms with the freed memory kept (the same values).

:func:`reuse_freed_memory` raises both thresholds (``mallopt``) while its block runs and, at the
end, trims what is left free and sets the limits glibc's own adaptive rule reaches after large
frees (:data:`AFTER_MMAP_THRESHOLD`, :data:`AFTER_TRIM_THRESHOLD`): a ``mallopt`` turns that rule
off for the rest of the process, and its fixed 128 KiB defaults made every later array of 128 KiB
or more a fresh ``mmap`` (``calibrate_rig`` after ``generate`` in one process: 2.3 million page
faults and 3x the CPU, 7.5 s against 2.3 s on 10 boards). What is computed does not change, only
where the memory comes from. It does nothing off glibc, or with
``LIPGEN_MEMORY_POLICY=off`` (to measure what it buys); a worker process that ends when the
work does keeps the setting for its life (:func:`keep_freed_memory`).
"""

from __future__ import annotations

import ctypes
import functools
import logging
import os
from contextlib import contextmanager

__all__ = ["reuse_freed_memory", "keep_freed_memory", "MEMORY_POLICY_ENV", "MMAP_THRESHOLD", "TRIM_THRESHOLD",
           "AFTER_MMAP_THRESHOLD", "AFTER_TRIM_THRESHOLD"]

log = logging.getLogger(__name__)

MEMORY_POLICY_ENV = "LIPGEN_MEMORY_POLICY"
"""Set to ``off`` to leave glibc's malloc settings alone."""

MMAP_THRESHOLD = 32 << 20
"""Blocks below this many bytes come from the heap (glibc's largest dynamic threshold, 32 MiB)."""
TRIM_THRESHOLD = 256 << 20
"""Free memory kept at the top of the heap before it is given back to the system, bytes."""

AFTER_MMAP_THRESHOLD = 32 << 20
"""After :func:`reuse_freed_memory`: the largest mmap threshold of glibc's adaptive rule (64-bit), bytes."""
AFTER_TRIM_THRESHOLD = 2 * AFTER_MMAP_THRESHOLD
"""After :func:`reuse_freed_memory`: twice the mmap threshold, as glibc's adaptive rule sets it, bytes."""

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
_DEFAULT = 128 * 1024  # glibc's default for both


@functools.lru_cache(maxsize=1)
def _libc():
    """glibc, or None (another C library, another platform)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.gnu_get_libc_version.restype = ctypes.c_char_p
        libc.gnu_get_libc_version()
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
    except (OSError, AttributeError):
        return None
    return libc


def _set(mmap_threshold: int, trim_threshold: int) -> bool:
    libc = _libc()
    if libc is None or os.environ.get(MEMORY_POLICY_ENV) == "off":
        return False
    if not libc.mallopt(_M_MMAP_THRESHOLD, mmap_threshold):
        log.info("mallopt refused the mmap threshold %d", mmap_threshold)
        return False
    if not libc.mallopt(_M_TRIM_THRESHOLD, trim_threshold):
        libc.mallopt(_M_MMAP_THRESHOLD, _DEFAULT)     # all or nothing: put the first back
        log.info("mallopt refused the trim threshold %d", trim_threshold)
        return False
    return True


_depth = 0       # open reuse_freed_memory blocks in this process (only the outermost sets and restores)
_kept = False    # keep_freed_memory() took: the whole process keeps freed memory


def keep_freed_memory() -> bool:
    """For the rest of the process: large blocks from the heap, freed memory kept (a worker's first
    call). Returns whether the setting took (False off glibc or with the policy off)."""
    global _kept
    _kept = _set(MMAP_THRESHOLD, TRIM_THRESHOLD)
    return _kept


@contextmanager
def reuse_freed_memory():
    """Inside the ``with`` block, freed memory is kept for reuse (see the module docstring); at its
    end the free memory is trimmed and the limits of glibc's adaptive rule are set
    (:data:`AFTER_MMAP_THRESHOLD`, :data:`AFTER_TRIM_THRESHOLD`). A block inside another (or in a
    process that called :func:`keep_freed_memory`) leaves the outer setting as it is."""
    global _depth
    if _depth or _kept or not _set(MMAP_THRESHOLD, TRIM_THRESHOLD):
        yield
        return
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        _set(AFTER_MMAP_THRESHOLD, AFTER_TRIM_THRESHOLD)
        _libc().malloc_trim(0)
