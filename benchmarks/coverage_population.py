"""A population of simulated units, calibrated, against the truth each result claims.

Shared by ``bench_coverage.py`` (the benchmark) and ``tests/test_coverage.py`` (its small
version). A unit is one of the demo profiles with every ``[plant]`` parameter (and the
``[firmware]`` current-loop lag, gains and filter) drawn across its measurement's tolerance
range (parameters without a declared measurement: ±20 %;
``T_s`` as ``T_c·(1.1 … 1.5)``, so that every unit has the Stribeck peak ``v_s`` describes),
every effect on, and its own noise seed. It is calibrated through the command line, as a
test engineer would (``gimbal-hil calibrate --drive sim``), and each certificate result
is compared with the truth of the drawn plant. No identified value is ever read as truth.

Truth map (``truths``): what each result claims to measure, from the plant parameters.
The drive converts current with the nominal K_t, so a torque the shaft feels as ``T`` is
reported as ``T / g`` with ``g = 1 + torque_constant_error_rel``; results identified from
the reported torque are in those units.

=================================  ==========================================================
result                             truth
=================================  ==========================================================
current_loop_time_constant_ms      ``1000·current_loop_time_constant_s`` (``[firmware]``)
gravity_mge_nm                     ``gravity_mge_nm / g``
gravity_phase_rad                  ``gravity_phase_rad``
eccentricity_mm                    ``1000·gravity_mge_nm / (g·mass_kg·9.80665)`` (reported)
cable_stiffness_nm_rad             ``cable_stiffness_nm_rad / g``
cable_hysteresis_nm                ``cable_hysteresis_nm / g``
inertia_kg_m2                      ``(J_motor + J_load + J_elevation·cos²(el)) / g``
viscous_nm_s_rad                   ``viscous_nm_s_rad / g``
coulomb_nm                         ``coulomb_nm / g``
static_friction_nm                 ``static_friction_nm / g`` (the cable loop taken out)
stribeck_velocity_rad_s            ``stribeck_velocity_rad_s``
cogging_peak_nm                    largest cogging amplitude ``/ g``
kt_ripple_peak_pct                 ``100·`` largest K_t ripple amplitude (a ratio: no ``g``)
torque_constant_nm_a               ``torque_constant_nm_a·g`` (the shaft sensor sees true K_t)
reported_torque_gain_error_pct     ``100·(g − 1)``
torque_constant_vs_datasheet_pct   ``100·(torque_constant_nm_a·g / (9.5493/kv) − 1)``
resonance_frequency_hz             two-mass resonance of the drawn shaft (``crb_frf``)
antiresonance_frequency_hz         two-mass anti-resonance
resonance_damping_ratio            two-mass resonance damping
azimuth_inertia_level_kg_m2        ``J_motor + J_load + J_elevation`` (shaft-torque units)
azimuth_inertia_zenith_kg_m2       ``J_motor + J_load``
azimuth_inertia_ratio              level / zenith
=================================  ==========================================================

Results with no truth of the plant's (``inertia_amplitude_spread_pct``,
``torque_linearity_pct``, ``resonance_to_bandwidth_ratio``) are checked by repeatability:
the same unit calibrated with two noise seeds, ``(x₁ − x₂)/√(u₁² + u₂²)``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray
from scipy.optimize import brentq

from hil.compare.budget import Sharing, classify
from hil.compare.certificates import BudgetLine
from hil.profile import builtin_profile_path, load_profile
from plant_sim.params import PlantParams

FloatArray = NDArray[np.float64]
STANDARD_GRAVITY_M_S2 = 9.80665
PROFILES = ("demo_gimbal_elevation", "demo_gimbal_azimuth")
NUISANCE_SPREAD = 0.2  # ± relative spread of plant parameters with no declared measurement
STRIBECK_RISE = (1.1, 1.5)  # T_s / T_c: a peak of 10–50 % (below ~10 % v_s is not defined)

# plant parameter → the measurement whose tolerance sets its spread
MEASURED_BY = {
    "inertia_kg_m2": "inertia_kg_m2",
    "load_inertia_kg_m2": "inertia_kg_m2",
    "viscous_nm_s_rad": "viscous_nm_s_rad",
    "coulomb_nm": "coulomb_nm",
    "static_friction_nm": "static_friction_nm",
    "stribeck_velocity_rad_s": "stribeck_velocity_rad_s",
    "gravity_mge_nm": "gravity_mge_nm",
    "cable_stiffness_nm_rad": "cable_stiffness_nm_rad",
    "current_loop_time_constant_s": "current_loop_time_constant_ms",
    "shaft_stiffness_nm_rad": "antiresonance_frequency_hz",
}
# not varied: they define the station or the experiment, not the unit
FIXED = {"torque_limit_nm", "encoder_counts_per_rev", "elevation_rad", "substeps",
         "exact_torque_hold", "locked_rotor", "position_kp_1_s", "cable_zero_rad",
         "coulomb_neg_nm", "viscous_neg_nm_s_rad", "torque_offset_nm"}
NO_TRUTH = ("inertia_amplitude_spread_pct", "torque_linearity_pct",
            "resonance_to_bandwidth_ratio")


@dataclass(frozen=True, slots=True, kw_only=True)
class Unit:
    """One drawn unit: its profile file, seed and serial."""

    profile_path: Path
    serial: str
    seed: int
    axis: str


def _relative_spread(profile_raw: Mapping[str, Any], measurement: str) -> float:
    spec = profile_raw.get("measurements", {}).get(measurement, {})
    return 0.9 * float(spec.get("tolerance_pct", 100 * NUISANCE_SPREAD)) / 100


def draw_plant(profile_raw: Mapping[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """The ``[plant]`` table of a new unit: every scalar drawn across its range."""
    plant = dict(profile_raw["plant"])
    drawn: dict[str, Any] = {}
    for key, value in plant.items():
        if key in FIXED or isinstance(value, bool):
            drawn[key] = value
        elif key in ("cogging", "kt_ripple"):
            drawn[key] = [
                {**h, "amplitude": h["amplitude"] * rng.uniform(0.4, 1.8),
                 "phase_rad": rng.uniform(-math.pi, math.pi)}
                for h in value
            ]
        elif key == "torque_constant_error_rel":
            drawn[key] = rng.uniform(-0.04, 0.04)
        elif key == "gravity_phase_rad":
            drawn[key] = rng.uniform(-0.08, 0.08)
        elif key == "cable_hysteresis_nm":
            drawn[key] = value * rng.uniform(0.4, 1.8)
        elif isinstance(value, int | float):
            spread = _relative_spread(profile_raw, MEASURED_BY.get(key, ""))
            drawn[key] = value * rng.uniform(1 - spread, 1 + spread)
        else:
            drawn[key] = value
    if "gravity_mge_nm" in drawn and "gravity_phase_rad" not in drawn:
        drawn["gravity_phase_rad"] = rng.uniform(-0.08, 0.08)
    if "static_friction_nm" in drawn:  # v_s exists only with a Stribeck peak above T_c
        drawn["static_friction_nm"] = drawn["coulomb_nm"] * rng.uniform(*STRIBECK_RISE)
    return drawn


# The [firmware] numbers are drawn where the [plant] table held them before they moved
# (after the key named here), so a seed draws the same population as it did then.
DRAWN_AFTER = {"current_loop_time_constant_s": "cable_hysteresis_nm",
               "velocity_filter_hz": "torque_noise_nm",
               "velocity_kp_nm_s_rad": "velocity_filter_hz",
               "velocity_ki_nm_rad": "velocity_kp_nm_s_rad"}


def draw_unit(profile_raw: Mapping[str, Any], rng: np.random.Generator
              ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The ``[plant]`` and ``[firmware]`` tables of a new unit: the plant as
    :func:`draw_plant`, the firmware's current-loop lag across its measurement's tolerance
    and its velocity gains and filter ±20 % (the tuning each drive ships with), its version
    and switches kept."""
    firmware = dict(profile_raw.get("firmware", {}))
    merged: dict[str, Any] = {}
    for key, value in profile_raw["plant"].items():
        merged[key] = value
        for moved, after in DRAWN_AFTER.items():
            if after in merged and moved in firmware and moved not in merged:
                merged[moved] = firmware[moved]
    merged.update({k: v for k, v in firmware.items()
                   if isinstance(v, float) and k not in merged})
    drawn = draw_plant({**profile_raw, "plant": merged}, rng)
    drawn_firmware = {k: drawn.pop(k) if k in drawn else v for k, v in firmware.items()}
    return drawn, drawn_firmware


