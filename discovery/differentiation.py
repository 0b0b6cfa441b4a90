"""Smoothing differentiation of logged velocity, and the matching smoothing of forces.

:class:`LocalPolynomial` is a Savitzky-Golay filter that also accepts jittered sample
times: at every sample a polynomial of degree ``order`` is fitted by least squares to
the ``window`` samples around it (shifted inwards at the ends of a segment, like
``scipy.signal.savgol_filter(mode="interp")``) and its value or first derivative at
the sample is the smoothed value or derivative. On uniformly spaced samples the
weights are exactly SciPy's (a test checks this).

Why a matched force kernel. The force residual (paper Eq. 28) compares the measured
``m a`` with the modelled forces. Differentiating noisy velocity needs smoothing, and
smoothing only one side of the equation would leave a lag error wherever the
acceleration changes. Any linear derivative estimate ``D v_k = sum_i h_ki v_i`` can
be rewritten, by summation by parts, as a weighted sum of the velocity increments
``v_{j+1} - v_j``, each of which is the integral of the acceleration over that step::

    D v_k = sum_j c_kj (v_{j+1} - v_j) = sum_j c_kj dt_j abar_j,   c_kj = -sum_{i <= j} h_ki

so :meth:`LocalPolynomial.step_average` applies exactly the weights ``c_kj dt_j`` (they
sum to one) to step-averaged forces. Then ``m D v_k`` and the smoothed model force
describe the same stretch of flight and differ only by noise and by what the model
lacks.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix

__all__ = ["LocalPolynomial", "moving_average", "window_samples"]

_ROWS_PER_BLOCK = 4096  # rows solved at once (bounds memory at 1 kHz)


def window_samples(t: np.ndarray, window_s: float, order: int) -> int:
    """Samples in a window of ``window_s`` seconds at the median rate: odd, at least ``order + 3``."""
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    w = int(round(window_s / dt)) + 1
    w = max(w, order + 3)
    w += 1 - w % 2
    return min(w, len(t) if len(t) % 2 == 1 else len(t) - 1)


def moving_average(x: np.ndarray, size: int) -> np.ndarray:
    """Mean over ``size`` samples around each sample along axis 0, ends padded with the end values.

    The same as ``scipy.ndimage.uniform_filter1d(x, size, axis=0, mode="nearest")``, without the import
    of ``scipy.ndimage`` (a fifth of a second).
    """
    x = np.asarray(x, dtype=float)
    size = max(1, int(size))
    padded = np.concatenate([np.repeat(x[:1], size // 2, axis=0), x, np.repeat(x[-1:], (size - 1) // 2, axis=0)])
    sums = np.cumsum(np.concatenate([np.zeros_like(x[:1]), padded]), axis=0)
    return (sums[size:] - sums[:-size]) / size


def _correlate_valid(x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Valid correlation along axis 0 by FFT: entry ``m`` is ``sum_j h[j] x[m + j]``, ``(n - len(h) + 1, d)``.

    NumPy's FFT rather than ``scipy.signal.fftconvolve``: importing ``scipy.signal`` takes about half a
    second, a tenth of the whole ``discover`` command's budget for a one-minute log.
    """
    n, w = len(x), len(h)
    size = 1 << int(np.ceil(np.log2(n + w - 1)))
    spectrum = np.fft.rfft(x, size, axis=0) * np.fft.rfft(h[::-1], size)[:, None]
    return np.fft.irfft(spectrum, size, axis=0)[w - 1 : n]


