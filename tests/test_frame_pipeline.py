"""The frame pipeline (issue 22): lossless PNG."""

import numpy as np
import pytest


@pytest.mark.parametrize("shape", [(30, 40, 3), (30, 40)])
@pytest.mark.parametrize("level", [0, 1, 9])
def test_generate_png_is_lossless(shape, level):
    import io

    from PIL import Image

    from lipgen._io import png_bytes

    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    back = np.array(Image.open(io.BytesIO(png_bytes(image, level))))
    assert back.dtype == np.uint8 and np.array_equal(back, image)
