"""Measured and simulated data: sensor series, DIC frames and the files they come in.

* :class:`Measurements` (:mod:`.series`): stretch-sensor time series, NaN where a sample is missing;
* :func:`read_measurements` (:mod:`.csv_file`): a CSV record, checked; :mod:`.csv_stream`: rows of a
  growing CSV or a pipe, one at a time; :class:`ChannelMap` (:mod:`.channels`): a DAQ file's column
  names and each sensor's gain and offset (``stretch = gain * (raw - offset)``); :class:`Acquisition`
  (:mod:`.acquisition`): how the DAQ sampled (point sampling, a digital or analog anti-aliasing filter);
* :class:`DICFrames`, :class:`DICMapping` (:mod:`.dic`): DIC frames in the wing's frame and the map
  from a DIC system's coordinates; :func:`read_dic` (:mod:`.dic_npz`): any DIC layout by its path
  (NPZ, DICe solution files, CSV frames: :mod:`.dic_readers`).
"""

from wingopt.measurements.acquisition import Acquisition
from wingopt.measurements.channels import ChannelMap
from wingopt.measurements.csv_file import CsvReport, read_measurements
from wingopt.measurements.dic import DICFrames, DICMapping, DICReadReport
from wingopt.measurements.dic_npz import read_dic
from wingopt.measurements.series import Measurements

__all__ = [
    "Measurements",
    "read_measurements",
    "CsvReport",
    "ChannelMap",
    "Acquisition",
    "DICFrames",
    "DICMapping",
    "DICReadReport",
    "read_dic",
]