class LocalPolynomial:
    """Least-squares polynomial smoothing and differentiation on (possibly jittered) sample times.

    Parameters
    ----------
    t: sample times (s), strictly increasing, one segment without gaps.
    window_s: window length (s); converted to an odd number of samples at the median rate.
    order: polynomial degree (at least 1).

    Uniformly spaced times (steps equal within 0.1 %) share one set of interior weights
    applied by correlation; jittered times get per-sample weights.
    """

    def __init__(self, t: np.ndarray, window_s: float = 0.2, order: int = 2):
        t = np.asarray(t, dtype=float)
        if t.ndim != 1 or len(t) < order + 2:
            raise ValueError(f"need at least {order + 2} samples for a degree-{order} fit, got {len(t)}")
        if order < 1:
            raise ValueError(f"order must be at least 1 to differentiate, got {order}")
        self.t = t
        self.n = len(t)
        self.order = order
        self.window = window_samples(t, window_s, order)
        self.half = self.window // 2
        self.start = np.clip(np.arange(self.n) - self.half, 0, self.n - self.window)
        dt = np.diff(t)
        self.dt = dt
        median = float(np.median(dt))
        self.uniform = bool(np.max(np.abs(dt - median)) <= 1e-3 * median) and self.n > 2 * self.window
        if self.uniform:
            # rows whose window is centred share weights; only the ends need their own
            self.rows = np.concatenate([np.arange(self.half), np.arange(self.n - self.half, self.n)])
            centre = np.array([self.half])
            uniform_t = np.arange(self.window) * median
            h0, h1, hs = self._weights(uniform_t, centre, np.zeros(1, dtype=int))
            self.interior = {"value": h0[0], "derivative": h1[0], "step": hs[0]}
        else:
            self.rows = np.arange(self.n)
            self.interior = {}
        self.edge = dict(zip(("value", "derivative", "step"), self._weights(t, self.rows, self.start[self.rows])))

    def _weights(self, t: np.ndarray, rows: np.ndarray,
                 starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value, derivative and matched step weights for ``rows`` whose windows begin at ``starts``."""
        offsets = np.arange(self.window)
        scale = max(float(t[self.window - 1] - t[0]) / 2.0, 1e-9)
        h0 = np.empty((len(rows), self.window))
        h1 = np.empty((len(rows), self.window))
        for lo in range(0, len(rows), _ROWS_PER_BLOCK):
            block = slice(lo, min(lo + _ROWS_PER_BLOCK, len(rows)))
            idx = starts[block, None] + offsets
            tau = (t[idx] - t[rows[block], None]) / scale  # (r, W), scaled for conditioning
            V = np.empty(tau.shape + (self.order + 1,))
            V[..., 0] = 1.0
            for k in range(1, self.order + 1):
                V[..., k] = V[..., k - 1] * tau
            normal = np.einsum("rwi,rwj->rij", V, V)
            X = np.linalg.solve(normal, V.transpose(0, 2, 1))  # (r, p, W): polynomial coefficients per sample
            h0[block] = X[:, 0]
            h1[block] = X[:, 1] / scale
        dt = np.diff(t)
        step = -np.cumsum(h1[:, :-1], axis=1) * dt[starts[:, None] + offsets[:-1]]
        return h0, h1, step

    def smooth(self, x: np.ndarray) -> np.ndarray:
        """Smoothed values ``(n, ...)`` of samples ``x`` ``(n, ...)``."""
        return self._apply("value", x, self.n)

    def derivative(self, x: np.ndarray) -> np.ndarray:
        """Smoothed first derivative ``(n, ...)`` of samples ``x`` ``(n, ...)`` (per second)."""
        return self._apply("derivative", x, self.n)

    def step_average(self, x_steps: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """The matched smoothing ``(n, ...)`` of per-step averages ``x_steps`` ``(n - 1, ...)``.

        ``step_average(diff(v) / diff(t)) == derivative(v)`` up to rounding. With ``rows``
        (sample indices) only those rows are computed and returned.
        """
        if rows is not None:
            return self._apply_rows("step", x_steps, self.n - 1, np.asarray(rows))
        return self._apply("step", x_steps, self.n - 1)

    def _row_weights(self, kind: str, rows: np.ndarray) -> np.ndarray:
        """Weights ``(len(rows), width)`` of the given rows."""
        if not self.uniform:
            return self.edge[kind][rows]
        weights = np.broadcast_to(self.interior[kind], (len(rows), len(self.interior[kind]))).copy()
        position = {int(r): i for i, r in enumerate(self.rows)}
        for i, r in enumerate(rows):
            j = position.get(int(r))
            if j is not None:
                weights[i] = self.edge[kind][j]
        return weights

    def _apply_rows(self, kind: str, x: np.ndarray, expected: int, rows: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape[0] != expected:
            raise ValueError(f"expected {expected} rows, got {x.shape[0]}")
        flat = x.reshape(expected, -1)
        key = (kind, rows.tobytes())
        cache = self.__dict__.setdefault("_row_cache", {})
        if key not in cache:  # the rows' weights as a sparse matrix (rows x expected)
            weights = self._row_weights(kind, rows)
            columns = self.start[rows, None] + np.arange(weights.shape[1])
            cache[key] = csr_matrix((weights.ravel(), (np.repeat(np.arange(len(rows)), weights.shape[1]),
                                                       columns.ravel())), shape=(len(rows), expected))
        out = cache[key] @ flat
        return np.asarray(out).reshape((len(rows),) + x.shape[1:])

    def _apply(self, kind: str, x: np.ndarray, expected: int) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape[0] != expected:
            raise ValueError(f"expected {expected} rows, got {x.shape[0]}")
        flat = x.reshape(expected, -1)
        out = np.empty((self.n, flat.shape[1]))
        if self.uniform:
            h = self.interior[kind]
            # valid correlation: entry m is sum_j h[j] x[m + j], the window of row m + half
            valid = _correlate_valid(flat, h)
            out[self.half : self.n - self.half] = valid[: self.n - 2 * self.half]
        weights = self.edge[kind]
        idx = self.start[self.rows, None] + np.arange(weights.shape[1])
        out[self.rows] = np.einsum("nw,nwd->nd", weights, flat[idx])
        return out.reshape((self.n,) + x.shape[1:])

    @property
    def noise_gain(self) -> float:
        """``sum(h_value^2)`` of a centred window: the variance ratio of smoothed to raw white noise."""
        h = self.interior["value"] if self.uniform else self.edge["value"][self.n // 2]
        return float(np.sum(h**2))

    def __repr__(self) -> str:
        duration = (self.window - 1) * float(np.median(self.dt))
        return (f"LocalPolynomial(n={self.n}, window={self.window} samples = {duration:.3f} s, order={self.order}, "
                f"{'uniform' if self.uniform else 'jittered'})")
