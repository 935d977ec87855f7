"""Calibration certificate: built from a :class:`hil.calibration.CalibrationRun`, written as
JSON (machine-readable) and text (human-readable) next to the raw recordings."""

from hil.certificate.build import build_certificate, write_certificate

__all__ = ["build_certificate", "write_certificate"]
