"""Closed-loop numerics: what a firmware change changes (frequency response and margins,
step response, tracking, standstill, cogging compensation). Pure: no I/O, no drives."""
