"""Dots are found in the ink image (brightest channel), and layouts are not moved into clutter."""

import numpy as np

from lipgen.recon.dots import DotSettings, as_gray, detect_dots, ink_gray
from lipgen.recon.pointreg import assign, register_points

# Colours measured in our renders (uint8 RGB): skin, lip, ink dot.
SKIN, LIP, INK = np.array([208, 155, 126.0]), np.array([182, 84, 84.0]), np.array([41, 42, 39.0])
H, W, SS = 80, 120, 4


def _supersampled_grid():
    off = (np.arange(SS) + 0.5) / SS - 0.5  # pixel i covers [i - 0.5, i + 0.5]
    ys = (np.arange(H)[:, None] + off).ravel()
    xs = (np.arange(W)[:, None] + off).ravel()
    return np.meshgrid(xs, ys)


def _coverage(mask):
    return mask.reshape(H, SS, W, SS).mean((1, 3))


def _lip_line_frame(dots, edge_y, rng):
    """Lip above the line y = edge_y, skin below, ink dots (radius 2.2 px), sensor noise 1."""
    sx, sy = _supersampled_grid()
    lip = _coverage(sy < edge_y)[..., None]
    img = SKIN * (1 - lip) + LIP * lip
    for u, v in dots:
        d = _coverage(np.hypot(sx - u, sy - v) < 2.2)[..., None]
        img = img * (1 - d) + INK * d
    return np.clip(img + rng.normal(scale=1.0, size=img.shape), 0, 255).round().astype(np.uint8)


def test_ink_gray_is_the_brightest_channel():
    img = np.array([[[10, 200, 30], [255, 0, 0]], [[0, 0, 0], [40, 41, 39]]], np.uint8)
    assert np.allclose(ink_gray(img), np.array([[200, 255], [0, 41]]) / 255)
    assert np.allclose(ink_gray(img[..., :1].squeeze(-1)), as_gray(img[..., :1].squeeze(-1)))
    rgba = np.concatenate([img, np.full(img.shape[:2] + (1,), 7, np.uint8)], axis=2)
    assert np.allclose(ink_gray(rgba), ink_gray(img))


def test_dots_beside_the_lip_line_are_not_pulled_toward_it():
    """In luminance the lip line is nearly as dark against the skin as ink is against the lip,
    so a dot 3 px from it is pulled toward the edge; the ink image barely sees the edge."""
    rng = np.random.default_rng(0)
    errors = {"ink": [], "luminance": []}
    for _ in range(10):
        edge = 40.0 + rng.uniform(-0.5, 0.5)
        dots = np.column_stack([np.linspace(15, 105, 6) + rng.uniform(-1, 1, 6),
                                edge - 3.2 + rng.uniform(-0.3, 0.3, 6)])
        img = _lip_line_frame(dots, edge, rng)
        luminance = np.round(as_gray(img) * 255).astype(np.uint8)
        for name, image in (("ink", img), ("luminance", luminance)):
            uv, _ = detect_dots(image, DotSettings(sigma=1.2))
            assert len(uv) == 6, f"{name}: every dot and nothing else"
            errors[name].append(np.linalg.norm(uv[:, None] - dots[None], axis=2).min(0))
    rms = {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for k, v in errors.items()}
    assert rms["ink"] < 0.15, rms
    assert rms["luminance"] > 2 * rms["ink"], rms


def test_registration_never_moves_the_layout_into_clutter():
    """ICP's wide first gate can slide into clutter; the layout as given explains more dots here,
    so it must be kept (the unguarded ICP ended 23 px from the truth in this scene)."""
    rng = np.random.default_rng(34)
    layout = rng.uniform(0, 60, size=(12, 2))
    truth = layout + rng.normal(scale=1.0, size=(12, 2))
    keep = rng.random(12) < 0.7
    clutter = rng.uniform(-30, 90, size=(rng.integers(5, 25), 2))
    dots = np.vstack([truth[keep], clutter])
    still = assign(layout, dots, np.full(12, 8.0))
    match, moved = register_points(dots, layout, 8.0)
    assert (match >= 0).sum() >= (still >= 0).sum()
    assert np.abs(moved - truth).max() < 3.0
