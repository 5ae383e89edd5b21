"""Movement-quality metrics: reference values, invariances, derivatives, summary, bad input."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rehabbot.analysis.metrics import (
    finite_differences,
    kinematic_summary,
    ldlj,
    normalized_jerk,
    sparc,
    speed,
)

FS = 100.0
MIN_JERK_SPARC = -1.406  # SPARC of the minimum-jerk speed profile (any duration, amplitude)
MIN_JERK_LDLJ = -math.log(720.0 / 1.875**2)  # -5.322: T^3/v_peak^2 * ∫ v''^2 = 204.8
MIN_JERK_NJ = math.sqrt(360.0)  # 18.97


def gaussian_speed() -> np.ndarray:
    """The published test signal: exp(-5 t^2), t in [-1, 1) at 100 Hz (200 samples)."""
    t = np.arange(-1.0, 1.0, 1.0 / FS)
    return np.exp(-5.0 * t**2)


def min_jerk(t: np.ndarray, start_s: float, duration_s: float, amplitude: float = 1.0):
    """Position and speed of a minimum-jerk movement x(τ) = A(10τ³ − 15τ⁴ + 6τ⁵)."""
    tau = np.clip((t - start_s) / duration_s, 0.0, 1.0)
    x = amplitude * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
    v = amplitude / duration_s * (30 * tau**2 - 60 * tau**3 + 30 * tau**4)
    return x, v


def min_jerk_samples(duration_s: float, fs_hz: float = FS, amplitude: float = 1.0):
    """Sample a movement of duration_s at fs_hz, both end points included."""
    n = round(duration_s * fs_hz) + 1
    t = np.linspace(0.0, duration_s, n)
    return min_jerk(t, 0.0, duration_s, amplitude)


def two_submovements(fs_hz: float = FS):
    """Two 1 s minimum-jerk sub-movements of 0.5 each, the second starting 0.6 s after the first."""
    t = np.arange(round(1.6 * fs_hz) + 1) / fs_hz
    x1, v1 = min_jerk(t, 0.0, 1.0, 0.5)
    x2, v2 = min_jerk(t, 0.6, 1.0, 0.5)
    return x1 + x2, v1 + v2


# --------------------------------------------------------------------------- reference values


def test_sparc_of_gaussian_matches_published_value():
    assert sparc(gaussian_speed(), FS) == pytest.approx(-1.41403, abs=1e-4)


@pytest.mark.parametrize("duration_s", [0.5, 1.0, 1.5, 2.0, 3.0, 4.0])
def test_sparc_of_min_jerk(duration_s):
    _, v = min_jerk_samples(duration_s)
    assert sparc(v, FS) == pytest.approx(-1.41, abs=0.02)
    # -1.4058 when N is just above a power of two, -1.4025 otherwise (zero-padding grid).
    assert sparc(v, FS) == pytest.approx(MIN_JERK_SPARC, abs=5e-3)


def test_ldlj_of_gaussian_matches_published_value():
    value = ldlj(gaussian_speed(), FS)
    assert value == pytest.approx(-5.81636, abs=0.02)
    # T = (N - 1)/fs = 1.99 s here; the published value uses N/fs = 2 s: 3 ln(200/199) apart.
    assert value == pytest.approx(-5.81636 + 3 * math.log(200 / 199), abs=2e-3)


@pytest.mark.parametrize("duration_s", [0.5, 1.0, 2.0, 4.0])
def test_ldlj_of_min_jerk(duration_s):
    _, v = min_jerk_samples(duration_s)
    value = ldlj(v, FS)
    assert -5.33 <= value <= -5.28
    assert value == pytest.approx(MIN_JERK_LDLJ, abs=0.03)


def test_ldlj_converges_to_analytic_min_jerk_value():
    _, v = min_jerk_samples(1.0, fs_hz=1000.0)
    assert ldlj(v, 1000.0) == pytest.approx(MIN_JERK_LDLJ, abs=1e-3)


@pytest.mark.parametrize("duration_s", [0.5, 1.0, 2.0, 4.0])
def test_normalized_jerk_of_min_jerk(duration_s):
    fs = 1000.0
    x, _ = min_jerk_samples(duration_s, fs_hz=fs)
    assert normalized_jerk(x, 1.0 / fs) == pytest.approx(MIN_JERK_NJ, rel=0.02)


def test_normalized_jerk_is_coordinate_free_and_amplitude_invariant():
    fs = 1000.0
    x, _ = min_jerk_samples(1.0, fs_hz=fs)
    direction = np.array([0.3, -0.4, 1.2])
    path = 0.25 * x[:, None] * direction / np.linalg.norm(direction)
    assert normalized_jerk(path, 1.0 / fs) == pytest.approx(normalized_jerk(x, 1.0 / fs))


def test_normalized_jerk_sampling_bias_is_documented_size():
    x, _ = min_jerk_samples(1.0)  # 101 samples at 100 Hz
    value = normalized_jerk(x, 1.0 / FS)
    assert value < MIN_JERK_NJ
    assert value / MIN_JERK_NJ - 1 == pytest.approx(-6 / 100, abs=0.01)


# --------------------------------------------------------------------------- sensitivity


def test_two_submovements_score_worse_than_one():
    _, v_two = two_submovements()
    _, v_one = min_jerk_samples(1.6, amplitude=1.0)
    sparc_two, ldlj_two = sparc(v_two, FS), ldlj(v_two, FS)
    assert sparc_two < sparc(v_one, FS) - 0.2
    assert ldlj_two < ldlj(v_one, FS) - 1.0
    assert sparc_two == pytest.approx(-1.76, abs=0.02)
    assert ldlj_two == pytest.approx(-7.02, abs=0.05)


def test_two_submovements_normalized_jerk_is_worse():
    fs = 1000.0
    x_two, _ = two_submovements(fs)
    x_one, _ = min_jerk_samples(1.6, fs_hz=fs)
    assert normalized_jerk(x_two, 1 / fs) > 1.5 * normalized_jerk(x_one, 1 / fs)


@settings(max_examples=30, deadline=None)
@given(
    n_samples=st.integers(min_value=51, max_value=401),
    amplitude=st.floats(min_value=1e-3, max_value=1e3),
)
def test_sparc_and_ldlj_invariant_to_duration_and_amplitude_for_min_jerk(n_samples, amplitude):
    duration = (n_samples - 1) / FS
    _, v = min_jerk_samples(duration, amplitude=amplitude)
    # Over N = 51..401 samples SPARC stays in [-1.408, -1.392]: only the zero-padding grid moves.
    assert sparc(v, FS) == pytest.approx(-1.41, abs=0.02)
    assert ldlj(v, FS) == pytest.approx(MIN_JERK_LDLJ, abs=0.03)


@settings(max_examples=30, deadline=None)
@given(scale=st.floats(min_value=1e-6, max_value=1e6))
def test_sparc_and_ldlj_amplitude_invariant_on_any_profile(scale):
    _, v = two_submovements()
    assert sparc(scale * v, FS) == pytest.approx(sparc(v, FS), abs=1e-9)
    assert ldlj(scale * v, FS) == pytest.approx(ldlj(v, FS), abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    n_samples=st.integers(min_value=51, max_value=401),
    freq_hz=st.floats(min_value=5.0, max_value=9.5),
    rel_amplitude=st.floats(min_value=0.1, max_value=0.3),
    phase=st.floats(min_value=0.0, max_value=2 * math.pi),
)
def test_high_frequency_tremor_makes_sparc_worse(n_samples, freq_hz, rel_amplitude, phase):
    _, v = min_jerk_samples((n_samples - 1) / FS)
    t = np.arange(v.size) / FS
    tremor = np.abs(v + rel_amplitude * v.max() * np.sin(2 * np.pi * freq_hz * t + phase))
    assert sparc(tremor, FS) < sparc(v, FS) - 0.1
    assert ldlj(tremor, FS) < ldlj(v, FS) - 0.1


@pytest.mark.parametrize("seed", range(5))
def test_white_noise_makes_sparc_and_ldlj_worse(seed):
    _, v = min_jerk_samples(1.0)
    rng = np.random.default_rng(seed)
    noisy = np.abs(v + 0.5 * v.max() * rng.standard_normal(v.size))
    assert sparc(noisy, FS) < sparc(v, FS) - 0.3
    assert ldlj(noisy, FS) < ldlj(v, FS) - 3.0


@pytest.mark.parametrize("seed", range(5))
def test_sparc_ignores_noise_below_amplitude_threshold_unlike_ldlj(seed):
    # 2 % white noise stays under the 5 % spectral threshold: SPARC barely moves, LDLJ plunges.
    _, v = min_jerk_samples(1.0)
    rng = np.random.default_rng(seed)
    noisy = np.abs(v + 0.02 * v.max() * rng.standard_normal(v.size))
    assert sparc(noisy, FS) == pytest.approx(sparc(v, FS), abs=0.02)
    assert ldlj(noisy, FS) < ldlj(v, FS) - 3.0


def sparc_reference(movement, fs, padlevel, fc, amp_th):
    """Independent transcription of the published algorithm: full FFT, normalised by its max."""
    nfft = int(2 ** (np.ceil(np.log2(len(movement))) + padlevel))
    f = np.arange(0, fs, fs / nfft)
    mf = np.abs(np.fft.fft(movement, nfft))
    mf = mf / mf.max()
    f_sel, mf_sel = f[f <= fc], mf[f <= fc]
    inx = np.nonzero(mf_sel >= amp_th)[0]
    f_sel, mf_sel = f_sel[inx[0] : inx[-1] + 1], mf_sel[inx[0] : inx[-1] + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        df = np.diff(f_sel) / (f_sel[-1] - f_sel[0])
    return -np.sum(np.sqrt(df**2 + np.diff(mf_sel) ** 2))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    n_samples=st.integers(min_value=4, max_value=300),
    padlevel=st.integers(min_value=0, max_value=6),
    fc_hz=st.floats(min_value=2.0, max_value=49.0),
    amp_threshold=st.floats(min_value=0.01, max_value=0.5),
)
def test_sparc_matches_published_algorithm(seed, n_samples, padlevel, fc_hz, amp_threshold):
    rng = np.random.default_rng(seed)
    v = np.abs(np.cumsum(rng.standard_normal(n_samples))) + rng.uniform(0.0, 1.0, n_samples)
    expected = sparc_reference(v, FS, padlevel, fc_hz, amp_threshold)
    if not np.isfinite(expected) or expected == 0.0:
        # A band of one bin: the reference divides by zero, the library names the cause.
        with pytest.raises(ValueError, match=r"padlevel|fc_hz"):
            sparc(v, FS, padlevel, fc_hz, amp_threshold)
        return
    assert sparc(v, FS, padlevel, fc_hz, amp_threshold) == pytest.approx(expected, rel=1e-9)


def test_sparc_band_is_capped_at_fc():
    # A 15 Hz ripple lies outside the default 10 Hz band and only shows up when fc_hz = 20.
    _, v = min_jerk_samples(2.0)
    t = np.arange(v.size) / FS
    ripple = v + 0.2 * v.max() * (1 + np.sin(2 * np.pi * 15.0 * t))
    assert sparc(ripple, FS) == pytest.approx(sparc(v, FS), abs=0.02)
    assert sparc(ripple, FS, fc_hz=20.0) < sparc(v, FS) - 0.5


# --------------------------------------------------------------------------- derivatives


@settings(max_examples=40, deadline=None)
@given(
    coeffs=st.lists(st.floats(min_value=-10, max_value=10), min_size=4, max_size=4),
    dt=st.sampled_from([0.001, 0.01, 0.05]),
    n=st.integers(min_value=8, max_value=200),
)
def test_finite_differences_exact_on_polynomials(coeffs, dt, n):
    c0, c1, c2, c3 = coeffs
    t = np.arange(n) * dt
    quadratic = c0 + c1 * t + c2 * t**2
    cubic = c3 * t**3

    def roundoff(x, order):  # a few ulps of the samples, amplified by 1/dt**order
        return 1e-12 * (1.0 + np.abs(x).max()) / dt**order

    v, a, _ = finite_differences(quadratic, dt)
    np.testing.assert_allclose(v, c1 + 2 * c2 * t, rtol=0, atol=roundoff(quadratic, 1))
    np.testing.assert_allclose(a, 2 * c2, rtol=0, atol=roundoff(quadratic, 2))
    v, a, j = finite_differences(cubic, dt)
    # Inside, the central difference of t^3 is 3t^2 + dt^2; its next passes are exact.
    np.testing.assert_allclose(v[1:-1], c3 * (3 * t[1:-1] ** 2 + dt**2), rtol=0,
                               atol=roundoff(cubic, 1))
    np.testing.assert_allclose(a[2:-2], 6 * c3 * t[2:-2], rtol=0, atol=roundoff(cubic, 2))
    np.testing.assert_allclose(j[3:-3], 6 * c3, rtol=0, atol=roundoff(cubic, 3))


def test_finite_differences_known_polynomials():
    dt = 0.01
    t = np.arange(0.0, 1.0 + dt / 2, dt)
    v, a, _ = finite_differences(t**2, dt)
    np.testing.assert_allclose(v, 2 * t, atol=1e-10)  # edges too: edge_order=2 is exact here
    np.testing.assert_allclose(a, 2.0, atol=1e-8)
    _, _, j = finite_differences(t**3, dt)
    np.testing.assert_allclose(j[3:-3], 6.0, atol=1e-6)


def test_finite_differences_column_wise_and_shapes():
    dt = 0.02
    t = np.arange(50) * dt
    pos = np.column_stack([t**2, 3 * t, np.sin(t)])
    v, a, j = finite_differences(pos, dt)
    assert v.shape == a.shape == j.shape == pos.shape
    for k in range(3):
        vk, ak, jk = finite_differences(pos[:, k], dt)
        np.testing.assert_array_equal(v[:, k], vk)
        np.testing.assert_array_equal(a[:, k], ak)
        np.testing.assert_array_equal(j[:, k], jk)
    np.testing.assert_allclose(v[:, 1], 3.0)


def test_speed_is_norm_of_velocity():
    dt = 0.01
    t = np.arange(100) * dt
    circle = np.column_stack([np.cos(2 * t), np.sin(2 * t), 0.5 * t])
    s = speed(circle, dt)
    assert s.shape == (100,)
    np.testing.assert_allclose(s[1:-1], math.sqrt(4 + 0.25), rtol=1e-3)
    line = -3.0 * t
    np.testing.assert_allclose(speed(line, dt), 3.0)


# --------------------------------------------------------------------------- summary


def sine_joints(dt=0.002, duration=3.0):
    t = np.arange(0.0, duration, dt)
    amplitudes = np.array([0.3, 0.8, 1.2])
    omegas = np.array([2 * np.pi * 0.5, 2 * np.pi * 0.25, 2 * np.pi * 0.7])
    q = amplitudes * np.sin(np.outer(t, omegas))
    return t, q, amplitudes, omegas


def test_kinematic_summary_on_sine_joints():
    dt = 0.002
    _, q, amplitudes, omegas = sine_joints(dt)
    summary = kinematic_summary(q, dt)
    json.dumps(summary)  # JSON-ready as is
    expected_speed = amplitudes * omegas
    assert summary["peak_joint_speed_per_joint_rad_s"] == pytest.approx(
        list(expected_speed), rel=0.02
    )
    assert summary["peak_joint_speed_rad_s"] == pytest.approx(expected_speed.max(), rel=0.02)
    assert summary["peak_joint_acceleration_rad_s2"] == pytest.approx(
        (amplitudes * omegas**2).max(), rel=0.02
    )
    assert summary["peak_joint_jerk_rad_s3"] == pytest.approx(
        (amplitudes * omegas**3).max(), rel=0.02
    )
    # Over whole periods the mean of sin^2 is 1/2; joint 2 covers 3 s * 0.7 Hz = 2.1 periods.
    rms = math.sqrt(np.mean((amplitudes * omegas**2) ** 2 / 2))
    assert summary["rms_joint_acceleration_rad_s2"] == pytest.approx(rms, rel=0.05)
    assert summary["smoothness_signal"] == "joint_speed"
    assert isinstance(summary["sparc"], float) and summary["sparc"] < 0
    assert isinstance(summary["ldlj"], float) and summary["ldlj"] < 0
    assert isinstance(summary["normalized_jerk"], float) and summary["normalized_jerk"] > 0
    assert summary["peak_tool_speed_m_s"] is None
    assert summary["peak_torque_nm"] is None
    assert summary["peak_torque_per_joint_nm"] is None
    assert summary["n_samples"] == q.shape[0]
    assert summary["duration_s"] == pytest.approx((q.shape[0] - 1) * dt)


def test_kinematic_summary_smoothness_of_tool_and_torques():
    fs = 500.0
    x, _ = min_jerk_samples(1.0, fs_hz=fs, amplitude=0.3)
    tool = np.column_stack([0.4 + x, np.full_like(x, 0.1), np.full_like(x, 0.9)])
    joints = np.column_stack([x, -0.5 * x])
    torque = np.array([[1.0, -4.0], [-2.5, 3.0], [0.0, 0.5]])
    summary = kinematic_summary(joints, 1 / fs, tool_m=tool, torque_nm=torque)
    json.dumps(summary)
    assert summary["smoothness_signal"] == "tool_speed"
    assert summary["sparc"] == pytest.approx(MIN_JERK_SPARC, abs=5e-3)
    assert summary["sparc"] == pytest.approx(sparc(speed(tool, 1 / fs), fs))
    assert summary["ldlj"] == pytest.approx(MIN_JERK_LDLJ, abs=0.02)
    assert summary["normalized_jerk"] == pytest.approx(MIN_JERK_NJ, rel=0.02)
    assert summary["peak_tool_speed_m_s"] == pytest.approx(1.875 * 0.3, rel=1e-3)
    assert summary["peak_torque_per_joint_nm"] == [2.5, 4.0]
    assert summary["peak_torque_nm"] == 4.0
    assert summary["peak_joint_speed_per_joint_rad_s"] == pytest.approx(
        [1.875 * 0.3, 0.5 * 1.875 * 0.3], rel=1e-3
    )


def test_kinematic_summary_joint_smoothness_matches_functions():
    dt = 0.01
    x, _ = min_jerk_samples(2.0)
    joints = np.column_stack([x, 2 * x])
    summary = kinematic_summary(joints, dt)
    profile = speed(joints, dt)
    assert summary["sparc"] == pytest.approx(sparc(profile, FS))
    assert summary["ldlj"] == pytest.approx(ldlj(profile, FS))
    assert summary["normalized_jerk"] == pytest.approx(normalized_jerk(joints, dt))


def test_motionless_trajectory_gives_none_smoothness():
    q = np.tile([0.1, -0.2, 0.3], (50, 1))
    summary = kinematic_summary(q, 0.01, tool_m=np.zeros((50, 3)), torque_nm=np.zeros((50, 3)))
    json.dumps(summary)
    assert summary["sparc"] is None
    assert summary["ldlj"] is None
    assert summary["normalized_jerk"] is None
    assert summary["peak_joint_speed_rad_s"] == 0.0
    assert summary["peak_tool_speed_m_s"] == 0.0
    assert summary["peak_torque_nm"] == 0.0
    assert math.isnan(sparc(np.zeros(50), FS))
    assert math.isnan(ldlj(np.zeros(50), FS))
    assert math.isnan(normalized_jerk(np.zeros((50, 2)), 0.01))


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_values_are_rejected(bad):
    x, v = min_jerk_samples(1.0)
    x[7], v[7] = bad, bad
    for call in (
        lambda: finite_differences(x, 0.01),
        lambda: speed(x, 0.01),
        lambda: normalized_jerk(x, 0.01),
    ):
        with pytest.raises(ValueError, match=r"position\[7\]"):
            call()
    for call in (lambda: sparc(v, FS), lambda: ldlj(v, FS)):
        with pytest.raises(ValueError, match=r"speed\[7\]"):
            call()
    q = np.zeros((20, 2))
    q[3, 1] = bad
    with pytest.raises(ValueError, match=r"joint_rad\[\(3, 1\)\]"):
        kinematic_summary(q, 0.01)
    tool = np.zeros((20, 3))
    tool[4, 2] = bad
    with pytest.raises(ValueError, match=r"tool_m\[\(4, 2\)\]"):
        kinematic_summary(np.zeros((20, 2)), 0.01, tool_m=tool)
    torque = np.zeros((5, 2))
    torque[0, 0] = bad
    with pytest.raises(ValueError, match=r"torque_nm\[\(0, 0\)\]"):
        kinematic_summary(np.zeros((20, 2)), 0.01, torque_nm=torque)


@pytest.mark.parametrize("dt", [0.0, -0.01, math.nan, math.inf, "fast", None, True])
def test_bad_sampling_interval_is_rejected(dt):
    x = np.linspace(0.0, 1.0, 20)
    for call in (
        lambda: finite_differences(x, dt),
        lambda: speed(x, dt),
        lambda: normalized_jerk(x, dt),
        lambda: kinematic_summary(x[:, None], dt),
    ):
        with pytest.raises(ValueError, match="dt_s"):
            call()
    for call in (lambda: sparc(x, dt), lambda: ldlj(x, dt)):
        with pytest.raises(ValueError, match="fs_hz"):
            call()


@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_too_few_samples_are_rejected(n):
    with pytest.raises(ValueError, match=f"got {n}"):
        finite_differences(np.zeros(n), 0.01)
    with pytest.raises(ValueError, match=f"got {n}"):
        sparc(np.ones(n), FS)
    with pytest.raises(ValueError, match=f"got {n}"):
        ldlj(np.ones(n), FS)
    with pytest.raises(ValueError, match=f"got {n}"):
        kinematic_summary(np.zeros((n, 2)), 0.01)


def test_wrong_shapes_are_rejected():
    with pytest.raises(ValueError, match=r"position must be 1-D or 2-D, got shape \(4, 2, 2\)"):
        finite_differences(np.zeros((4, 2, 2)), 0.01)
    with pytest.raises(ValueError, match=r"speed must be 1-D, got shape \(10, 3\)"):
        sparc(np.ones((10, 3)), FS)
    with pytest.raises(ValueError, match=r"joint_rad must be 2-D, got shape \(10,\)"):
        kinematic_summary(np.zeros(10), 0.01)
    with pytest.raises(ValueError, match=r"tool_m must have shape \(10, d\).*got \(9, 3\)"):
        kinematic_summary(np.zeros((10, 2)), 0.01, tool_m=np.zeros((9, 3)))
    with pytest.raises(ValueError, match=r"torque_nm must have shape \(T', 2\).*got \(10, 3\)"):
        kinematic_summary(np.zeros((10, 2)), 0.01, torque_nm=np.zeros((10, 3)))
    with pytest.raises(ValueError, match="position must be a numeric array"):
        finite_differences(["a", "b", "c", "d"], 0.01)


def test_bad_sparc_parameters_are_rejected():
    _, v = min_jerk_samples(1.0)
    with pytest.raises(ValueError, match=r"speed\[\d+\] = -"):
        sparc(v - 0.1, FS)
    with pytest.raises(ValueError, match=r"speed\[\d+\] = -"):
        ldlj(-v, FS)
    for fc in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="fc_hz"):
            sparc(v, FS, fc_hz=fc)
    for pad in (-1, 17, 2.5, True):
        with pytest.raises(ValueError, match="padlevel"):
            sparc(v, FS, padlevel=pad)
    for threshold in (0.0, 1.0, -0.1, math.nan, "x"):
        with pytest.raises(ValueError, match="amp_threshold"):
            sparc(v, FS, amp_threshold=threshold)
    with pytest.raises(ValueError, match=r"fc_hz = 0\.01 is below the frequency resolution"):
        sparc(v, FS, padlevel=0, fc_hz=0.01)


def test_import_prints_nothing_and_needs_no_scipy():
    probe = (
        "import sys; import rehabbot.analysis.metrics; "
        "bad = [m for m in ('scipy', 'matplotlib') if m in sys.modules]; "
        "print('LOADED:' + ','.join(bad), file=sys.stderr)"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            check=True)
    assert result.stdout == ""
    assert result.stderr.strip() == "LOADED:"
