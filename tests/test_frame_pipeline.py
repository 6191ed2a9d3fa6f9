"""The frame pipeline (issue 22): lossless, standard PNG."""

import io

import numpy as np
import pytest


def _decoders(data: bytes) -> list[np.ndarray]:
    """The pixels as Pillow and OpenCV (libpng) decode them (RGB order)."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        im.verify()  # chunk CRCs and structure
    with Image.open(io.BytesIO(data)) as im:
        out = [np.array(im)]
    cv2 = pytest.importorskip("cv2")
    back = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if back.ndim == 3:
        back = back[..., [2, 1, 0, 3][:back.shape[2]]]
    return out + [back]


@pytest.fixture(params=["zlib", "zlib-ng"])
def deflate(request, monkeypatch):
    """Both deflate back ends: zlib-ng when installed, and the standard library's zlib."""
    import zlib

    from lipgen import _io

    if request.param == "zlib":
        monkeypatch.setattr(_io, "_deflate_module", lambda: zlib)
    else:
        pytest.importorskip("zlib_ng")
        assert _io._deflate_module() is not zlib
    return request.param


@pytest.mark.parametrize("shape", [(30, 40, 3), (30, 40), (1, 1), (17, 5, 4), (3, 8, 1)])
@pytest.mark.parametrize("level", [0, 1, 9])
def test_generate_png_is_lossless(shape, level, deflate):
    from lipgen._io import png_bytes

    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    for back in _decoders(png_bytes(image, level)):
        assert back.dtype == np.uint8 and np.array_equal(back, image.reshape(back.shape))


def test_png_of_a_frame_and_a_mask(deflate):
    """Smooth content with noise (a frame) and long runs (a label mask) decode exactly; the mask
    stays small (the filter leaves runs of zeros for the RLE strategy)."""
    from lipgen._io import png_bytes

    rng = np.random.default_rng(2)
    y, x = np.mgrid[0:120, 0:160]
    frame = np.clip(np.stack([x, y, x + y], -1) + rng.integers(-2, 3, (120, 160, 3)), 0, 255).astype(np.uint8)
    mask = ((x - 80) ** 2 + (y - 60) ** 2 < 900).astype(np.uint8) * 3
    for image in (frame, mask):
        for back in _decoders(png_bytes(image, 1)):
            assert np.array_equal(back, image)
    assert len(png_bytes(mask, 1)) < 2000


@pytest.mark.parametrize("image, level, match", [
    (np.zeros((4, 4), np.float32), 1, "uint8 array, got float32 of shape \\(4, 4\\)"),
    (np.zeros((4, 4, 2), np.uint8), 1, "shape \\(4, 4, 2\\)"),
    (np.zeros((0, 4), np.uint8), 1, "shape \\(0, 4\\)"),
    (np.zeros((4, 4), np.uint8), 10, "level .* got 10"),
    (np.zeros((4, 4), np.uint8), 1.5, "level .* got 1.5"),
])
def test_png_bad_input_is_named(image, level, match):
    from lipgen._io import png_bytes

    with pytest.raises(ValueError, match=match):
        png_bytes(image, level)
