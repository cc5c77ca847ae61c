"""Synthetic pinhole cameras for the two-view tests (epipolar geometry, rectification): a rotation from three angles
and the projection of 3-D points."""

import numpy as np


def rotation(ax, ay, az):
    """``Rz @ Ry @ Rx`` for the angles (radians) about the x, y and z axes."""
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def project(X, K, R=np.eye(3), t=np.zeros(3)):
    """(N, 2) pixels of the (N, 3) points ``X`` in the camera ``K [R | t]``."""
    x = (X @ R.T + t) @ K.T
    return x[:, :2] / x[:, 2:]