def write_population(
    directory: Path, *, units_per_profile: int, seed: int, profiles: Sequence[str] = PROFILES
) -> list[Unit]:
    """Draw ``units_per_profile`` units of each profile; one TOML file each."""
    rng = np.random.default_rng(seed)
    directory.mkdir(parents=True, exist_ok=True)
    units = []
    for name in profiles:
        raw = tomllib.loads(builtin_profile_path(name).read_text(encoding="utf-8"))
        for i in range(units_per_profile):
            serial = f"{name.removeprefix('demo_gimbal_')[:3].upper()}-{i:04d}"
            path = directory / f"{serial}.toml"
            plant, firmware = draw_unit(raw, rng)
            drawn = {**raw, "plant": plant, "firmware": firmware}
            path.write_text(tomli_w.dumps(drawn), encoding="utf-8")
            units.append(Unit(profile_path=path, serial=serial, axis=raw["unit"]["axis"],
                              seed=int(rng.integers(1, 2**31 - 1))))
    return units


#: The protocols an earlier result's budget line may name (``… (gravity_cable)``).
PROTOCOLS = ("current_loop", "gravity_cable", "inertia_friction", "cogging", "stribeck",
             "torque_constant", "resonance", "inertia_elevation")
#: The closed-loop protocols measure behaviour with no truth in the plant's parameters;
#: their run-to-run check is ``bench_compare.py`` (same firmware, other seeds). Left out
#: here, they would only add machine time.
MECHANICS_ONLY = ("not (test_velocity_loop_frf or test_velocity_step or test_tracking or "
                  "test_standstill or test_cogging_compensation)")


