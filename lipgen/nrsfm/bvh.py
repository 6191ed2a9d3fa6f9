"""Biovision hierarchy (BVH) motion capture: the skeleton, its motion, and joint positions.

A BVH file is a joint tree (``OFFSET`` from the parent, ``CHANNELS`` each joint animates) followed by
one line of channel values per frame. A joint's rotation is the product of its rotation channels in
the order they are listed (``Zrotation Yrotation Xrotation`` is ``Rz @ Ry @ Rx``, degrees), applied
in its parent's frame; the root also translates. ``End Site`` blocks are points fixed to their joint.
This is the form the CMU motion-capture library is distributed in, and the standard NRSfM
sequences (drink, pickup, ...) were made from that library.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._rotation import rotation_matrix

__all__ = ["BvhSkeleton", "parse_bvh", "joint_positions"]

_AXES = {"Xrotation": 0, "Yrotation": 1, "Zrotation": 2}
_MOVES = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


@dataclass(frozen=True)
class BvhSkeleton:
    """A parsed BVH file.

    Attributes
    ----------
    names : list of str
        Joints and end sites in file order (an end site is ``"<joint>_end"``).
    parents : (J,) int
        Parent index of each, -1 for the root.
    offsets : (J, 3) float
        Offset from the parent in the parent's frame (file units).
    channels : list of list of str
        Each joint's channel names (empty for end sites).
    motion : (F, C) float
        Channel values per frame, in the order of the joints' channels.
    frame_time : float
        Seconds per frame.
    """

    names: list
    parents: np.ndarray
    offsets: np.ndarray
    channels: list
    motion: np.ndarray
    frame_time: float

    @property
    def n_channels(self) -> int:
        return sum(len(c) for c in self.channels)


def _floats(tokens, where: str) -> list[float]:
    try:
        return [float(t) for t in tokens]
    except ValueError as exc:
        raise ValueError(f"BVH {where}: not a number ({exc})") from None


def parse_bvh(text: str) -> BvhSkeleton:
    """Parse BVH ``text`` (the whole file, or a hierarchy followed by any run of whole frame lines).

    Raises
    ------
    ValueError
        A malformed hierarchy, an unknown channel, or a frame line whose count of values is not the
        hierarchy's channel count (named with its line number).
    """
    lines = text.splitlines()
    names, parents, offsets, channels, stack = [], [], [], [], []
    i = 0
    while i < len(lines) and lines[i].strip() != "MOTION":
        tok = lines[i].split()
        i += 1
        if not tok or tok[0] == "HIERARCHY":
            continue
        if tok[0] in ("ROOT", "JOINT") or tok[:2] == ["End", "Site"]:
            if tok[0] != "ROOT" and not stack:
                raise ValueError(f"BVH line {i}: {' '.join(tok)} outside any joint")
            if len(tok) < 2:
                raise ValueError(f"BVH line {i}: {tok[0]} without a name")
            name = tok[1] if tok[0] != "End" else f"{names[stack[-1]]}_end"
            names.append(name)
            parents.append(stack[-1] if stack else -1)
            offsets.append(None)
            channels.append([])
        elif tok[0] == "{":
            stack.append(len(names) - 1)
        elif tok[0] == "}":
            if not stack:
                raise ValueError(f"BVH line {i}: unbalanced '}}'")
            stack.pop()
        elif tok[0] in ("OFFSET", "CHANNELS") and (not stack or stack[-1] != len(names) - 1):
            raise ValueError(f"BVH line {i}: {tok[0]} outside its joint's braces")
        elif tok[0] == "OFFSET":
            if len(tok) != 4:
                raise ValueError(f"BVH line {i}: OFFSET needs 3 values, got {len(tok) - 1}")
            offsets[stack[-1]] = _floats(tok[1:], f"line {i}")
        elif tok[0] == "CHANNELS":
            chans = tok[2:]
            bad = [c for c in chans if c not in _AXES and c not in _MOVES]
            if bad or len(tok) < 2 or not tok[1].isdigit() or int(tok[1]) != len(chans):
                raise ValueError(f"BVH line {i}: bad CHANNELS {' '.join(tok[1:])!r}")
            channels[stack[-1]] = chans
        else:
            raise ValueError(f"BVH line {i}: unexpected {tok[0]!r} in the hierarchy")
    if stack or not names or any(o is None for o in offsets):
        raise ValueError("BVH hierarchy is incomplete (unbalanced braces or a joint without OFFSET)")
    if i >= len(lines):
        raise ValueError("BVH has no MOTION section")
    frame_time, rows = 1.0 / 120.0, []
    n = sum(len(c) for c in channels)
    for j, line in enumerate(lines[i + 1:], start=i + 2):
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "Frames:":
            continue
        if tok[:2] == ["Frame", "Time:"]:
            frame_time = _floats(tok[2:3], f"line {j}")[0]
            continue
        if len(tok) != n:  # n: the hierarchy's channel count (BvhSkeleton.n_channels)
            raise ValueError(f"BVH line {j}: {len(tok)} values, the hierarchy has {n} channels")
        rows.append(_floats(tok, f"line {j}"))
    if not rows:
        raise ValueError("BVH has no frames")
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise ValueError(f"BVH Frame Time must be a positive number of seconds, got {frame_time!r}")
    motion = np.asarray(rows, float)
    if not np.isfinite(motion).all():
        raise ValueError("BVH frames hold NaN or inf values")
    return BvhSkeleton(names, np.asarray(parents, int), np.asarray(offsets, float), channels, motion,
                       float(frame_time))


def joint_positions(skeleton: BvhSkeleton) -> np.ndarray:
    """World positions of every joint and end site by forward kinematics.

    Returns
    -------
    (F, J, 3) float
        In the file's units and axes.
    """
    F, J = len(skeleton.motion), len(skeleton.names)
    pos = np.zeros((F, J, 3))
    rot = np.zeros((F, J, 3, 3))
    col = 0
    for j in range(J):
        local = np.broadcast_to(np.eye(3), (F, 3, 3)).copy()
        move = np.zeros((F, 3))
        for name in skeleton.channels[j]:
            values = skeleton.motion[:, col]
            col += 1
            if name in _AXES:
                local = local @ rotation_matrix(np.radians(values)[:, None] * np.eye(3)[_AXES[name]])
            else:
                move[:, _MOVES[name]] = values
        p = skeleton.parents[j]
        if p < 0:
            pos[:, j] = skeleton.offsets[j] + move
            rot[:, j] = local
        else:
            pos[:, j] = pos[:, p] + rot[:, p] @ skeleton.offsets[j] + np.einsum("fij,fj->fi", rot[:, p], move)
            rot[:, j] = rot[:, p] @ local
    return pos
