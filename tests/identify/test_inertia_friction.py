"""J, B, T_c by orthogonal correlation: the article's worked example, exactness, uncertainty."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.errors import IdentificationError
from hil.identify.inertia_friction import _jackknife, identify_inertia_friction, jackknife_dof
from hil.identify.sine_run import analyse_sine_run, band_noise_rms_nm, orthogonal_components
from hil.recording import Recording
from tests.helpers import sine_model_recording

ARTICLE = {"inertia": 0.0036, "viscous": 0.005, "coulomb": 0.020}


@pytest.mark.parametrize(
    ("amplitude", "c_expected", "s_expected"), [(0.5, 0.02262, 0.02796), (1.0, 0.04524, 0.03046)]
)
def test_article_worked_example_to_five_decimals(
    amplitude: float, c_expected: float, s_expected: float
) -> None:
    rec = sine_model_recording(
        **ARTICLE, amplitude=amplitude, frequency_hz=2.0, periods=10, fs_hz=4000.0
    )
    c, s = orthogonal_components(rec.effort, time_s=rec.time_s, frequency_hz=2.0)
    assert round(c, 5) == c_expected
    assert round(s, 5) == s_expected


def test_noise_free_model_is_recovered_exactly() -> None:
    runs = [
        analyse_sine_run(
            sine_model_recording(
                **ARTICLE, amplitude=a, frequency_hz=2.0, periods=10, fs_hz=4000.0
            ),
            frequency_hz=2.0,
            settle_periods=2,
            hold_samples=0.0,
        )
        for a in (0.5, 1.0, 1.5)
    ]
    result = identify_inertia_friction(runs)
    assert result.inertia.value == pytest.approx(0.0036, rel=1e-4)
    assert result.viscous.value == pytest.approx(0.005, rel=1e-3)
    assert result.coulomb.value == pytest.approx(0.020, rel=1e-4)
    assert result.fit_pct > 99.0


def test_reported_uncertainty_matches_the_scatter_and_the_cramer_rao_bound() -> None:
    """Over repeated noisy experiments the spread of J, B, T_c equals the reported standard
    uncertainty (within sampling error) and is close to the Cramér–Rao bound."""
    noise = 0.004
    values, u, crb = [], [], []
    for seed in range(40):
        runs = [
            analyse_sine_run(
                sine_model_recording(
                    **ARTICLE,
                    amplitude=a,
                    frequency_hz=2.0,
                    periods=10,
                    fs_hz=2000.0,
                    noise_nm=noise,
                    seed=100 * seed + i,
                ),
                frequency_hz=2.0,
                settle_periods=2,
                hold_samples=0.0,
            )
            for i, a in enumerate((0.5, 1.0))
        ]
        r = identify_inertia_friction(runs)
        values.append([r.inertia.value, r.viscous.value, r.coulomb.value])
        u.append([e.standard_uncertainty for e in (r.inertia, r.viscous, r.coulomb)])
        crb.append([e.cramer_rao_std for e in (r.inertia, r.viscous, r.coulomb)])
    spread = np.std(values, axis=0, ddof=1)
    truth = np.array([ARTICLE["inertia"], ARTICLE["viscous"], ARTICLE["coulomb"]])
    assert np.all(np.abs(np.mean(values, axis=0) - truth) < 3 * spread / math.sqrt(40))
    ratio_u = spread / np.mean(u, axis=0)
    assert np.all((ratio_u > 0.7) & (ratio_u < 1.4)), ratio_u
    efficiency = spread / np.mean(crb, axis=0)
    # J uses all the information there is; B and T_c use only the fundamental (the article's
    # method), leaving the Coulomb term's odd harmonics unused: above the bound, never below
    assert 0.8 < efficiency[0] < 1.25, efficiency
    assert np.all(efficiency[1:] > 0.8), efficiency


def test_single_amplitude_is_refused() -> None:
    run = analyse_sine_run(
        sine_model_recording(**ARTICLE, amplitude=0.5, frequency_hz=2.0, periods=6, fs_hz=2000.0),
        frequency_hz=2.0,
        settle_periods=2,
        hold_samples=0.0,
    )
    with pytest.raises(IdentificationError, match="two or more amplitudes"):
        identify_inertia_friction([run])
    with pytest.raises(IdentificationError, match="too close"):
        identify_inertia_friction([run, run])


def test_too_few_periods_is_refused() -> None:
    rec = sine_model_recording(**ARTICLE, amplitude=0.5, frequency_hz=2.0, periods=3, fs_hz=2000.0)
    with pytest.raises(IdentificationError, match="whole periods"):
        analyse_sine_run(rec, frequency_hz=2.0, settle_periods=2, hold_samples=0.0)


def test_the_stated_bound_takes_the_noise_where_the_regressors_are() -> None:
    """High-frequency torque (a velocity loop's response to quantisation) raises the
    non-periodic RMS but not the bound of a fit whose regressors live at the sine's first
    harmonics: the stated bound follows the low band's σ (2 mN·m here), not the RMS."""
    sigma, fs = 0.002, 4000.0
    recording = sine_model_recording(**ARTICLE, amplitude=0.5, frequency_hz=2.0, periods=8,
                                     fs_hz=fs, noise_nm=sigma, seed=3)
    chatter = 0.006 * np.diff(np.random.default_rng(4).normal(size=len(recording.time_s) + 1))
    runs = [
        analyse_sine_run(recording, frequency_hz=2.0, settle_periods=1, hold_samples=0.0),
        analyse_sine_run(
            Recording(columns={**recording.columns, "torque_nm": 2 * recording.effort + chatter},
                      source="synthetic"),
            frequency_hz=2.0, settle_periods=1, hold_samples=0.0),
    ]
    assert runs[1].noise_rms_nm > 3 * sigma  # the differenced noise: its power is high up
    assert band_noise_rms_nm(runs[0], harmonics=25) == pytest.approx(sigma, rel=0.08)
    assert band_noise_rms_nm(runs[1], harmonics=25) == pytest.approx(2 * sigma, rel=0.08)


def test_the_jackknife_states_the_degrees_of_freedom_its_variance_has() -> None:
    """Ten periods at two amplitudes (5 each, a regressor twice as large in the second):
    the delete-one-period jackknife's variance of that regressor's coefficient scatters as a
    χ² of the Satterthwaite degrees of freedom, not of 9. Measured from 4000 draws of white
    noise (the scatter of u²: ν = 2·E[u²]²/var u²)."""
    rng = np.random.default_rng(3)
    samples = 40
    phase = np.linspace(0, 2 * math.pi, samples, endpoint=False)
    designs = [np.column_stack([scale * np.cos(phase), scale * np.sin(phase), np.ones(samples)])
               for scale in (1.0,) * 5 + (2.0,) * 5]
    normals = [x.T @ x for x in designs]
    total = np.sum(normals, axis=0)
    stated = jackknife_dof(total, normals, size=3)
    u_sq = []
    for _ in range(4000):
        blocks = [(n, x.T @ rng.normal(0.0, 1.0, samples)) for n, x in zip(normals, designs,
                                                                             strict=True)]
        _, u, _ = _jackknife(blocks)
        u_sq.append(u**2)
    u_sq_arr = np.array(u_sq)
    measured = 2 * u_sq_arr.mean(axis=0) ** 2 / u_sq_arr.var(axis=0, ddof=1)
    # ν from 4000 draws: relative sd ≈ √(2/4000 · (1 + ν·kurtosis)) ≈ 7 % here
    assert stated[0] == pytest.approx(9 * 25**2 / (10 * (5 * 16 + 5)), rel=1e-6)  # 6.6
    assert stated[2] == pytest.approx(9.0)  # the constant: equal blocks
    assert measured[:2] == pytest.approx(stated[:2], rel=0.2)
    assert measured[2] == pytest.approx(9.0, rel=0.2)