def calibrate(unit: Unit, out_dir: Path, *, seed: int | None = None,
              method_bias: str | None = None, reuse: bool = False) -> dict[str, dict[str, Any]]:
    """Calibrate one unit through ``gimbal-hil calibrate``; its results by parameter
    (``method_bias``: a map file or ``off``; default the shipped one; ``reuse``: read a
    certificate already in ``out_dir`` instead)."""
    seed = unit.seed if seed is None else seed
    serial = f"{unit.serial}-s{seed}"
    path = out_dir / serial / "certificate.json"
    if reuse and path.is_file():
        return {r["parameter"]: r for r in json.loads(path.read_text("utf-8"))["results"]}
    extra = ["--", "--no-documents", "--store", "off", "-k", MECHANICS_ONLY] + (
        [] if method_bias is None else ["--method-bias", method_bias])
    subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim",
         "--profile", str(unit.profile_path), "--unit-serial", serial,
         "--seed", str(seed), "--out", str(out_dir), *extra],
        capture_output=True, check=False, env={**os.environ, "PYTHONHASHSEED": "0"},
    )
    if not path.is_file():
        return {}
    certificate = json.loads(path.read_text(encoding="utf-8"))
    return {r["parameter"]: r for r in certificate["results"]}


def truths(unit: Unit) -> dict[str, float]:
    """What each result claims to measure, for the drawn plant (module docstring's map)."""
    profile = load_profile(unit.profile_path)
    plant = profile.plant
    assert plant is not None
    g = 1.0 + plant.torque_constant_error_rel
    truth: dict[str, float] = {
        "current_loop_time_constant_ms": 1000 * profile.firmware.current_loop_time_constant_s,
        "gravity_mge_nm": plant.gravity_mge_nm / g,
        "gravity_phase_rad": plant.gravity_phase_rad,
        "cable_stiffness_nm_rad": plant.cable_stiffness_nm_rad / g,
        "cable_hysteresis_nm": plant.cable_hysteresis_nm / g,
        "inertia_kg_m2": _total_inertia(plant, plant.elevation_rad) / g,
        "viscous_nm_s_rad": plant.viscous_nm_s_rad / g,
        "coulomb_nm": plant.coulomb_nm / g,
        "static_friction_nm": plant.static_friction_nm / g,
        "stribeck_velocity_rad_s": plant.stribeck_velocity_rad_s,
        "cogging_peak_nm": max((h.amplitude for h in plant.cogging), default=0.0) / g,
        "kt_ripple_peak_pct": 100 * max((h.amplitude for h in plant.kt_ripple), default=0.0),
        "torque_constant_nm_a": plant.torque_constant_nm_a * g,
        "reported_torque_gain_error_pct": 100 * (g - 1),
    }
    mass_kg = profile.unit.get("mass_kg")
    if isinstance(mass_kg, int | float):
        weight_n = mass_kg * STANDARD_GRAVITY_M_S2
        truth["eccentricity_mm"] = 1000 * truth["gravity_mge_nm"] / weight_n
    kv = profile.unit.get("kv_rpm_per_v")
    if isinstance(kv, int | float):
        datasheet = 60 / (2 * math.pi) / kv
        truth["torque_constant_vs_datasheet_pct"] = 100 * (plant.torque_constant_nm_a * g
                                                           / datasheet - 1)
    if plant.load_inertia_kg_m2 > 0:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from crb_frf import two_mass_truth

        model = two_mass_truth(
            plant, time_constant_s=profile.firmware.current_loop_time_constant_s)
        truth["resonance_frequency_hz"] = model.resonance_hz
        truth["antiresonance_frequency_hz"] = model.antiresonance_hz
        truth["resonance_damping_ratio"] = model.resonance_damping
    if plant.inertia_elevation_kg_m2 > 0:
        level, zenith = _total_inertia(plant, 0.0), _total_inertia(plant, math.pi / 2)
        truth["azimuth_inertia_level_kg_m2"] = level
        truth["azimuth_inertia_zenith_kg_m2"] = zenith
        truth["azimuth_inertia_ratio"] = level / zenith
    return {k: v for k, v in truth.items() if k in profile.measurements}


