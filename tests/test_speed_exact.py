"""Speed-ups that must give the same bits as the code they replaced."""

import numpy as np
import pytest

from lipgen.rig.scene import vertex_normals


def _add_at_normals(vertices, faces):
    """The former vertex normals: np.cross and np.add.at over the faces' corners in turn."""
    tri = vertices[faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, faces[:, k], nrm)
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, length, out=np.zeros_like(out), where=length > 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_vertex_normals_are_the_add_at_sum_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    V = rng.standard_normal((500, 3)) * 10.0 ** rng.uniform(-3, 3)
    F = rng.integers(0, 480, (1200, 3))  # vertices 480.. in no face: zero normals
    F[:5, 1] = F[:5, 0]  # degenerate faces
    got = vertex_normals(V, F)
    assert got.tobytes() == _add_at_normals(V, F).tobytes()
    assert not got[480:].any()
    V32 = V.astype(np.float32)  # float32 keeps the float32 sum
    assert vertex_normals(V32, F).tobytes() == _add_at_normals(V32, F).tobytes()


def _integers_rounded_gaussian(shape, sigma, rng):
    """The former draw: ``rng.integers`` per value and a fancy-index table look-up."""
    from lipgen.rig.noise import _STEP, _tables

    edges, values, bucket = _tables(float(sigma))
    u = rng.integers(0, 1 << 32, size=int(np.prod(shape, dtype=np.int64)), dtype=np.uint32)
    k = bucket[u >> np.uint32(16)]
    step = np.flatnonzero(k == _STEP)
    k[step] = values[np.searchsorted(edges, u[step].astype(np.uint64), side="right")]
    return k.reshape(shape)


@pytest.mark.parametrize("bits", ["PCG64", "PCG64DXSM", "MT19937", "Philox"])
@pytest.mark.parametrize("shape", [(48, 64, 3), (7, 5, 3), (1,)])  # even and odd counts
@pytest.mark.parametrize("buffered", [False, True])  # a 32-bit half kept from an earlier draw
def test_rounded_gaussian_draws_the_former_values_and_leaves_the_same_state(bits, shape, buffered):
    from lipgen.rig.noise import rounded_gaussian

    gens = [np.random.Generator(getattr(np.random, bits)(11)) for _ in range(2)]
    if buffered:
        for g in gens:
            g.integers(0, 1 << 32, size=3, dtype=np.uint32)
    for sigma in (1.0, 2.7, 0.3):
        got = rounded_gaussian(shape, sigma, gens[0])
        want = _integers_rounded_gaussian(shape, sigma, gens[1])
        assert got.dtype == want.dtype and got.tobytes() == want.tobytes()
        after = [(g.integers(0, 1 << 32, size=3, dtype=np.uint32), g.random(2)) for g in gens]
        assert all((a == b).all() for a, b in zip(*after, strict=True))  # the same draws after it
