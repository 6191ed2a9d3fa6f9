"""Markers measured through the camera-mirror rig: pixel noise in both views, triangulated."""

import numpy as np
import pytest

from lipgen.experiments.table51_protocol import measure_through_rig


def test_rig_noise_matches_the_closed_form_of_ray_midpoint_triangulation():
    """The ray midpoint minimises the summed squared distance to the two rays, so for small noise
    its covariance is A⁻¹ (Σ σ² M_i M_iᵀ) A⁻¹, with P_i = I - r_i r_iᵀ the projector across view
    i's ray r_i, A = Σ P_i, and M_i (3, 2) = |X - c_i| P_i ∂r_i/∂uv the shift of the ray at the point
    per pixel (from the pinhole's K and R alone). Depth along the bisector of the two views is
    measured worst (cot 22° ≈ 2.5 times x for the default rig)."""
    from lipgen.rig.camera import default_rig

    rig = default_rig()
    X = np.array([0.0, 5.0, 0.0])  # the rig's target: on both optical axes
    assert np.allclose(measure_through_rig(X, 0.0), X, atol=1e-9)
    sigma = 0.5
    A, B = np.zeros((3, 3)), np.zeros((3, 3))
    for cam in rig.views:
        c = -cam.R.T @ cam.t
        dist = np.linalg.norm(X - c)
        r = (X - c) / dist
        P = np.eye(3) - np.outer(r, r)
        q = np.linalg.inv(cam.K) @ np.append(cam.K[:2, :2] @ (cam.R @ r)[:2] / (cam.R @ r)[2]
                                             + cam.K[:2, 2], 1.0)  # the pixel's ray, camera frame
        d = cam.R.T @ q
        # ∂(d/|d|)/∂uv = P_d R^T K⁻¹[:, :2] / |d|, and d ∥ r
        M = dist * P @ (cam.R.T @ np.linalg.inv(cam.K)[:, :2]) / np.linalg.norm(d)
        A += P
        B += sigma**2 * M @ M.T
    cov = np.linalg.inv(A) @ B @ np.linalg.inv(A)
    samples = measure_through_rig(np.broadcast_to(X, (40000, 3)), sigma, rng=3) - X
    emp = np.cov(samples.T)
    assert np.allclose(np.diag(emp), np.diag(cov), rtol=0.05), (np.diag(emp), np.diag(cov))
    assert abs(emp[0, 2]) < 0.1 * np.sqrt(emp[0, 0] * emp[2, 2]) + abs(cov[0, 2])
    ratio = np.sqrt(emp[2, 2] / emp[0, 0])
    assert 2.0 < ratio < 3.2  # depth worst: about cot(22°), scaled by the two views' distances


def test_rig_noise_bad_input():
    with pytest.raises(ValueError, match="noise_px must be >= 0, got -1"):
        measure_through_rig(np.zeros(3), -1.0)
