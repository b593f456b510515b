"""Measured and simulated data: sensor series and the files they come in.

* :class:`Measurements` (:mod:`.series`): stretch-sensor time series, NaN where a sample is missing;
* :func:`read_measurements` (:mod:`.csv_file`): a CSV record, checked; :mod:`.csv_stream`: rows of a
  growing CSV or a pipe, one at a time.
"""

from wingopt.measurements.csv_file import CsvReport, read_measurements
from wingopt.measurements.series import Measurements

__all__ = ["Measurements", "read_measurements", "CsvReport"]
