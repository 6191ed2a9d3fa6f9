"""Freed memory kept for reuse while frames are made (lipgen._memory): fewer page faults, the same bytes."""

import os
import resource

import numpy as np
import pytest

from lipgen import _memory
from lipgen._memory import MEMORY_POLICY_ENV, keep_freed_memory, reuse_freed_memory

glibc = pytest.mark.skipif(_memory._libc() is None, reason="needs glibc's mallopt")


def _faults_allocating(rounds: int = 4, n: int = 10, size: int = 8 << 20) -> int:
    """Minor page faults of ``rounds`` rounds of making and filling ``n`` arrays of ``size`` bytes
    together, then freeing them (80 MB at a time: more than glibc keeps by default)."""
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(rounds):
        held = [np.ones(size, np.uint8) for _ in range(n)]
        del held
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0


_ROUND = 10 * (8 << 20) // resource.getpagesize()  # pages of one round's arrays


@pytest.fixture(autouse=True)
def _small_pages_and_glibc_defaults():
    """A baseline that does not depend on the machine's state or on what ran before.

    numpy asks for transparent huge pages on large arrays (madvise), and whether it gets them
    depends on free memory at that moment: one fault per 2 MB instead of per 4 KB page (on CI's
    worker 15304 faults in 4 rounds of 20480 pages). So huge pages are not asked for here. And
    glibc raises its mmap threshold by itself each time a large mapped block is freed, so its
    fixed default thresholds are set first."""
    try:
        from numpy._core.multiarray import _set_madvise_hugepage
    except ImportError:  # numpy < 2 without the numpy._core alias
        from numpy.core.multiarray import _set_madvise_hugepage
    was = _set_madvise_hugepage(False)
    libc = _memory._libc()
    if libc is not None:
        libc.mallopt(_memory._M_MMAP_THRESHOLD, _memory._DEFAULT)
        libc.mallopt(_memory._M_TRIM_THRESHOLD, _memory._DEFAULT)
    yield
    _set_madvise_hugepage(was)


_FAULTS_SCRIPT = """
import json, resource
import numpy as np
from lipgen import _memory
from lipgen._memory import reuse_freed_memory
try:
    from numpy._core.multiarray import _set_madvise_hugepage
except ImportError:
    from numpy.core.multiarray import _set_madvise_hugepage
_set_madvise_hugepage(False)
libc = _memory._libc()
libc.mallopt(_memory._M_MMAP_THRESHOLD, _memory._DEFAULT)
libc.mallopt(_memory._M_TRIM_THRESHOLD, _memory._DEFAULT)

def faults(rounds=4, n=10, size=8 << 20):
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(rounds):
        held = [np.ones(size, np.uint8) for _ in range(n)]
        del held
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0

out = {"before": faults()}
with reuse_freed_memory():
    faults(1)  # the first round grows the heap once
    out["inside"] = faults()
faults(1, n=4)
out["kept"] = faults(n=4)
out["mapped"] = faults(n=1, size=_memory.AFTER_MMAP_THRESHOLD + (8 << 20))
print(json.dumps(out))
"""


@glibc
def test_large_arrays_reuse_freed_pages_inside_the_block_only():
    """Measured in a fresh process. In a test worker, what ran before could change how a 40 MB block
    was served: `mapped` read 8 faults instead of ~40,000 in about 1 of 5 runs (random test order;
    the cause was not pinned down)."""
    import json
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != MEMORY_POLICY_ENV}
    run = subprocess.run([sys.executable, "-c", _FAULTS_SCRIPT], capture_output=True, text=True, env=env,
                         check=True)
    f = json.loads(run.stdout)
    big = _memory.AFTER_MMAP_THRESHOLD + (8 << 20)
    assert f["before"] > 0.8 * _ROUND  # glibc's own settings: the pages are given back and faulted in again
    assert f["inside"] < 0.1 * _ROUND  # kept: the same pages again
    # after it, the limits glibc's adaptive rule reaches: 32 MB at a time is kept (below its trim
    # threshold), a block above its mmap threshold is mapped and given back each time
    assert f["kept"] < 0.1 * _ROUND * 4 / 10
    assert f["mapped"] > 0.8 * 4 * big // resource.getpagesize()


@glibc
def test_the_policy_can_be_turned_off(monkeypatch):
    monkeypatch.setenv(MEMORY_POLICY_ENV, "off")
    assert keep_freed_memory() is False
    with reuse_freed_memory():
        assert _faults_allocating() > 0.8 * _ROUND


@pytest.mark.render
def test_generate_writes_the_same_bytes_with_the_policy_off(tmp_path, monkeypatch):
    pytest.importorskip("lipgen.rig.render")
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings

    s = GenerateSettings(frames=3, seed=4, size=(160, 120), calib_frames=1, script="AA:0.2 M")
    on = generate(tmp_path / "on", s, progress=False)
    monkeypatch.setenv(MEMORY_POLICY_ENV, "off")
    off = generate(tmp_path / "off", s, progress=False)
    files = sorted(p.relative_to(on) for p in on.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(off) for p in off.rglob("*") if p.is_file())
    assert [(on / f).read_bytes() for f in files] == [(off / f).read_bytes() for f in files]


def test_a_block_inside_another_leaves_the_outer_setting(monkeypatch):
    """Only the outermost block sets and restores glibc's limits: an inner block's end (e.g. an NRSfM
    completion run inside ``generate``'s block) would otherwise lower the trim threshold under the outer
    block; and a process that keeps freed memory for good keeps it."""
    calls = []
    monkeypatch.setattr(_memory, "_set", lambda mmap, trim: calls.append((mmap, trim)) or True)
    monkeypatch.setattr(_memory, "_libc", lambda: type("L", (), {"malloc_trim": staticmethod(lambda n: 1)})())
    monkeypatch.setattr(_memory, "_kept", False)
    monkeypatch.setattr(_memory, "_depth", 0)
    with reuse_freed_memory():
        with reuse_freed_memory():
            pass
        assert calls == [(_memory.MMAP_THRESHOLD, _memory.TRIM_THRESHOLD)]   # the inner end restored nothing
    assert calls[-1] == (_memory.AFTER_MMAP_THRESHOLD, _memory.AFTER_TRIM_THRESHOLD) and len(calls) == 2
    assert _memory._depth == 0
    calls.clear()
    keep_freed_memory()
    with reuse_freed_memory():
        pass
    assert calls == [(_memory.MMAP_THRESHOLD, _memory.TRIM_THRESHOLD)]    # keep's own call; the block left it
