"""The calibration suite's library: per protocol, its spec (read from the unit profile),
its excitation and its analysis; ``protocols/test_*.py`` hold only the tests."""
