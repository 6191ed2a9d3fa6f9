"""The frame pipeline (issue 22): integer sensor noise (law, clipping, determinism), lossless PNG."""

import numpy as np
import pytest
from scipy.special import ndtr

from lipgen.rig.noise import TABLE_BITS, add_gray_noise, gray_noise_table


@pytest.mark.parametrize("sigma", [0.4, 1.0, 3.7])
def test_noise_has_the_law_of_rounded_gaussian_noise(sigma):
    image = np.full((1000, 1000), 128, np.uint8)  # far from the clip
    k = add_gray_noise(image, sigma, np.random.default_rng(7)).astype(int) - 128
    values, counts = np.unique(k, return_counts=True)
    p = ndtr((values + 0.5) / sigma) - ndtr((values - 0.5) / sigma)
    n = k.size
    # each count within 5 binomial standard deviations (plus the table's 2**-20 resolution)
    assert np.all(np.abs(counts - n * p) <= 5 * np.sqrt(n * p * (1 - p)) + n * 2.0**-TABLE_BITS + 1)
    # every value with probability above 1e-5 occurs, and no value the law makes impossible
    K = np.arange(-int(10 * sigma) - 2, int(10 * sigma) + 3)
    pk = ndtr((K + 0.5) / sigma) - ndtr((K - 0.5) / sigma)
    assert set(K[pk > 1e-5]) <= set(values)
    sd = np.sqrt(np.sum(K**2 * pk))  # the law's standard deviation (mean 0 by symmetry)
    assert abs(k.mean()) < 5 * sd / np.sqrt(n) and abs(k.std() / sd - 1) < 0.01


def test_table_is_the_inverse_cdf():
    t = gray_noise_table(1.0)
    assert t.shape == (2**TABLE_BITS,) and np.all(np.diff(t) >= 0) and np.array_equal(t, -t[::-1])
    with pytest.raises(ValueError, match="sigma"):
        gray_noise_table(0.0)


def test_noise_clips_is_deterministic_and_off_at_zero():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    a = add_gray_noise(image, 20.0, np.random.default_rng(3))
    b = add_gray_noise(image, 20.0, np.random.default_rng(3))
    assert a.dtype == np.uint8 and a.shape == image.shape and np.array_equal(a, b)
    assert (a[image == 0] <= 60).all() and (a == 0).any() and (a == 255).any()  # clipped, not wrapped
    assert add_gray_noise(image, 0.0, rng) is image
    with pytest.raises(TypeError, match="uint8"):
        add_gray_noise(image.astype(float), 1.0, rng)


@pytest.mark.parametrize("shape", [(30, 40, 3), (30, 40)])
@pytest.mark.parametrize("level", [0, 1, 9])
def test_generate_png_is_lossless(shape, level):
    import io

    from PIL import Image

    from lipgen._io import png_bytes

    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    back = np.array(Image.open(io.BytesIO(png_bytes(image, level))))
    assert back.dtype == np.uint8 and np.array_equal(back, image)