def _total_inertia(plant: PlantParams, elevation_rad: float) -> float:
    return (plant.inertia_kg_m2 + plant.load_inertia_kg_m2
            + plant.inertia_elevation_kg_m2 * math.cos(elevation_rad) ** 2)


@dataclass(frozen=True, slots=True, kw_only=True)
class Row:
    """One result of one calibrated unit against its truth."""

    unit: str
    axis: str
    parameter: str
    value: float
    truth: float
    standard_uncertainty: float
    expanded_uncertainty: float

    @property
    def normalised_error(self) -> float:
        return (self.value - self.truth) / self.standard_uncertainty

    @property
    def covered(self) -> bool:
        return abs(self.value - self.truth) <= self.expanded_uncertainty


@dataclass(frozen=True, slots=True, kw_only=True)
class Summary:
    """Per result: how the stated uncertainty describes the errors over the population."""

    axis: str
    parameter: str
    n: int
    relative: bool  # bias and median_u as fractions of the truth (else in the result's unit)
    bias: float  # mean (x − truth)
    rms_normalised: float
    coverage: float
    median_u: float
    coverage_interval: tuple[float, float]  # Wilson 95 % for the coverage over n units
    rms_interval: tuple[float, float]  # 95 %, from the mean of z² and its standard error


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % interval of a proportion (Wilson score): what ``n`` units can tell of it."""
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def rms_interval(normalised: FloatArray, z: float = 1.96) -> tuple[float, float]:
    """95 % interval of the RMS of ``normalised`` (normal approximation for the mean of
    its squares, with their own scatter: heavy tails widen it)."""
    squares = normalised**2
    mean = float(np.mean(squares))
    error = float(np.std(squares, ddof=1)) / math.sqrt(len(squares)) if len(squares) > 1 else 0
    return math.sqrt(max(mean - z * error, 0.0)), math.sqrt(mean + z * error)


def errors_of(group: Sequence[Row]) -> tuple[bool, FloatArray, FloatArray]:
    """Errors ``x − truth`` and stated ``u``, relative to the truth when every truth is
    positive, else absolute: ``(relative, errors, u)``."""
    truth = np.array([r.truth for r in group])
    relative = bool(np.all(truth > 0))
    scale = truth if relative else np.ones_like(truth)
    errors = (np.array([r.value for r in group]) - truth) / scale
    return relative, errors, np.array([r.standard_uncertainty for r in group]) / scale


def by_result(rows: Iterable[Row]) -> dict[tuple[str, str], list[Row]]:
    """Rows grouped by (axis, result)."""
    groups: dict[tuple[str, str], list[Row]] = {}
    for row in rows:
        groups.setdefault((row.axis, row.parameter), []).append(row)
    return dict(sorted(groups.items()))


def run_population(units: Sequence[Unit], out_dir: Path, *, workers: int = 2,
                   method_bias: str | None = None, reuse: bool = False) -> list[Row]:
    """Calibrate every unit (``workers`` at a time); one row per result with a truth."""

    def one(unit: Unit) -> list[Row]:
        results = calibrate(unit, out_dir, method_bias=method_bias, reuse=reuse)
        truth = truths(unit)
        return [
            Row(unit=unit.serial, axis=unit.axis, parameter=name, value=float(r["value"]),
                truth=truth[name], standard_uncertainty=float(r["standard_uncertainty"]),
                expanded_uncertainty=float(r["expanded_uncertainty"]))
            for name, r in results.items() if name in truth and r["standard_uncertainty"]
        ]

    with ThreadPoolExecutor(max_workers=workers) as pool:
        return [row for rows in pool.map(one, units) for row in rows]


def summarise(rows: Iterable[Row]) -> list[Summary]:
    """Bias, RMS normalised error and coverage per axis and result."""
    summaries = []
    for (axis, name), group in by_result(rows).items():
        relative, errors, u = errors_of(group)
        covered = sum(r.covered for r in group)
        summaries.append(Summary(
            axis=axis, parameter=name, n=len(group), relative=relative,
            bias=float(np.mean(errors)),
            rms_normalised=float(np.sqrt(np.mean((errors / u) ** 2))),
            coverage=covered / len(group),
            median_u=float(np.median(u)),
            coverage_interval=wilson_interval(covered, len(group)),
            rms_interval=rms_interval(errors / u),
        ))
    return summaries


def repeatability(first: Mapping[str, Mapping[str, Any]],
                  second: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
    """``(x₁ − x₂)/√(u₁² + u₂²)`` per result of the same unit under two noise seeds, each
    ``u`` the part of its budget that differs between two runs of one unit
    (:func:`seed_part`)."""
    return {
        name: (float(a["value"]) - float(second[name]["value"]))
        / math.hypot(seed_part(a), seed_part(second[name]))
        for name, a in first.items()
        if name in second and seed_part(a) > 0
    }


def seed_part(result: Mapping[str, Any]) -> float:
    """The part of a result's ``u`` that a second run of the same unit draws anew: its Type A
    lines and the earlier protocols' results measured again (``gimbal-hil compare``'s
    rule); the method's scatter over units, a model's misfit to the unit and resolutions
    repeat, so a rerun cannot check them."""
    lines = result.get("budget") or []
    if not lines:
        return float(result["standard_uncertainty"])
    kept = [line for line in lines if classify(BudgetLine(
        source=line["component"], kind=line["type"],
        standard_uncertainty=float(line["standard_uncertainty"]),
        sensitivity=float(line["sensitivity"]), dof=math.inf,
    ), protocols=PROTOCOLS)[0] is Sharing.INDEPENDENT]
    return math.sqrt(sum(float(line["contribution"]) ** 2 for line in kept))


def bias_map(rows: Iterable[Row], *, population: str) -> dict[str, Any]:
    """The method-bias map (``fixtures/method_bias.toml``) the rows show, per axis.

    Per result, with errors ``e`` relative to the truth when every truth is positive (else
    absolute) and the stated (Type A) ``u``: the scatter ``s`` beyond what ``u`` covers is
    the maximum-likelihood one, ``mean((e − b)²/(u² + s²)) = 1`` (zero when the stated
    ``u`` already covers the errors), the bias ``b`` the mean of ``e`` weighted by
    ``1/(u² + s²)``; the bias's own standard error is added to ``s``. Units whose ``u``
    differs a lot (an ill-determined cable loop) then count by their own ``u``, which a
    moment estimate ``var(e) − mean(u²)`` would not do. Computed on results calibrated
    with ``--method-bias off``.
    """
    results: dict[str, dict[str, Any]] = {}
    for (axis, name), group in by_result(rows).items():
        relative, errors, u = errors_of(group)
        bias, scatter = float(np.mean(errors)), 0.0
        for _ in range(20):
            scatter = _excess_scatter(errors - bias, u)
            weights = 1 / (u**2 + scatter**2)
            bias = float(np.sum(weights * errors) / np.sum(weights))
        results.setdefault(axis, {})[name] = {
            "scale": "relative" if relative else "absolute",
            "bias": bias,
            "scatter": math.hypot(scatter, 1 / math.sqrt(float(np.sum(weights)))),
            "units": len(group),
        }
    return {"population": population, "results": results}


def with_validation(document: Mapping[str, Any], summaries: Iterable[Summary]
                    ) -> dict[str, Any]:
    """The map ``document`` with each result's coverage on this (out-of-sample)
    population: ``validated_coverage`` and ``validated_units`` (notes are kept)."""
    results = {axis: {name: dict(entry) for name, entry in table.items()}
               for axis, table in document["results"].items()}
    for s in summaries:
        entry = results.get(s.axis, {}).get(s.parameter)
        if entry is not None:
            entry["validated_coverage"] = round(s.coverage, 4)
            entry["validated_units"] = s.n
    return {**document, "results": results}


def _excess_scatter(errors: FloatArray, u: FloatArray) -> float:
    """``s ≥ 0`` with ``mean(e²/(u² + s²)) = 1``."""

    def excess(s: float) -> float:
        return float(np.mean(errors**2 / (u**2 + s**2))) - 1.0

    if excess(0.0) <= 0:
        return 0.0
    high = float(np.sqrt(np.mean(errors**2))) + 1e-300
    return float(brentq(excess, 0.0, high))
