"""The first frame's detector floor lowered in a pale view (:func:`lipgen.recon.firstframe.first_frame_dots`):
a pale dot under the fixed floor is found after the lowering, a dark view is left as it was."""

import numpy as np
import pytest

from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.firstframe import first_frame_dots, pale_floor
from lipgen.recon.settings import ReconstructSettings

SIGMA = 1.3
# The matched filter (top-hat smoothed by 0.6 sigma) keeps sigma^2 / (sigma^2 + (0.6 sigma)^2) of a
# Gaussian dot's depth at its peak.
KEEP = 1.0 / (1.0 + 0.6 ** 2)


def _grid():
    """(8, 2) dot centres (column, row), 14 px apart, off the pixel grid."""
    cols, rows = np.meshgrid(np.arange(4), np.arange(2))
    return np.column_stack([cols.ravel(), rows.ravel()]) * 14.0 + [30.3, 40.6]


def _image(centres, depths, background=0.8):
    """(100, 100) grey image: Gaussian dots of ``SIGMA`` px and the given depths on a flat background."""
    rows, cols = np.mgrid[0:100, 0:100].astype(float)
    img = np.full((100, 100), background)
    for (u, v), a in zip(centres, depths, strict=True):
        img -= a * np.exp(-((cols - u) ** 2 + (rows - v) ** 2) / (2 * SIGMA ** 2))
    return img


def _found(dots, centres, tol=0.3):
    """(n,) bool: each centre has a dot within ``tol`` px."""
    if len(dots) == 0:
        return np.zeros(len(centres), dtype=bool)
    return np.linalg.norm(centres[:, None] - dots[None], axis=2).min(1) < tol


def _run(images, expected, ratio, least=0.05):
    return first_frame_dots(images, DotSettings(sigma=SIGMA), expected, gate=6.0, robust=False, dark=0.4,
                            ratio=ratio, least=least)


def test_pale_floor_closed_forms():
    assert pale_floor([0.09, 0.10, 0.11], 0.08, 0.7, 0.05) == pytest.approx(0.07)
    assert pale_floor([0.2, 0.3], 0.08, 0.7, 0.05) is None            # dark enough: the floor stays
    assert pale_floor([0.06], 0.08, 0.7, 0.05) == 0.05                # never under the least floor
    assert pale_floor([], 0.08, 0.7, 0.05) is None                    # nothing matched
    assert pale_floor([0.1142], 0.08, 0.7, 0.05) == pytest.approx(0.07994)   # just under: lowered
    assert pale_floor([0.1143], 0.08, 0.7, 0.05) is None                     # just over: kept


def test_a_pale_views_faint_dots_are_found_after_the_lowering():
    """The mirror's dots at a quarter to a third of the direct view's darkness: 5 over the fixed floor
    0.08 (smoothed darkness 0.095), 3 under it (0.071); the lowered floor 0.7 x 0.095 = 0.066 takes them."""
    centres = _grid()
    strong, faint = 0.136, 0.102        # depths; x KEEP = 0.100, 0.075 (0.095, 0.071 off the pixel grid)
    mirror = _image(centres, [strong, strong, faint, strong, faint, strong, faint, strong])
    direct = _image(centres, [0.4] * 8)
    expected = np.stack([centres + [2.0, -1.5]] * 2)
    faint_idx = [2, 4, 6]
    old = detect_dots(mirror, DotSettings(sigma=SIGMA))[0]
    assert _found(old, centres).sum() == 5 and not _found(old, centres[faint_idx]).any()
    new = _run([mirror, direct], expected, ratio=0.7)
    assert _found(new[0][0], centres).all(), "every mirror dot within 0.3 px after the lowering"
    # The direct view's dots (0.4 x KEEP = 0.29) keep the fixed floor: the same output to the bit.
    for a, b in zip(new[1], detect_dots(direct, DotSettings(sigma=SIGMA)), strict=True):
        np.testing.assert_array_equal(a, b)


def test_off_and_dark_views_are_the_fixed_floors_output():
    centres = _grid()
    images = [_image(centres, [0.12] * 8), _image(centres, [0.3] * 8)]
    expected = np.stack([centres] * 2)
    fixed = [detect_dots(img, DotSettings(sigma=SIGMA)) for img in images]
    for ratio in (None, 0.7):     # None: off; 0.7: 0.7 x 0.084 = 0.059, but the least floor 0.08
        out = _run(images, expected, ratio, least=0.08)   # leaves it where it was
        for got, want in zip(out, fixed, strict=True):
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])


def test_a_lowered_floor_changes_the_view_when_allowed():
    """The same pale view with the least floor at 0.05: the floor drops to 0.7 x 0.084 = 0.059, and the
    8th dot (0.063) is found."""
    centres = _grid()
    img = _image(centres, [0.12] * 7 + [0.09])
    expected = np.stack([centres] * 2)
    out = _run([img, img], expected, ratio=0.7)
    assert _found(out[0][0], centres).sum() == 8
    assert _found(detect_dots(img, DotSettings(sigma=SIGMA))[0], centres).sum() == 7


@pytest.mark.parametrize("bad", [0, 1, 1.5, -0.2, True, "0.7", float("nan")])
def test_the_setting_is_checked(bad):
    with pytest.raises(ValueError, match="first_frame_floor"):
        ReconstructSettings(first_frame_floor=bad)


def run_to_the_first_frame(settings):
    """track_raw_frames on one blank image, up to a spy that raises RuntimeError("stop")."""
    import lipgen.recon.steps as steps

    class Layout:
        def split_views(self, raw):
            return raw, raw

    with pytest.raises(RuntimeError, match="stop"):
        steps.track_raw_frames(iter([np.zeros((20, 20))]), Layout(), np.zeros((2, 3, 2)), settings)


def test_the_setting_reaches_the_first_frame(monkeypatch):
    """track_raw_frames hands first_frame_floor and the tracker's floor_min to first_frame_dots."""
    import lipgen.recon.firstpose as firstpose
    seen = {}

    def spy(views, dots, expected, gate, robust, dark, ratio, least):
        seen.update(ratio=ratio, least=least)
        raise RuntimeError("stop")

    monkeypatch.setattr(firstpose, "first_frame_dots", spy)
    run_to_the_first_frame(ReconstructSettings(first_frame_floor=0.6))
    assert seen == {"ratio": 0.6, "least": ReconstructSettings().tracker.floor_min}
