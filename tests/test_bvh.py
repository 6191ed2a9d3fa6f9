"""BVH parsing and forward kinematics (lipgen.nrsfm.bvh), and the CMU clips built on them."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lipgen.nrsfm.bvh import joint_positions, parse_bvh

CHAIN = """HIERARCHY
ROOT Hips
{
\tOFFSET 1.0 2.0 3.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT Knee
\t{
\t\tOFFSET 0.0 -4.0 0.0
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0.0 0.0 2.0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: .0083333
0 0 0 0 0 0 0 0 0
10 0 -1 90 25 -15 30 20 -40
"""


def test_a_chain_places_its_joints_by_the_listed_euler_order():
    sk = parse_bvh(CHAIN)
    assert sk.names == ["Hips", "Knee", "Knee_end"]
    assert sk.parents.tolist() == [-1, 0, 1]
    assert sk.motion.shape == (2, 9) and sk.frame_time == pytest.approx(1 / 120, rel=1e-4)
    X = joint_positions(sk)
    # frame 0: offsets only
    np.testing.assert_allclose(X[0], [[1, 2, 3], [1, -2, 3], [1, -2, 5]])
    # frame 1, independently: intrinsic 'ZYX' Euler angles are Rz @ Ry @ Rx
    R0 = Rotation.from_euler("ZYX", [90, 25, -15], degrees=True).as_matrix()
    R1 = R0 @ Rotation.from_euler("ZYX", [30, 20, -40], degrees=True).as_matrix()
    hips = np.array([1 + 10, 2 + 0, 3 - 1])
    knee = hips + R0 @ [0, -4, 0]
    end = knee + R1 @ [0, 0, 2]
    np.testing.assert_allclose(X[1], [hips, knee, end], atol=1e-12)


def test_bone_lengths_stay_fixed_whatever_the_angles():
    rng = np.random.default_rng(0)
    lines = CHAIN.split("MOTION")[0] + "MOTION\nFrames: 50\nFrame Time: 0.01\n"
    lines += "\n".join(" ".join(f"{v:.4f}" for v in row) for row in rng.uniform(-180, 180, (50, 9)))
    X = joint_positions(parse_bvh(lines))
    lengths = np.linalg.norm(X[:, 1:] - X[:, :-1], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to([4.0, 2.0], lengths.shape), rtol=1e-12)


@pytest.mark.parametrize("edit, match", [
    (lambda t: t.replace("0 0 0 0 0 0 0 0 0\n", "0 0 0 0 0 0 0 0\n"),
     "line 19: 8 values, the hierarchy has 9"),
    (lambda t: t.replace("10 0 -1", "10 x -1"), "not a number"),
    (lambda t: t.replace("Zrotation Yrotation Xrotation\n\t\tEnd", "Zrotation Yrotation Wrotation\n\t\tEnd"),
     "bad CHANNELS"),
    (lambda t: t.split("MOTION")[0], "no MOTION"),
    (lambda t: t.replace("\t\t}\n\t}\n}", "\t\t}\n\t}"), "incomplete"),
    (lambda t: t.replace("10 0 -1", "nan 0 -1"), "NaN or inf"),
    (lambda t: t.replace("Frame Time: .0083333", "Frame Time: 0"), "Frame Time must be a positive"),
    (lambda t: t.replace("HIERARCHY\n", "HIERARCHY\nEnd Site\n"), "line 2: End Site outside any joint"),
    (lambda t: t.replace("ROOT Hips\n{\n", "OFFSET 1 2 3\nROOT Hips\n{\n"), "OFFSET outside its joint"),
    (lambda t: t.replace("CHANNELS 3 Zrotation Yrotation Xrotation\n\t\tEnd", "CHANNELS\n\t\tEnd"),
     "bad CHANNELS"),
    (lambda t: t.replace("CHANNELS 3 Zrotation Yrotation Xrotation\n\t\tEnd",
                         "CHANNELS x Zrotation Yrotation Xrotation\n\t\tEnd"), "bad CHANNELS"),
])
def test_a_malformed_file_is_refused_with_where(edit, match):
    with pytest.raises(ValueError, match=match):
        parse_bvh(edit(CHAIN))


def _random_body(n_frames: int, seed: int = 0) -> str:
    """A BVH skeleton of a root and two 4-bone limbs, with smooth random angles."""
    limb = ""
    for side in (1, -1):
        rot = "CHANNELS 3 Zrotation Yrotation Xrotation"
        limb += f"\tJOINT L{side}\n\t{{\n\t\tOFFSET {side}.0 0.0 0.0\n\t\t{rot}\n"
        limb += f"\t\tJOINT M\n\t\t{{\n\t\t\tOFFSET 0.0 -3.0 0.5\n\t\t\t{rot}\n"
        limb += "\t\t\tEnd Site\n\t\t\t{\n\t\t\t\tOFFSET 0.3 -2.0 0.0\n\t\t\t}\n\t\t}\n\t}\n"
    head = ("HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation "
            "Yrotation Xrotation\n" + limb + f"}}\nMOTION\nFrames: {n_frames}\nFrame Time: .0083333\n")
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames)[:, None] / 30.0
    angles = 40 * np.sin(2 * np.pi * rng.uniform(0.2, 1.0, 18) * t + rng.uniform(0, 6, 18))
    angles[:, :3] = 0.1 * angles[:, :3]
    return head + "\n".join(" ".join(f"{v:.4f}" for v in row) for row in angles) + "\n"


def test_a_window_keeps_whole_frames_and_counts_them():
    from lipgen.nrsfm.mocap import assemble_window

    text = _random_body(30)
    head, frames = text.split("Frame Time: .0083333\n")
    head += "Frame Time: .0083333\n"
    cut = frames[37:-11]                       # starts and ends inside lines
    window = parse_bvh(assemble_window(head + frames[:5], cut))
    whole = parse_bvh(text)
    np.testing.assert_array_equal(window.motion, whole.motion[1:-1])
    assert "Frames: 28\n" in assemble_window(head, cut)
    # the whole file given as the head: its own frames
    np.testing.assert_array_equal(parse_bvh(assemble_window(text, "")).motion, whole.motion)
    with pytest.raises(ValueError, match="no MOTION"):
        assemble_window(text.split("MOTION")[0], cut)


def test_clip_points_drop_joints_at_their_parents_place(tmp_path):
    import gzip

    from lipgen.nrsfm.mocap import clip_points, load_clip, mocap_set

    (tmp_path / "run0901.bvh.gz").write_bytes(gzip.compress(_random_body(40).encode()))
    sk = load_clip("run0901", tmp_path)
    X = clip_points(sk)
    assert X.shape == (20, 7, 3)              # every 2nd frame; root, 2 x (limb root, knee, end site)
    (a, b) = mocap_set(clips=["run0901"], folder=tmp_path)
    assert (a.seed, b.seed) == (2000, 2100) and a.W.shape == (40, 7) and a.S.shape == (60, 7)
    # the truth's first two rows of each frame are the tracks, centred
    centred = (a.W - a.W.mean(1, keepdims=True)).reshape(20, 2, 7)
    np.testing.assert_allclose(a.S.reshape(20, 3, 7)[:, :2], centred, atol=1e-9)
    with pytest.raises(ValueError, match="unknown clip"):
        mocap_set(clips=["drink"], folder=tmp_path)
    with pytest.raises(FileNotFoundError, match="not stored"):
        load_clip("walk0701", tmp_path)


def test_the_stored_clips_are_whole_and_rigid():
    from lipgen.nrsfm.mocap import CLIPS, DATA, clip_points, load_clip

    missing = [n for n in CLIPS if not (DATA / f"{n}.bvh.gz").is_file()]
    assert not missing, f"clips not stored: {missing}"
    for name in CLIPS:
        sk = load_clip(name)
        assert sk.motion.shape[1] == sk.n_channels == 96 and len(sk.motion) >= 120, name
        X = joint_positions(sk)
        bones = np.linalg.norm(X[:, 1:] - X[:, sk.parents[1:]], axis=-1)
        np.testing.assert_allclose(bones, np.broadcast_to(bones[0], bones.shape), atol=1e-9, err_msg=name)
        assert clip_points(sk).shape[1] >= 25, name


def test_an_unknown_clip_is_refused_before_anything_runs(tmp_path, capsys):
    from lipgen.cli import main

    out = tmp_path / "out"
    status = main(["experiment", "nrsfm", "--sequences", "--mocap-clips", "drink", "--out", str(out)])
    assert status == 1 and not out.exists()
    assert "unknown --mocap-clips ['drink']; the clips are run0901" in capsys.readouterr().err
