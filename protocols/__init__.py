"""The calibration suite: one pytest module per identification protocol.

Each module holds a frozen ``Spec`` read from the unit profile, a pure ``excitation(spec)``,
a pure ``analyse(recordings, spec)``, the names of its declared measurements, and a short
test that runs it on the ``drive`` fixture and records the judged results.
"""
