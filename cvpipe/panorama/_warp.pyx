# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of :mod:`cvpipe.panorama.warp` (compute only; the Python module validates and documents)."""


def canvas_maps(const float[::1] alpha, const float[::1] chi, const float[::1] beta, const float[::1] gamma,
                const float[:, ::1] M, float x_end, float y_end, float[:, ::1] mx, float[:, ::1] my,
                unsigned char[:, ::1] mask):
    """The remap maps of a block of canvas rows: ``mx``, ``my`` (-10 where the image has no pixel) and ``mask``
    (255 / 0), with every value computed as ``canvas_to_image`` computes it in float32 (same operations, same order).

    ``alpha``, ``chi`` per column and ``beta``, ``gamma`` per row are the ray's factors; ``M`` the float32 matrix
    from rays to image pixels; a pixel is the image's where ``-0.5 < x < x_end`` and ``-0.5 < y < y_end``.
    """
    cdef Py_ssize_t H = mx.shape[0], W = mx.shape[1], r, c
    cdef float b, g, Z, zs, x, y
    cdef float m00 = M[0, 0], m01 = M[0, 1], m02 = M[0, 2]
    cdef float m10 = M[1, 0], m11 = M[1, 1], m12 = M[1, 2]
    cdef float m20 = M[2, 0], m21 = M[2, 1], m22 = M[2, 2]
    cdef float tiny = 1e-12, edge = -0.5, outside = -10.0  # float32, as numpy compares float32 arrays with them
    cdef bint ok
    with nogil:
        for r in range(H):
            b = beta[r]
            g = gamma[r]
            for c in range(W):
                Z = (m20 * alpha[c] + m22 * chi[c]) * g + m21 * b
                ok = Z > tiny
                zs = Z if ok else 1.0
                x = ((m00 * alpha[c] + m02 * chi[c]) * g + m01 * b) / zs
                y = ((m10 * alpha[c] + m12 * chi[c]) * g + m11 * b) / zs
                ok = ok and x > edge and x < x_end and y > edge and y < y_end
                mx[r, c] = x if ok else outside
                my[r, c] = y if ok else outside
                mask[r, c] = 255 if ok else 0


def clear_outside(unsigned char[:, ::1] pixels, const unsigned char[:, ::1] mask, Py_ssize_t channels):
    """Set to 0 the ``channels`` bytes of ``pixels`` (rows of ``W * channels``) of every pixel where ``mask`` is 0."""
    cdef Py_ssize_t H = mask.shape[0], W = mask.shape[1], r, c, k
    with nogil:
        for r in range(H):
            for c in range(W):
                if mask[r, c] == 0:
                    for k in range(channels):
                        pixels[r, c * channels + k] = 0
