"""The noise floor of a log, measured from the log itself, and the spectrum of what a model leaves.

The force residual (paper Eq. 28) is the matched smoothing ``K`` of a per-step quantity,
``r_k = sum_j w_j e_{k+j}`` with ``e_j = m (v_{j+1} - v_j) / dt + m g e3 - T_j z_j - F_j``
(:mod:`discovery.differentiation`, :mod:`discovery.residuals`). Aerodynamic effects and
manoeuvres live below a few hertz; above :data:`BAND_HZ` the per-step quantity is what the
sensors and the unlogged disturbances add. Its spectrum there is fitted, per world axis,
with two kinds of noise: white (a force or thrust disturbance, attitude noise) and
differenced white (velocity measurement noise differentiated), ``S(nu) = A + B 2 (1 -
cos 2 pi nu)`` (two-sided, per cycle per step). The same two kinds pass the smoothing
kernel as ``A sum w^2 + B sum (w_j - w_{j+1})^2``: that is the **noise floor**, the rms
force residual a perfect model would leave on held-out data (:func:`noise_floor`). A logged
acceleration read as the mean of each step's two samples
(:func:`discovery.residuals.accelerometer_steps`) brings its white noise averaged,
``A (1 + cos 2 pi nu) / 2``, which passes the kernel as ``A sum ((w_j + w_{j+1}) / 2)^2``:
fitted as white, it put the floor of a clean 100 Hz log at 0.037 N under its 0.050 N residual.

A residual within about the floor is noise; one well above it is a force the model does
not describe, and :func:`residual_spectrum` says where it lives in time: the excess of its
power spectrum over the noise's, its peak (a periodic gust) and how much of the excess lies
below :data:`SLOW_HZ` (a wind that changes over seconds).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import nnls

from discovery.residuals import FlightData, Segment, step_average_samples

__all__ = ["BAND_HZ", "SLOW_HZ", "FLOOR_FACTOR", "TRANSIENT_RATIO", "step_residual", "noise_floor", "judged_floor",
           "residual_spectrum"]

BAND_HZ = 2.0  # Hz: above this the per-step residual is noise (manoeuvres and effects live below ~1 Hz)
SLOW_HZ = 0.5  # Hz: a residual varying below this varies over seconds (a changing wind, a gust)
#: a held-out residual more than this many times the noise floor (rms) is more than noise
FLOOR_FACTOR = 1.5
_WELCH_S = 2.56  # s per Welch segment of the per-step residual (0.4 Hz resolution)
_SPECTRUM_S = 20.0  # s per Welch segment of the smoothed residual (0.05 Hz resolution)
JACKKNIFE_GROUPS = 8  # groups of Welch segments the floor's spread is taken over (leaving out one at a time)
Z_UPPER_95 = 1.645  # standard normal quantile of a one-sided 95 % bound
#: a log whose per-step residual has, at the top quarter of the band, less than this share of the power the two
#: noise shapes fitted predict (on its weakest axis) has noise that falls with frequency: filtered states
FILTERED_SHARE = 0.5
#: a Welch segment whose power in the band, bin by bin against the typical segment's, is more than this many times
#: the typical segment's on any axis (:func:`_stationary`) holds a transient the model does not describe (a guard
#: grazing a wall on each pass, a strike), not the log's stationary noise: it is left out of the floor. Over 20
#: draws of stationary noise through a real segment's kernel, none was.
TRANSIENT_RATIO = 2.0


def step_residual(seg: Segment) -> np.ndarray:
    """The per-step quantity ``e`` ``(n - 1, 3)`` whose matched smoothing is the segment's measured force.

    On a log with a step longer than the rest (a sample the logger dropped) each step's impulse is taken over the
    median period, ``(m dv_j + (m g e3 - T_j z_j) dt_j) / dt``: the velocity noise stays differenced white (its
    increments still sum to the end values' difference), where dividing each increment by its own step left a
    white part that raised the floor threefold with one sample in twenty dropped. The slow force the data show
    (the smoothed measured force) is taken at each step's own length, ``F (dt_j / dt - 1)`` less: a steady 2.4 N
    (an affine thrust map's offset) scaled by the longer steps alone was spikes of white power eight times the
    noise's."""
    mass = seg.states.mass
    weight_less_thrust = mass * seg.gravity * np.array([0.0, 0.0, 1.0]) - seg.thrust[:-1, None] * seg.z_body_steps
    if seg.a_steps is not None:  # a measured acceleration: its mean over each step
        return mass * seg.a_steps + weight_less_thrust
    assert seg.v_raw is not None, "a segment keeps its logged velocity or acceleration"
    stretch = (np.diff(seg.t) / seg.dt)[:, None]  # each step over the median period
    slow = step_average_samples(seg.measured_force)
    return mass * np.diff(seg.v_raw, axis=0) / seg.dt + weight_less_thrust * stretch - slow * (stretch - 1.0)


def _periodograms(x: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided power per cycle per step of the columns of ``x`` ``(n, d)`` at ``length // 2 + 1`` frequencies,
    one periodogram per Hann-windowed, half-overlapping segment, in time order: ``(nu, (k, f, d))``."""
    length = min(length, len(x))
    window = np.hanning(length)
    norm = float(np.sum(window**2))
    starts = range(0, len(x) - length + 1, max(1, length // 2))
    powers = [np.abs(np.fft.rfft((x[s:s + length] - x[s:s + length].mean(axis=0)) * window[:, None], axis=0)) ** 2
              / norm for s in starts]
    return np.fft.rfftfreq(length), np.asarray(powers)


def _stationary(powers: np.ndarray, band: np.ndarray) -> np.ndarray:
    """Which of the periodograms ``powers`` ``(k, f, d)`` hold the log's stationary noise ``(k,)``: on every axis,
    their power relative to the median periodogram's, bin by bin over ``band`` and then averaged, within
    :data:`TRANSIENT_RATIO` times the median periodogram's such mean. Taken bin by bin, the low end of the band
    counts as much as the top: there the white level is fitted, under the differenced noise that dominates the
    band's total power."""
    in_band = powers[:, band, :]
    typical = np.median(in_band, axis=0)
    relative = np.mean(np.where(typical > 0, in_band / np.where(typical > 0, typical, 1.0), 0.0), axis=1)
    centre = np.median(relative, axis=0)
    return np.all((relative <= TRANSIENT_RATIO * centre) | (centre <= 0.0), axis=1)


def _welch(x: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch's estimate: the mean of :func:`_periodograms`, ``(nu, (f, d))``; a mean over ``nu`` equals the
    variance."""
    nu, powers = _periodograms(x, length)
    return nu, powers.mean(axis=0)


def _white_shape(nu: np.ndarray, averaged: bool) -> np.ndarray:
    """The white noise's spectral shape per cycle per step: flat, or ``(1 + cos 2 pi nu) / 2`` when each step's value
    is the mean of two white samples (``averaged``)."""
    return 0.5 * (1.0 + np.cos(2 * np.pi * nu)) if averaged else np.ones(len(nu))


def _design(nu: np.ndarray, averaged: bool) -> np.ndarray:
    """The two noise shapes at ``nu`` ``(f, 2)``: white (:func:`_white_shape`) and differenced white."""
    return np.column_stack([_white_shape(nu, averaged), 2.0 * (1.0 - np.cos(2 * np.pi * nu))])


def _levels_covariance(nu: np.ndarray, levels: np.ndarray, averaged: bool, periodograms: int) -> np.ndarray:
    """Whittle's covariance ``(2, 2)`` of levels ``(A, B)`` fitted to the mean of ``periodograms`` Welch periodograms:
    the inverse of ``K sum g g^T / S^2`` over the band, ``K`` half their number (half-overlapping Hann segments and
    neighbouring bins are correlated: so halved, it matched the spread of the white level over draws of the noise
    within 0.85-1.05)."""
    design = _design(nu, averaged)
    top = float(np.max(design @ levels))
    if not top > 1e-200:  # no noise fitted (a noise-free log): nothing uncertain about it
        return np.zeros((2, 2))
    model = np.maximum(design @ levels, 1e-12 * top)
    scaled = design / model[:, None]
    return np.linalg.pinv(0.5 * periodograms * scaled.T @ scaled)


def _fit_levels(nu: np.ndarray, power: np.ndarray, rounds: int = 5, averaged: bool = False) -> np.ndarray:
    """White and differenced-white levels ``(A, B) >= 0`` of a periodogram, ``S = A + B 2 (1 - cos 2 pi nu)`` (the
    white part shaped by :func:`_white_shape` when ``averaged``).

    Least squares weighted by the model itself (Whittle's likelihood, as iteratively reweighted least
    squares): every bin counts by its relative error, so the white level is set where it shows (the low
    end of the band) rather than swamped by the differenced noise that grows with frequency."""
    design = _design(nu, averaged)
    top = float(np.max(power)) if len(power) else 0.0
    if not np.isfinite(top) or top <= 1e-200:  # a noise-free log (synthetic): no noise to fit
        return np.zeros(2)
    levels = nnls(design, power)[0]
    for _ in range(rounds):
        model = np.maximum(design @ levels, 1e-12 * top)
        levels = nnls(design / model[:, None], power / model)[0]
    return levels


def _axes_levels(nu: np.ndarray, power: np.ndarray, averaged: bool) -> np.ndarray:
    """:func:`_fit_levels` of each world axis of ``power`` ``(f, 3)``: ``(3, 2)``, A and B per axis."""
    return np.array([_fit_levels(nu, power[:, a], averaged=averaged) for a in range(3)])


def _refine_peak(data: FlightData, residual: np.ndarray, peak_hz: float, resolution_hz: float) -> float:
    """The frequency within one Welch bin of ``peak_hz`` at which a sinusoid (a sine and a cosine per axis, over
    the whole log) takes most of ``residual``'s energy: a gust's period to a fraction of the Welch resolution,
    so that a sinusoid fitted on some folds stays in phase on the others."""
    t = data.times
    best, best_energy = peak_hz, -1.0
    for f in np.linspace(max(peak_hz - resolution_hz, resolution_hz / 4), peak_hz + resolution_hz, 41):
        basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
        coefficients, *_ = np.linalg.lstsq(basis, residual, rcond=None)
        energy = float(np.sum((basis @ coefficients) ** 2))
        if energy > best_energy:
            best, best_energy = float(f), energy
    return best


def _kernel_gains(seg: Segment) -> tuple[float, float]:
    """``sum w^2`` and ``sum (w_j - w_{j+1})^2`` of the weights the segment's interior kernel gives the impulses of
    :func:`step_residual` (:meth:`~discovery.residuals.Segment.impulse_weights`, zero-padded); the first is
    ``sum ((w_j + w_{j+1}) / 2)^2`` when its white noise comes averaged (``Segment.a_steps_averaged``)."""
    w = seg.impulse_weights()
    padded = np.concatenate([[0.0], w, [0.0]])
    white = 0.5 * (padded[1:] + padded[:-1]) if seg.a_steps_averaged else w
    return float(np.sum(white**2)), float(np.sum(np.diff(padded) ** 2))


def noise_floor(data: FlightData, model_steps: Callable[[int], np.ndarray] | None = None) -> dict:
    """The rms force residual (N) that measurement noise and unlogged disturbances leave after smoothing.

    Returns ``{"floor_N", "floor_axes_N", "floor_upper_N", "white_N2", "differenced_N2", "band_hz",
    "band_top_share", "filtered", "transient_share"}``: the floor over all three axes (vector norm) and per world
    axis, its one-sided 95 % upper bound, the fitted white and differenced-white levels (N^2 per step, per axis,
    averaged over segments weighted by their samples), the power at the top quarter of the band as a share of what
    the fitted shapes predict there (weakest axis), whether that share is below :data:`FILTERED_SHARE`, and the
    share of the Welch segments left out as transients. ``floor_N`` is NaN when no segment is long enough or its
    rate too low to have a band above :data:`BAND_HZ`.

    The floor is the log's stationary noise: a Welch segment whose band holds more than :data:`TRANSIENT_RATIO`
    times the typical segment's power (:func:`_stationary`) holds a force the model does not describe, and is left
    out. A guard grazing a wall on each pass (the second simulator's seed 7894) raised the floor 1.4 times, and a
    0.19 N residual passed as noise; of 75 logs of that simulator, only that one and a survey striking the ground
    had a segment left out. A burst under a velocity's differenced noise, which swamps the band, is not seen.

    Where the residual's noise falls with frequency faster than the fitted shapes allow (a PX4 SITL log's
    velocity, an estimator's output: at the band's top 4 % of the fit's power on its weakest axis, against 69-99 % on
    321 logs of the second simulator, the lowest beside a struck wall), the log's states are filtered, the
    estimator's own errors live below 2 Hz unseen, and the floor is only a lower bound.

    The upper bound is what a residual is judged against (:func:`discovery.unexplained.is_unexplained`): the
    white level shows only where the differenced one has not yet risen, the low end of the band, and where the
    velocity's noise is large it is hardly determined. On a 100 Hz log with 1.5 cm/s of velocity noise and a white
    level of 0.0125 N^2 per step, the level came out 0.010 +- 0.009 N^2 over 40 draws of the noise (zero in some),
    and the floor of the second simulator's clean log at half its residual. The floor's spread is taken from the
    log itself: the larger of Whittle's (:func:`_levels_covariance`) and a grouped jackknife's over its Welch segments
    (:data:`JACKKNIFE_GROUPS` groups, in time order). The jackknife also sees noise the two shapes do not
    describe; Whittle's also holds where a level is fitted at zero, where every jackknife replicate is zero too.

    ``model_steps`` (segment index -> the chosen effects' force over each step,
    :meth:`discovery.fitting.EffectFit.steps`) is taken out of the per-step residual first: a brisk flight's forces
    reach above the band's edge, and measured on what the nominal model leaves, the floor of the second simulator's
    waypoint flights came out 3.7 times the residual a right quadratic drag left and 2.1 times a thrust scale's; on
    what they leave, 0.86 and 0.85 times."""
    floors, weights, whites, differenced, variances, shares, transients = [], [], [], [], [], [], []
    for index, seg in enumerate(data.segments):
        dt = seg.dt
        length = max(64, int(round(_WELCH_S / dt)))
        if seg.n < length:
            continue
        residual = step_residual(seg)
        if model_steps is not None:
            residual = residual - model_steps(index)
        nu, powers = _periodograms(residual, length)
        band = nu >= BAND_HZ * dt
        if band.sum() < 4:
            continue
        stationary = _stationary(powers, band)
        transients.append(float(np.mean(~stationary)))
        powers = powers[stationary]
        gains = np.array(_kernel_gains(seg))
        power = powers.mean(axis=0)[band]
        levels = _axes_levels(nu[band], power, seg.a_steps_averaged)
        floors.append(levels @ gains)
        top = slice(-max(1, int(band.sum()) // 4), None)  # the top quarter of the band: power there against the fit's
        fitted = _design(nu[band], seg.a_steps_averaged)[top] @ levels.T
        expected = fitted.mean(axis=0)  # no noise fitted on an axis (a noise-free log): nothing falls there
        shares.append(float(np.min(np.where(expected > 0, power[top].mean(axis=0) / np.maximum(expected, 1e-300), 1.0))))
        # the spread of the floor (its square, summed over the axes): the larger of Whittle's and the jackknife's
        whittle = sum(float(gains @ _levels_covariance(nu[band], levels[a], seg.a_steps_averaged, len(powers)) @ gains)
                      for a in range(3))
        groups = np.array_split(np.arange(len(powers)), min(JACKKNIFE_GROUPS, len(powers)))
        if len(groups) > 1:
            totals = np.array([np.sum(_axes_levels(nu[band], np.delete(powers, g, axis=0).mean(axis=0)[band],
                                                   seg.a_steps_averaged) @ gains) for g in groups])
            jackknife = (len(groups) - 1) / len(groups) * float(np.sum((totals - totals.mean()) ** 2))
        else:  # one spectrum segment (a stretch of a few seconds): its floor taken as known only to its own size
            jackknife = float(np.sum(floors[-1])) ** 2
        variances.append(max(whittle, jackknife))
        whites.append(levels[:, 0])
        differenced.append(levels[:, 1])
        weights.append(seg.n)
    if not floors:
        nan = float("nan")
        return {"floor_N": nan, "floor_axes_N": [nan] * 3, "floor_upper_N": nan, "white_N2": [nan] * 3,
                "differenced_N2": [nan] * 3, "band_hz": BAND_HZ, "band_top_share": nan, "filtered": False,
                "transient_share": nan}
    w = np.asarray(weights, dtype=float) / float(np.sum(weights))
    axes = np.sqrt(np.asarray(floors).T @ w)
    square = float(np.sum(axes**2))
    spread = float(np.sqrt(np.asarray(variances) @ w**2))
    return {"floor_N": float(np.sqrt(square)), "floor_axes_N": [float(a) for a in axes],
            "floor_upper_N": float(np.sqrt(square + Z_UPPER_95 * spread)),
            "white_N2": [float(x) for x in np.asarray(whites).T @ w],
            "differenced_N2": [float(x) for x in np.asarray(differenced).T @ w], "band_hz": BAND_HZ,
            "band_top_share": float(np.asarray(shares) @ w), "filtered": bool(np.asarray(shares) @ w < FILTERED_SHARE),
            "transient_share": float(np.asarray(transients) @ w)}


def judged_floor(floor: dict) -> float:
    """The level (N) a residual is judged against: the floor's 95 % upper bound (``floor_upper_N`` of
    :func:`noise_floor`), or the floor itself where the bound is missing; NaN when the log has no floor."""
    upper = floor.get("floor_upper_N", float("nan"))
    return float(upper) if np.isfinite(upper) else float(floor.get("floor_N", float("nan")))


def residual_spectrum(data: FlightData, residual: np.ndarray, floor: dict) -> dict | None:
    """Where in time a smoothed residual ``(N, 3)`` (all segments) has more power than the noise predicts.

    The residual's spectrum (Welch, :data:`_SPECTRUM_S` segments, summed over the axes) less the noise's
    after the kernel (``|W(f)|^2 S(f)``) is its excess. Returns ``{"peak_hz", "peak_share", "peak_amplitude_N",
    "slow_share", "excess_rms_N", "resolution_hz"}``: the frequency of the largest excess, the share of the
    excess within two bins of it, the amplitude of a sinusoid with that power, the share below :data:`SLOW_HZ`
    and the excess in rms, or None when no segment is long enough."""
    spectra, weights = [], []
    start = 0
    for seg in data.segments:
        part = residual[start:start + seg.n]
        start += seg.n
        dt = seg.dt
        length = min(int(round(_SPECTRUM_S / dt)), seg.n)
        if length < 16:
            continue
        nu, power = _welch(part, length)
        noise = np.zeros_like(power)
        if np.isfinite(floor.get("floor_N", np.nan)):
            response = np.abs(np.fft.rfft(seg.step_weights(), length)) ** 2
            shaped = 2.0 * (1.0 - np.cos(2 * np.pi * nu))
            white = _white_shape(nu, seg.a_steps_averaged)
            for a in range(3):
                noise[:, a] = response * (floor["white_N2"][a] * white + floor["differenced_N2"][a] * shaped)
        spectra.append((nu / dt, np.clip(power - noise, 0.0, None).sum(axis=1), dt))
        weights.append(seg.n)
    if not spectra:
        return None
    # segments of one log share their rate: put every excess on the first segment's frequency grid
    hz = spectra[0][0]
    excess = np.zeros_like(hz)
    for (f, e, _), n in zip(spectra, weights):
        excess += np.interp(hz, f, e) * n
    excess /= float(np.sum(weights))
    total = float(np.sum(excess))
    if total <= 0:
        return {"peak_hz": None, "peak_share": 0.0, "peak_amplitude_N": 0.0, "slow_share": 0.0, "excess_rms_N": 0.0,
                "resolution_hz": float(hz[1] - hz[0])}
    peak = int(np.argmax(excess[1:]) + 1)
    near = slice(max(1, peak - 2), peak + 3)
    bins = len(hz)
    # each bin's power is a variance share of the residual: mean over the two-sided band = sum over one side / N
    variance = lambda x: float(x) * 2.0 / (2 * (bins - 1))  # noqa: E731
    resolution = float(hz[1] - hz[0])
    refined = _refine_peak(data, residual, float(hz[peak]), resolution)
    return {"peak_hz": round(refined, 4), "peak_share": round(float(np.sum(excess[near])) / total, 3),
            "peak_amplitude_N": round(float(np.sqrt(2.0 * variance(np.sum(excess[near])))), 4),
            "slow_share": round(float(np.sum(excess[hz < SLOW_HZ])) / total, 3),
            "excess_rms_N": round(float(np.sqrt(variance(total))), 4), "resolution_hz": round(float(hz[1] - hz[0]), 4)}
