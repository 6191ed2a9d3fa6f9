"""The nose mark found again where the tracker lost it, and its stand-in (lipgen.recon.nose)."""

import numpy as np
import pytest
from synthetic_images import background, frame

from lipgen._rotation import rotation_matrix
from lipgen.recon.dots import DotSettings
from lipgen.recon.nose import (
    NoseNeverSeen,
    carried_nose,
    choose_path,
    nose_candidates,
    nose_line,
    predict_nose,
)

RNG = np.random.default_rng(11)
REST = np.vstack([np.c_[RNG.uniform(-25, 25, (12, 2)), RNG.uniform(-4, 4, 12)], [[0.0, 35.0, 12.0]]])


def _moved(scale, angles, shift):
    R = rotation_matrix(np.radians(angles))
    return scale * REST @ R.T + shift


def test_the_nose_is_where_the_moved_layout_puts_it():
    frames = [_moved(1.1, (5, -10, 3), [4.0, -2, 300]), _moved(0.95, (-3, 8, 0), [0.0, 1, 290])]
    points = np.stack(frames)
    visible = np.ones((2, 12), bool)
    visible[1, 4:] = False                                # 4 markers are enough
    np.testing.assert_allclose(predict_nose(points[:, :12], visible, REST), points[:, 12], atol=1e-9)
    visible[1, 3] = False                                 # 3 are not
    assert np.isnan(predict_nose(points[:, :12], visible, REST)[1]).all()


def test_the_stand_in_is_interpolated_where_too_few_lips_are_seen_and_refused_without_any():
    points = np.stack([_moved(1.0, (0, 0, 0), [t, 0, 300]) for t in (0.0, 1.0, 2.0)])
    visible = np.ones((3, 12), bool)
    visible[1] = False
    nose = carried_nose(points[:, :12], visible, REST)
    np.testing.assert_allclose(nose, points[:, 12], atol=1e-9)   # frame 1 halfway, as the truth
    with pytest.raises(NoseNeverSeen, match="4 lip markers"):
        carried_nose(points[:, :12], np.zeros((3, 12), bool), REST)


def _clip(F=30, missed=(10, 20), seed=0):
    """A nose moving 1.2 mm a frame; guesses 5.4 mm off; two chance candidates within 12 mm per frame;
    in ``missed`` frames the mark is not among the candidates, but a chance pair 3 mm from it is."""
    rng = np.random.default_rng(seed)
    true = np.array([0.0, 35, 12]) + np.arange(F)[:, None] * [1.2, 0.3, 0.0]
    guess = true + [5.0, 2.0, 0.0] + rng.normal(0, 0.5, (F, 3))
    cands, truth_index = [], []
    for f in range(F):
        lures = guess[f] + rng.uniform(-7, 7, (2, 3))
        mark = true[f] + rng.normal(0, 0.1, 3)
        if f in missed:
            cands.append(np.vstack([lures, true[f] + [3.0, 0, 0]]))
            truth_index.append(-1)
        else:
            cands.append(np.vstack([lures[:1], mark, lures[1:]]))
            truth_index.append(1)
    return cands, guess, np.array(truth_index)


def test_the_path_follows_the_mark_and_not_the_chance_pairs():
    cands, guess, want = _clip()
    path = choose_path(cands, guess, np.zeros(len(cands), bool), prior_sd=5.0, step_sd=2.0, radius=12.0)
    np.testing.assert_array_equal(path, want)


def test_held_frames_are_kept_and_lone_candidates_are_not_taken():
    cands, guess, want = _clip(missed=())
    held = np.zeros(len(cands), bool)
    held[[0, 29]] = True
    cands[0], cands[29] = cands[0][1:2], cands[29][1:2]   # the tracker's own point there
    path = choose_path(cands, guess, held, prior_sd=5.0, step_sd=2.0, radius=12.0)
    assert path[0] == 0 and path[29] == 0 and (path[1:29] == 1).all()
    # Candidates in two frames only, with nothing before or after: too short a run to stand.
    lone = [np.zeros((0, 3))] * 10
    lone[4], lone[5] = guess[4][None], guess[5][None] + [0.5, 0, 0]
    assert (choose_path(lone, guess[:10], np.zeros(10, bool), 5.0, 2.0, 12.0) == -1).all()


def test_the_candidates_are_the_dot_pairs_whose_rays_meet_near_the_guess():
    from lipgen.rig.pinhole import PinholeCamera

    K = np.array([[800.0, 0, 80], [0, 800, 60], [0, 0, 1]])

    def camera(angle):
        c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
        return PinholeCamera(K=K, R=np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]]), t=np.array([0.0, 0, 300]),
                             width=160, height=120)

    cams = (camera(-20.0), camera(10.0))
    nose = np.array([1.0, 0.5, 0.0])
    far = nose + [0.0, 30.0, 0.0]                          # another dot, outside the search
    rng = np.random.default_rng(2)
    views = [frame(background((120, 160), rng), np.stack([c.project(nose[None])[0], c.project(far[None])[0]]),
                   rng, sigma=1.5, depth=0.4) for c in cams]
    X, uv = nose_candidates(views, cams, nose + [4.0, -3.0, 2.0], radius=12.0, max_gap=1.0,
                            dots=DotSettings(sigma=1.5))
    assert len(X) == 1
    np.testing.assert_allclose(X[0], nose, atol=0.2)
    for v in range(2):
        np.testing.assert_allclose(uv[0, v], cams[v].project(nose[None])[0], atol=0.3)
    # A guess whose window leaves the image gives no candidate.
    assert len(nose_candidates(views, cams, nose + [200.0, 0, 0], 12.0, 1.0, DotSettings(sigma=1.5))[0]) == 0


def test_the_line_says_where_the_nose_came_from():
    assert nose_line(None) is None and nose_line({"searched": 0, "found": 0, "stand_in": False}) is None
    assert nose_line({"searched": 40, "found": 40, "stand_in": False}).endswith("in 40.")
    assert "interpolated in the others" in nose_line({"searched": 5, "found": 3, "stand_in": False})
    assert "carried by the lip markers" in nose_line({"searched": 40, "found": 0, "stand_in": True})


def test_the_setting_is_a_bool():
    from lipgen.recon.settings import ReconstructSettings

    with pytest.raises(ValueError, match="nose_search must be True or False, got 'yes'"):
        ReconstructSettings(nose_search="yes")
