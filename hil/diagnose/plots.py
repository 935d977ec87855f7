"""PNG plots of a diagnosis (matplotlib, Agg backend; imported only for ``--plots``)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hil.errors import InputError

if TYPE_CHECKING:
    from hil.diagnose.core import Diagnosis


def write_plots(diagnosis: Diagnosis, directory: str | Path) -> list[Path]:
    """Residual time series, against position and velocity, spectrum, correlations.

    Parameters
    ----------
    diagnosis : Diagnosis
    directory : str or Path
        Created when missing.

    Returns
    -------
    list of Path
        ``residual_time.png``, ``residual_vs_position.png``, ``residual_vs_velocity.png``,
        ``residual_spectrum.png`` and ``residual_correlations.png`` in ``directory``.

    Raises
    ------
    InputError
        matplotlib is not installed.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - matplotlib is an optional extra
        raise InputError("--plots needs matplotlib (pip install gimbal-hil[plots])") from exc
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    signals = diagnosis.signals
    unit = "N·m" if signals.axis_kind == "rotary" else "N"
    base = diagnosis.designer.predict(diagnosis.base, signals)
    final = diagnosis.designer.predict(diagnosis.final, signals)
    valid = signals.valid
    residual_base = np.where(valid, signals.effort_filtered - base, np.nan)
    residual_final = np.where(valid, signals.effort_filtered - final, np.nan)
    written: list[Path] = []

    def save(fig: object, name: str) -> None:
        path = out / name
        fig.savefig(path, dpi=90)  # type: ignore[attr-defined]
        plt.close(fig)  # type: ignore[arg-type]
        written.append(path)

    label = "with " + ", ".join(diagnosis.cause_names) if diagnosis.causes else "(no cause)"
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    axes[0].plot(signals.time_s, signals.effort_filtered, lw=0.6, label="measured (filtered)")
    axes[0].plot(signals.time_s, base, lw=0.6, label="base model")
    axes[0].set_ylabel(f"effort [{unit}]")
    axes[0].legend(loc="upper right")
    axes[1].plot(signals.time_s, residual_base, lw=0.5, label="residual, base model")
    axes[1].plot(signals.time_s, residual_final, lw=0.5, label=f"residual, {label}")
    axes[1].set_xlabel("time [s]")
    axes[1].set_ylabel(f"residual [{unit}]")
    axes[1].legend(loc="upper right")
    save(fig, "residual_time.png")

    for key, xlabel, name in (
        ("against_position", f"position [{'rad' if unit == 'N·m' else 'm'}]",
         "residual_vs_position.png"),
        ("against_velocity", "velocity", "residual_vs_velocity.png"),
    ):
        source = signals.position if key == "against_position" else signals.velocity
        fig, ax = plt.subplots(figsize=(9, 4.5))
        ax.plot(source[valid], residual_base[valid], ",", alpha=0.3, label="samples")
        binned = diagnosis.residual[key]
        ax.plot(binned["centre"], binned["mean"], "k-", lw=1.5, label="bin mean")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"base-model residual [{unit}]")
        ax.legend(loc="upper right")
        save(fig, name)

    spectrum = diagnosis.residual["spectrum"]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    ax.semilogy(spectrum["frequency_hz"], spectrum["psd"], lw=0.8)
    for peak in spectrum["peaks_hz"]:
        ax.axvline(peak, color="r", lw=0.5, alpha=0.5)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel(f"residual PSD [{unit}²/Hz]")
    save(fig, "residual_spectrum.png")

    tests = diagnosis.residual["tests"]
    fig, axes = plt.subplots(2, 1, figsize=(9, 6))
    bound = tests["bound_99"]
    for ax, key, title in ((axes[0], "autocorrelation", "autocorrelation of residual"),
                           (axes[1], "cross_correlation",
                            f"cross-correlation with {tests['cross_correlation']['input']}")):
        ax.stem(tests[key]["lags"], tests[key]["values"])
        ax.axhline(bound, color="r", lw=0.8)
        ax.axhline(-bound, color="r", lw=0.8)
        ax.set_title(title + " (99 % bounds)")
    axes[1].set_xlabel("lag [samples after decimation]")
    fig.tight_layout()
    save(fig, "residual_correlations.png")
    return written
