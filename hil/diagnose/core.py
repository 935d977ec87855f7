"""``diagnose(recording)``: fit the base model, test the residual, name and rank the causes.

Training and held-out data: with ``validate`` the whole first recording trains and the
second judges every gain. Without it the recording is split into interleaved blocks of
0.25 s, every third block held out: a gimbal test run strings different experiments
together (sines, a staircase, a sweep, a chirp), so a plain first-70 %/last-30 % split
would judge on an experiment the fit never saw, while interleaved blocks put a part of
every experiment on both sides.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hil.budget import check_memory
from hil.diagnose import data_issues, interpret
from hil.diagnose.data_issues import DataIssue
from hil.diagnose.effects import reweighted
from hil.diagnose.model import Designer, Fit, IndexArray, Model, base_terms, fit_percent, rms
from hil.diagnose.residual import analyse
from hil.diagnose.ripple import two_stage
from hil.diagnose.select import Candidate, DataSet, Evaluator, Selection, select
from hil.diagnose.signals import Signals, prepare
from hil.errors import IdentificationError
from hil.recording import Recording

log = logging.getLogger(__name__)

BLOCK_S = 0.25
HELDOUT_EVERY = 3
#: A drive holding each torque over the next period with the position sampled mid-period
#: has the effort lead the motion by half a sample (``diagnose(..., hold_samples=0.5)``);
#: by default the lead is estimated in [0, 1] sample (it differs between drives and
#: simulators: this project's simulator needs 0, the shared recordings' 0.5).
HOLD_SAMPLES = 0.5


@dataclass(frozen=True, slots=True, kw_only=True)
class Diagnosis:
    """Everything ``gimbal-hil diagnose`` found (laid out by :func:`report.report`).

    Attributes
    ----------
    recording : Recording
        The log diagnosed.
    signals : Signals
        ``recording`` prepared (see :func:`hil.diagnose.signals.prepare`).
    heldout, train : DataSet
        The rows that judge every gain and the rows every model is fitted on.
    selection : Selection
        The base fit, the causes accepted and every candidate evaluated.
    issues : tuple of DataIssue
        Problems of the data itself (see :func:`hil.diagnose.data_issues.find_issues`).
    residual : dict of str to Any
        Analysis of the base fit's residual over ``recording`` (see
        :func:`hil.diagnose.residual.analyse`).
    split : str
        How training and held-out rows were chosen, in words.
    designer : Designer
        The design-matrix builder the fits used (its caches are kept).
    final : Fit
        The extended model: the last cause's fit, or the base fit when none was named;
        with K_t ripple, fitted in two stages (:func:`hil.diagnose.ripple.two_stage`).
    """

    recording: Recording
    signals: Signals
    heldout: DataSet
    train: DataSet
    selection: Selection
    issues: tuple[DataIssue, ...]
    residual: dict[str, Any]
    split: str
    designer: Designer
    final: Fit

    @property
    def base(self) -> Fit:
        """The base model ``J·α + B·ω + T_c·sgn(ω)`` fitted on the training rows."""
        return self.selection.base

    @property
    def causes(self) -> tuple[Candidate, ...]:
        """The causes named, ranked (:attr:`Selection.accepted`)."""
        return self.selection.accepted

    @property
    def estimation_rows(self) -> tuple[Signals, IndexArray]:
        """The signals and rows a named cause's parameters and intervals are estimated on.

        Every usable row of the recording (training and held-out: the held-out rows judged
        the selection, and then estimate too); with a separate validation recording, the
        training recording's rows.
        """
        if self.heldout.signals is self.train.signals:
            return self.train.signals, np.union1d(self.train.rows, self.heldout.rows)
        return self.train.signals, self.train.rows

    @property
    def cause_names(self) -> list[str]:
        """The effects of :attr:`causes`, in rank order."""
        return [c.effect for c in self.causes]

    def heldout_prediction(self, fit: Fit) -> tuple[np.ndarray, np.ndarray]:
        """Measured (filtered) and predicted effort on the held-out rows.

        Parameters
        ----------
        fit : Fit
            A model fitted on the training rows.

        Returns
        -------
        measured, predicted : ndarray
            ``effort_filtered`` of the held-out signals and ``fit``'s prediction there, on
            the held-out rows (N·m, or N on a linear axis).
        """
        rows = self.heldout.rows
        signals = self.heldout.signals
        return signals.effort_filtered[rows], self.designer.predict(fit, signals)[rows]


def block_split(signals: Signals) -> tuple[DataSet, DataSet]:
    """Interleaved blocks: every third 0.25 s block is held out.

    Parameters
    ----------
    signals : Signals
        The prepared recording.

    Returns
    -------
    train, heldout : DataSet
        Valid, decimated rows (see :meth:`Signals.rows`) outside and inside the held-out
        blocks. A block is 0.25 s, and at least 50 samples.

    Raises
    ------
    IdentificationError
        Either side has fewer than 50 rows.
    """
    length = max(50, round(BLOCK_S * signals.fs_hz))
    held = (np.arange(len(signals)) // length) % HELDOUT_EVERY == HELDOUT_EVERY - 1
    train, test = signals.rows(~held), signals.rows(held)
    if train.size < 50 or test.size < 50:
        raise IdentificationError("recording too short to hold out data for judging gains")
    return DataSet(signals=signals, rows=train), DataSet(signals=signals, rows=test)


# memory per row of a diagnosis (signals, the candidates' design matrices, the fits),
# reading included: maxrss 1072 MB at 100 k rows, 1521 MB at 200 k (4.5 kB/row marginal,
# ~620 MB fixed); stated with margin as 8 kB/row (benchmarks/bench_diagnose_memory.py)
DIAGNOSE_BYTES_PER_ROW = 8192


def check_size(rows: int, source: str) -> None:
    """Refuse a recording too long to diagnose within the memory budget, in one line.

    Raises
    ------
    InputError
        ``rows`` x :data:`DIAGNOSE_BYTES_PER_ROW` exceeds the budget
        (:func:`hil.budget.memory_budget_bytes`).
    """
    check_memory(rows * DIAGNOSE_BYTES_PER_ROW,
                 f"diagnosing {rows:,} rows ({DIAGNOSE_BYTES_PER_ROW:,} B each)", source=source)


def diagnose(
    recording: Recording,
    *,
    validate: Recording | None = None,
    cutoff_hz: float | None = None,
    hold_samples: float | None = None,
) -> Diagnosis:
    """Diagnose ``recording``; with ``validate``, judge every gain on that recording.

    Parameters
    ----------
    recording : Recording
        The measured log to explain.
    validate : Recording, optional
        A second log of the same axis, held out: never fitted. Without it a block split of
        ``recording`` is held out.
    cutoff_hz : float, optional
        Analysis bandwidth (default: an eighth of the sample rate, at most 250 Hz).
    hold_samples : float or None
        How many sample periods the effort leads the motion (0.5: zero-order hold with
        the position sampled mid-period); ``None`` (default) estimates it in [0, 1]
        sample, jointly with τ when a current-loop lag is tried.

    Returns
    -------
    Diagnosis
        The base fit, the causes named (ranked, each with its held-out gain), the residual
        analysis and the data issues; :func:`hil.diagnose.report.report` lays it out.

    Raises
    ------
    IdentificationError
        The data cannot support the fit (too short, too few usable samples), or
        ``validate`` is of another axis kind than ``recording``.
    InputError
        A recording too long for the memory budget (:func:`check_size`).
    """
    for each in (recording, validate):
        if each is not None:
            check_size(len(each), each.source)
    signals = prepare(recording, cutoff_hz=cutoff_hz)
    data_issues.refuse_unusable(signals)
    if validate is not None:
        if validate.axis_kind != recording.axis_kind:
            raise IdentificationError(
                f"{validate.source} is a {validate.axis_kind} axis, "
                f"{recording.source} a {recording.axis_kind} one"
            )
        other = prepare(validate, cutoff_hz=signals.cutoff_hz)
        train, test = DataSet(signals=signals, rows=signals.rows()), DataSet(
            signals=other, rows=other.rows())
        split = f"fit on {recording.source}, judged on {validate.source}"
    else:
        train, test = block_split(signals)
        split = (f"interleaved {BLOCK_S:g} s blocks, every {HELDOUT_EVERY}rd held out "
                 f"({test.rows.size} of {train.rows.size + test.rows.size} rows)")
    issues = data_issues.find_issues(recording, signals)
    designer = Designer()
    evaluator = Evaluator(designer, train, test, data_issues.encoder_counts(issues))
    selection = select(evaluator, Model(terms=base_terms()), hold_samples=hold_samples)
    prediction = designer.predict(selection.base, signals)
    command = recording.velocity_cmd
    if command is not None and len(command) != len(signals):
        command = np.interp(signals.time_s, recording.time_s, command)
    residual = analyse(signals, prediction, velocity_cmd=command)
    log.info("%s: causes %s", recording.source, [c.effect for c in selection.accepted])
    return Diagnosis(recording=recording, signals=signals, heldout=test, train=train,
                     selection=selection, issues=tuple(issues), residual=residual,
                     split=split, designer=designer,
                     final=two_stage(designer, reweighted(designer, selection.final,
                                                          train.signals, train.rows),
                                     train.signals, train.rows))


def summary_metrics(diagnosis: Diagnosis, fit: Fit) -> dict[str, float]:
    """Residual RMS and fit % of ``fit`` on the training and the held-out rows.

    Parameters
    ----------
    diagnosis : Diagnosis
        Gives the rows and the design-matrix builder.
    fit : Fit
        The model to score, e.g. :attr:`Diagnosis.base` or :attr:`Diagnosis.final`.

    Returns
    -------
    dict of str to float
        ``train_rms_nm``, ``train_fit_pct``, ``heldout_rms_nm``, ``heldout_fit_pct``:
        RMS of filtered effort minus prediction (N·m, or N on a linear axis) and
        :func:`hil.diagnose.model.fit_percent` (%).
    """
    out: dict[str, float] = {}
    for name, data in (("train", diagnosis.train), ("heldout", diagnosis.heldout)):
        target = data.signals.effort_filtered[data.rows]
        prediction = diagnosis.designer.predict(fit, data.signals)[data.rows]
        out[f"{name}_rms_nm"] = rms(target - prediction)
        out[f"{name}_fit_pct"] = fit_percent(target, prediction)
    return out


def base_parameters(diagnosis: Diagnosis) -> dict[str, Any]:
    """The base fit's named parameters, their uncertainties and the effort's lead.

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    dict of str to Any
        ``parameters``: ``inertia_kg_m2``, ``viscous_nm_s_rad``, ``coulomb_nm`` and their
        values (see :func:`hil.diagnose.interpret.base_parameters`); ``uncertainty``: each
        one's :meth:`FittedParameter.as_dict`; ``hold_samples``: the base model's
        ``shift_s`` in sample periods.
    """
    estimates = interpret.base_parameters(diagnosis.base)
    return {
        "parameters": {name: e.value for name, e in estimates.items()},
        "uncertainty": {name: e.as_dict() for name, e in estimates.items()},
        "hold_samples": diagnosis.base.model.shift_s * diagnosis.signals.fs_hz,
    }


def finite_or_none(value: float) -> float | None:
    """``value`` if finite, else ``None`` (JSON has no NaN or infinity).

    Parameters
    ----------
    value : float

    Returns
    -------
    float or None
    """
    return value if math.isfinite(value) else None
