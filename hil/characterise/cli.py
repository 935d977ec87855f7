"""``gimbal-hil characterise``: the method-bias map of a unit type, built by the user.

Draws ``--units`` units of each ``--profile`` across its tolerances
(:mod:`hil.characterise.draw`), calibrates each on the simulator through ``gimbal-hil
calibrate`` (``--jobs`` at once, or on a Dask cluster: ``--scheduler``), compares every
result with the truth of its drawn plant and prints, per result, the bias, the RMS of
``(x − truth)/u`` and the coverage of ±U. ``--write-map`` writes the map these results
show (calibrate with ``--method-bias off`` for that), ``--validate-map`` adds this
population's coverage to a map the calibrations used. Resumable: ``--out`` keeps the drawn
units, the certificates and the population's options; run it again with the same options
and finished units are read back, not calibrated again. The result does not depend on
``--jobs`` or on the cluster: every unit has its own seed and its own process, and the
rows are kept in the units' order.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The subcommand's options (argparse only: ``gimbal-hil --help`` stays fast)."""
    parser.add_argument("--profile", action="append", default=None, metavar="PROFILE",
                        help="unit profile TOML or built-in name, repeatable (default: "
                             "the two demo profiles)")
    parser.add_argument("--units", type=int, default=100, help="units drawn per profile")
    parser.add_argument("--jobs", type=int, default=2,
                        help="calibrations at once on this machine (each is one process)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="run the units on the Dask cluster of this scheduler "
                             "(tcp://HOST:8786; pip install 'gimbal-hil[cluster]'; its "
                             "workers must see --out and the profiles at the same paths) "
                             "instead of --jobs here (default: none)")
    parser.add_argument("--seed", type=int, default=2026, help="the population's seed")
    parser.add_argument("--out", type=Path, default=Path("characterise"),
                        help="folder of the population: units, certificates, summary.json")
    parser.add_argument("--method-bias", default=None, metavar="MAP",
                        help="map the calibrations apply, or 'off' (default: the shipped "
                             "one); 'off' to build a map")
    parser.add_argument("--write-map", type=Path, default=None, metavar="FILE",
                        help="write the method-bias map these results show (default: none)")
    parser.add_argument("--validate-map", type=Path, default=None, metavar="FILE",
                        help="add this population's coverage to the map FILE (a population "
                             "not used to build it; default: none)")


def run(args: argparse.Namespace) -> int:
    """Draw, calibrate, summarise; exit 0 (2 for bad options, before any calibration)."""
    from hil.characterise.session import characterise

    return characterise(args)
