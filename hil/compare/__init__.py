"""``gimbal-hil compare``: a baseline calibration against a candidate (firmware regression).

Pure functions over certificate JSON: :mod:`certificates` reads and checks them,
:mod:`budget` keeps only what the two runs do not share, :mod:`statistics` holds the
Student-t and Holm procedures, :mod:`verdict` judges each result, :mod:`report` prints it.
"""

from hil.compare.certificates import Certificate, load_side, read_certificate
from hil.compare.verdict import Comparison, Row, Verdict, compare_sides

__all__ = ["Certificate", "Comparison", "Row", "Verdict", "compare_sides", "load_side",
           "read_certificate"]
