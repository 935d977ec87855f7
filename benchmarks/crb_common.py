"""Shared machinery of ``bench_crb.py``: plants, Fisher information, Monte Carlo summary.

Every bound here is the Cramér–Rao bound *conditional on the measured motion*: the only
random quantity is the white noise the simulator adds to a measured torque
(``torque_noise_nm`` on the drive's reported torque, ``load_torque_noise_nm`` on the
locked-rotor shaft sensor; both are drawn outside the kernel's loops and never fed back,
see ``plant_sim/kernel.py``: ``out_torque[k] = torque_cmd + torque_noise[k]``), so the
measured positions are deterministic given the excitation and the likelihood of the torque
samples is Gaussian with known variance. For a model ``τ = m(θ; q, q̇, q̈)`` the Fisher
information is ``F = JᵀJ/σ²`` with ``J = ∂m/∂θ`` over the samples the estimator uses, with
every nuisance parameter the estimator fits as a column of ``J``; the bound on parameter
``i`` is ``sqrt((F⁻¹)ᵢᵢ)`` and on a function ``g(θ)`` ``sqrt(∇gᵀF⁻¹∇g)``.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from hil.drives.sim import SimDrive
from hil.identify.current_loop import TREND_ORDER, block_phasors
from hil.motion import Limits
from hil.profile import UnitProfile
from plant_sim.firmware import Firmware
from plant_sim.params import PlantParams

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def bare_plant(plant: PlantParams) -> PlantParams:
    """``plant`` with every effect beyond ``J·α + B·ω + T_c·sgn(ω)`` and the white torque
    noise switched off (ideal encoder, exact K_t, rigid; :func:`bare_firmware` takes the
    velocity filter and the current-loop lag out of the drive)."""
    return plant.with_changes(
        static_friction_nm=0.0,
        coulomb_neg_nm=None,
        viscous_neg_nm_s_rad=None,
        torque_offset_nm=0.0,
        load_inertia_kg_m2=0.0,
        shaft_stiffness_nm_rad=0.0,
        shaft_damping_nm_s_rad=0.0,
        cogging=(),
        kt_ripple=(),
        gravity_mge_nm=0.0,
        cable_stiffness_nm_rad=0.0,
        cable_hysteresis_nm=0.0,
        encoder_counts_per_rev=0,
        torque_constant_error_rel=0.0,
        inertia_elevation_kg_m2=0.0,
    )


def bare_firmware(profile: UnitProfile, *, keep_lag: bool = False) -> UnitProfile:
    """``profile`` with its firmware's velocity filter (and, unless ``keep_lag``, the
    current-loop lag) off: the drive of a "white" case."""
    firmware = profile.firmware.with_changes(velocity_filter_hz=0.0)
    if not keep_lag:
        firmware = firmware.with_changes(current_loop_time_constant_s=0.0)
    return dataclasses.replace(profile, firmware=firmware)


def sim_drive(
    plant: PlantParams, *, firmware: Firmware, limits: Limits, fs_hz: float, seed: int,
    exact_torque_hold: bool = True,
) -> SimDrive:
    """An enabled :class:`SimDrive` (``exact_torque_hold``: its default, see the Stribeck case
    in ``bench_crb.py`` for why one case turns it off)."""
    drive = SimDrive(
        plant, firmware=firmware, limits=limits, fs_hz=fs_hz, seed=seed,
        exact_torque_hold=exact_torque_hold,
    )
    drive.enable()
    return drive


def bound(information: FloatArray, gradients: FloatArray) -> FloatArray:
    """``sqrt(diag(G F⁻¹ Gᵀ))`` for the rows of ``gradients`` (one per reported quantity)."""
    covariance = np.linalg.inv(information)
    g = np.atleast_2d(gradients)
    return np.asarray(np.sqrt(np.einsum("ij,jk,ik->i", g, covariance, g)), dtype=np.float64)


def linear_information(jacobian: FloatArray, sigma: float) -> FloatArray:
    """``JᵀJ/σ²`` of a model whose samples have white noise ``sigma``."""
    return np.asarray(jacobian.T @ jacobian / sigma**2, dtype=np.float64)


def central_jacobian(
    model: Callable[[FloatArray], FloatArray], theta: FloatArray, steps: FloatArray
) -> FloatArray:
    """Central finite differences of a vector-valued ``model`` (columns: parameters)."""
    columns = []
    for i, h in enumerate(steps):
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        columns.append((model(up) - model(down)) / (2 * h))
    return np.column_stack(columns)


@dataclass(frozen=True, slots=True, kw_only=True)
class FrfBlocks:
    """What one stepped-sine frequency gives the Fisher information: per block the measured
    position phasor ``P_b`` (exact: no noise on position) and the covariance of the torque
    phasor ``T_b = c − j·s`` from the block's regression ``[cos, sin, 1, t]`` (the estimator's
    design, :func:`hil.identify.current_loop.block_phasors`)."""

    frequency_hz: float
    position: ComplexArray
    covariance: FloatArray  # (blocks, 2, 2): cov of (Re T_b, Im T_b)


def frf_blocks(
    time_s: FloatArray,
    position_rad: FloatArray,
    *,
    frequency_hz: float,
    fs_hz: float,
    blocks: int,
    sigma: float,
) -> FrfBlocks:
    """Block phasors of position and torque-noise covariances, cut as
    :func:`hil.identify.current_loop.analyse_frequency` and ``resonance.frf_point`` cut."""
    periods = math.floor((time_s[-1] - time_s[0] + 1.0 / fs_hz) * frequency_hz + 1e-6)
    blocks = min(blocks, periods)
    omega = 2 * math.pi * frequency_hz
    per_block = periods // blocks
    edges = np.searchsorted(
        time_s - time_s[0], np.arange(blocks + 1) * per_block / frequency_hz - 0.5 / fs_hz
    )
    phasors, covariances = [], []
    flip = np.diag([1.0, -1.0])  # (c, s) → (Re, Im) of c − j·s
    for a, b in itertools.pairwise(edges):
        t = time_s[a:b]
        phasors.append(block_phasors(t, [position_rad[a:b]], omega=omega)[0])
        centred = t - t.mean()
        scale = max(float(np.ptp(centred)), 1e-12)
        columns = [np.cos(omega * t), np.sin(omega * t)]
        columns += [(centred / scale) ** p for p in range(TREND_ORDER + 1)]
        design = np.column_stack(columns)
        cs = sigma**2 * np.linalg.inv(design.T @ design)[:2, :2]
        covariances.append(flip @ cs @ flip)
    return FrfBlocks(
        frequency_hz=frequency_hz,
        position=np.asarray(phasors, dtype=np.complex128),
        covariance=np.asarray(covariances),
    )


def frf_information(
    points: Sequence[FrfBlocks],
    response: Callable[[FloatArray], ComplexArray],
    theta: FloatArray,
    steps: FloatArray,
) -> FloatArray:
    """Fisher information of ``theta`` from the torque phasors ``T_b = P_b / H(f; θ)`` of every
    block, ``H = response(θ)`` at the points' frequencies: ``Σ_b J_bᵀ C_b⁻¹ J_b`` with
    ``J_b = ∂(Re, Im)(P_b/H)/∂θ`` (``P_b`` measured exactly, white torque noise)."""

    def stacked(x: FloatArray) -> FloatArray:
        h = response(x)
        parts = [p.position / h[k] for k, p in enumerate(points)]
        z = np.concatenate(parts)
        return np.concatenate([z.real, z.imag])

    jac = central_jacobian(stacked, theta, steps)
    n = jac.shape[0] // 2
    re, im = jac[:n], jac[n:]
    cov = np.concatenate([p.covariance for p in points])
    info = np.linalg.inv(cov)  # (n, 2, 2)
    pair = np.stack([re, im], axis=1)  # (n, 2, params)
    return np.asarray(np.einsum("nip,nij,njq->pq", pair, info, pair), dtype=np.float64)


@dataclass(frozen=True, slots=True, kw_only=True)
class Parameter:
    """A reported quantity: its truth and whether bias is shown relative (%) or absolute."""

    name: str
    truth: float
    relative: bool = True
    unit: str = ""


@dataclass(slots=True)
class MonteCarlo:
    """Estimates and per-run bounds of one estimator under one case."""

    estimator: str
    case: str
    parameters: tuple[Parameter, ...]
    estimates: list[FloatArray] = field(default_factory=list)
    bounds: list[FloatArray] = field(default_factory=list)
    failures: int = 0
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)

    def add(self, estimate: Sequence[float], crb: Sequence[float]) -> None:
        self.estimates.append(np.asarray(estimate, dtype=np.float64))
        self.bounds.append(np.asarray(crb, dtype=np.float64))

    def rows(self) -> list[dict[str, float | str | int]]:
        """Per parameter: bias (% of truth, or absolute), RMSE, bound, RMSE/CRB. The bound
        is ``sqrt(mean(CRB²))`` over the runs (the conditional bounds differ a little with
        the motion; the mean squared bound is what the mean squared error compares to).
        Runs in which the estimator failed or missed a parameter (NaN) are left out and
        counted."""
        est = np.array(self.estimates)
        crb = np.array(self.bounds)
        out: list[dict[str, float | str | int]] = []
        for i, p in enumerate(self.parameters):
            ok = np.isfinite(est[:, i]) & np.isfinite(crb[:, i])
            if not ok.any():
                out.append(
                    {
                        "parameter": p.name,
                        "bias": math.nan,
                        "bias_unit": "",
                        "rmse": math.nan,
                        "crb": math.nan,
                        "rmse_over_crb": math.nan,
                        "std_over_crb": math.nan,
                        "runs": 0,
                    }
                )
                continue
            err = est[ok, i] - p.truth
            rmse = float(np.sqrt(np.mean(err**2)))
            b = float(np.sqrt(np.mean(crb[ok, i] ** 2)))
            bias = float(err.mean())
            out.append(
                {
                    "parameter": p.name,
                    "bias": 100 * bias / p.truth if p.relative else bias,
                    "bias_unit": "%" if p.relative else p.unit,
                    "rmse": rmse,
                    "crb": b,
                    "rmse_over_crb": rmse / b,
                    "std_over_crb": float(err.std() / b),
                    "runs": int(ok.sum()),
                }
            )
        return out


def monte_carlo(
    result: MonteCarlo,
    runs: int,
    one_run: Callable[[int], tuple[Sequence[float], Sequence[float]] | None],
    *,
    seed0: int = 0,
) -> MonteCarlo:
    """Run ``one_run(seed)`` for ``runs`` seeds (``None``: the estimator failed)."""
    started = time.perf_counter()
    for k in range(runs):
        found = one_run(seed0 + k)
        if found is None:
            result.failures += 1
            continue
        result.add(*found)
    result.wall_s = time.perf_counter() - started
    return result


def markdown(results: Sequence[MonteCarlo]) -> str:
    """The table: one row per estimator, case and parameter."""
    lines = [
        "| estimator | case | parameter | bias | RMSE / CRB | std / CRB | runs | wall s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        for row in r.rows():
            failed = f" ({r.failures} failed)" if r.failures else ""
            if row["runs"] == 0:
                lines.append(
                    f"| {r.estimator} | {r.case} | {row['parameter']} | not found in any run "
                    f"| – | – | 0{failed} | {r.wall_s:.0f} |"
                )
                continue
            unit = row["bias_unit"]
            bias = f"{row['bias']:+.2f} %" if unit == "%" else f"{row['bias']:+.2g} {unit}"
            lines.append(
                f"| {r.estimator} | {r.case} | {row['parameter']} | {bias} | "
                f"{row['rmse_over_crb']:.2f} | {row['std_over_crb']:.2f} | "
                f"{row['runs']}{failed} | {r.wall_s:.0f} |"
            )
    return "\n".join(lines)
