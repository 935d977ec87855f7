"""Benchmark (not a timed test): every estimator against its Cramér–Rao bound.

    python -m benchmarks.bench_crb [--runs 200] [--only NAME ...] [--json OUT.json]

For each estimator in ``hil/identify/`` the protocol's own excitation is built from the
profile's ``[protocols.X]`` table (read at run time, through the protocol's ``Spec`` and
``excitation``), run on :class:`hil.drives.sim.SimDrive` with ``--runs`` noise seeds,
reduced by the protocol's ``analyse`` (or the estimator it calls), and compared with the
truth of the simulated plant. Reported per parameter: bias (% of the truth; absolute for
an angle whose truth is 0), RMSE / CRB, std / CRB (the efficiency without the bias), runs
and wall time. The bound is ``sqrt(mean over runs of CRB²)``.

Cases: ``white`` switches off every effect the estimator does not model (what remains is
listed per estimator below) and shows efficiency; ``demo`` is the profile's unit with every
effect on and shows bias. Torque-type truths are in the drive's reported-torque units
(``/(1 + torque_constant_error_rel)``).

The bounds (machinery in ``crb_common.py``): white Gaussian torque noise of the plant's
known σ (``torque_noise_nm``; ``load_torque_noise_nm`` for the shaft sensor), never fed back
into the loops, so the measured motion is deterministic and the bound is conditional on it.
``F = JᵀJ/σ²``, ``J = ∂τ_model/∂θ`` over the samples the estimator uses, every nuisance
parameter it fits included, ``CRB = sqrt(diag(F⁻¹))`` (delta method for functions).

- ``stribeck`` (T_c, T_s, v_s, B; elevation profile). Per sample ``τ = L_{s,k} ± F(v_s)``,
  ``F(v) = T_c + (T_s − T_c)·exp(−(v/v_s)²) + B·v`` at each clean speed's measured speed,
  a free load ``L`` per speed and position block (what the estimator's half difference
  cancels), the samples its matched, settled blocks hold. White: Coulomb + viscous +
  Stribeck friction. Also run on a SimDrive with ``exact_torque_hold=False``: the default
  exact-hold step moves the position by ``h·ω − h²·T/(2J)`` per physics step even when
  friction balances ``T``, so the kernel's velocity (which friction sees) runs ``h·T/(2J)``
  (≈ 0.0008 rad/s on the demo unit) above the encoder's rate: a simulator artefact that
  biases T_s and v_s at the slowest steps (see RESULTS.md).
- ``gravity_cable`` (m·g·e, φ, k_cable; elevation profile). Per sample ``τ = a·cos θ +
  b·sin θ + k·θ + c ± F_bin`` with a free ``F`` per position bin (cancelled by the half
  sum), the bins' samples. Hysteresis h: probe samples ``τ = L_bin + c + 2h·exp(−s/s₀)``
  and the settled pass's samples ``τ = L_bin`` (s₀, c and each travel bin's L free). White:
  friction, gravity, cable spring and hysteresis.
- ``cogging`` (amplitude per order, K_t ripple amplitude; elevation profile). Per pass
  ``τ = poly₆(θ) + Σ_n cos/sin(nθ)·(G_n − T̄_p·R_n)`` over the estimator's orders (its
  acceleration correction is known given the motion), amplitudes by the delta method.
  White: friction, cogging, K_t ripple.
- ``torque_constant`` (K_t, reported-torque gain; elevation profile). Per angle
  ``T_sensor = K_a·i + c_a`` (measured current exact) over the settled level samples;
  the gain as errors-in-variables (each level's true reported torque a nuisance, the
  reported torque's own noise included); bound of the mean over angles. White: no K_t
  ripple. ``demo + table``: the cogging protocol's ripple table known (here the truth).
- ``current_loop`` (τ; elevation profile) and ``resonance`` (f_res, f_anti, ζ_res;
  azimuth profile). The estimators use each frequency's torque and position phasors from
  a regression on ``[cos, sin, 1, t]`` per block. With the position exact, the block's
  torque phasor ``T_b = P_b/H(f; θ)`` has covariance ``σ²·[(DᵀD)⁻¹]₂ₓ₂`` (≈ ``2σ²/N`` per
  component); ``F = Σ_b J_bᵀ C_b⁻¹ J_b``, ``J_b = ∂(Re, Im)(P_b/H)/∂θ`` by central
  differences of the estimator's own sampled-data model, with all its parameters free (τ:
  J, B/J; resonance: J, ζ_a, B/J, τ). τ is also shown against the bound of the phases
  alone (a free magnitude per frequency), which is what its fit uses. White: rigid
  (current loop) or two-mass (resonance) axis, friction, the current-loop lag; the
  resonance's white case refines the simulator's physics step (``substeps = 64``): the
  two-mass kernel's f_res and f_anti err by ≈ +0.35 % at its default step (one per
  control period), +0.04 % at 8, +0.005 % at 64 (first order in the step). A diagnostic
  case lengthens the settling per frequency to 0.2 s (the profile's is 0.03 s, under one
  decay time 1/(ζ·2π·f_res) ≈ 39 ms of the resonance); it widens the simulated travel.
- ``inertia_elevation`` (J level, J zenith, ratio; azimuth profile). Each elevation's J
  bound from the J/B/T_c samples (``hil.identify.inertia_friction.cramer_rao_std``: its B,
  T_c and constants free), then ``J(el) = J_z + ΔJ·cos²(el)``. White: rigid axis carrying
  motor + load inertia and the elevation-dependent part, friction.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

from benchmarks import crb_frf, crb_locked, crb_slow
from benchmarks.crb_common import MonteCarlo, bare_firmware, markdown
from hil.profile import load_profile

ELEVATION = "demo_gimbal_elevation"
AZIMUTH = "demo_gimbal_azimuth"
RESONANCE_SUBSTEPS = 64  # the two-mass kernel's f_r error is first order in its step


def _stribeck(runs: int) -> list[MonteCarlo]:
    profile = load_profile(ELEVATION)
    assert profile.plant is not None
    white = crb_slow.stribeck_white(profile.plant)
    bare = bare_firmware(profile)
    return [
        crb_slow.stribeck(
            bare, white, runs, "white, exact_torque_hold=False", exact_torque_hold=False
        ),
        crb_slow.stribeck(bare, white, runs, "white"),
        crb_slow.stribeck(profile, profile.plant, runs, "demo unit"),
        crb_slow.stribeck(profile, profile.plant, runs, "demo unit, ripple and cable loop known",
                          earlier_inputs=True),
    ]


def _gravity_cable(runs: int) -> list[MonteCarlo]:
    profile = load_profile(ELEVATION)
    assert profile.plant is not None
    white = crb_slow.gravity_white(profile.plant)
    bare = bare_firmware(profile)
    return [
        crb_slow.gravity_cable(bare, white, runs, "white"),
        crb_slow.gravity_cable(profile, profile.plant, runs, "demo unit"),
    ]


def _cogging(runs: int) -> list[MonteCarlo]:
    profile = load_profile(ELEVATION)
    assert profile.plant is not None
    white = crb_slow.cogging_white(profile.plant)
    bare = bare_firmware(profile)
    return [
        crb_slow.cogging(bare, white, runs, "white"),
        crb_slow.cogging(profile, profile.plant, runs, "demo unit"),
    ]


def _torque_constant(runs: int) -> list[MonteCarlo]:
    profile = load_profile(ELEVATION)
    assert profile.plant is not None
    white = crb_locked.torque_constant_white(profile.plant)
    bare = bare_firmware(profile)
    return [
        crb_locked.torque_constant(bare, white, runs, "white"),
        crb_locked.torque_constant(profile, profile.plant, runs, "demo unit"),
        crb_locked.torque_constant(
            profile, profile.plant, runs, "demo unit + ripple table", ripple_table=True
        ),
    ]


def _current_loop(runs: int) -> list[MonteCarlo]:
    profile = load_profile(ELEVATION)
    assert profile.plant is not None
    white = crb_frf.current_loop_white(profile.plant)
    lagged = bare_firmware(profile, keep_lag=True)
    return [
        crb_frf.current_loop(lagged, white, runs, "white"),
        crb_frf.current_loop(profile, profile.plant, runs, "demo unit"),
    ]


def _resonance(runs: int) -> list[MonteCarlo]:
    profile = load_profile(AZIMUTH)
    assert profile.plant is not None
    white = crb_frf.resonance_white(profile.plant, substeps=RESONANCE_SUBSTEPS)
    lagged = bare_firmware(profile, keep_lag=True)
    return [
        crb_frf.resonance(lagged, white, runs, f"white (substeps {RESONANCE_SUBSTEPS})"),
        crb_frf.resonance(
            lagged, white, runs, "white, settle_s = 0.2 s (diagnostic)", settle_s=0.2
        ),
        crb_frf.resonance(profile, profile.plant, runs, "demo unit"),
    ]


def _inertia_elevation(runs: int) -> list[MonteCarlo]:
    profile = load_profile(AZIMUTH)
    assert profile.plant is not None
    white = crb_locked.inertia_elevation_white(profile.plant)
    bare = bare_firmware(profile)
    return [
        crb_locked.inertia_elevation(bare, white, runs, "white"),
        crb_locked.inertia_elevation(profile, profile.plant, runs, "demo unit"),
    ]


BENCHMARKS: dict[str, Callable[[int], list[MonteCarlo]]] = {
    "stribeck": _stribeck,
    "gravity_cable": _gravity_cable,
    "cogging": _cogging,
    "torque_constant": _torque_constant,
    "current_loop": _current_loop,
    "resonance": _resonance,
    "inertia_elevation": _inertia_elevation,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--runs", type=int, default=200, help="Monte Carlo runs per case")
    parser.add_argument("--only", nargs="+", choices=sorted(BENCHMARKS), default=None)
    parser.add_argument("--json", default=None, help="also write the rows as JSON here")
    args = parser.parse_args()
    started = time.perf_counter()
    results: list[MonteCarlo] = []
    for name in args.only or list(BENCHMARKS):
        results += BENCHMARKS[name](args.runs)
    print(markdown(results))
    print(f"\n{args.runs} runs per case, {time.perf_counter() - started:.0f} s wall in all")
    if args.json:
        rows = [
            {
                "estimator": r.estimator,
                "case": r.case,
                "failures": r.failures,
                "wall_s": r.wall_s,
                "parameters": r.rows(),
            }
            for r in results
        ]
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"runs": args.runs, "results": rows}, handle, indent=2)


if __name__ == "__main__":
    main()
