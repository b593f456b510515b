"""Results: atomic output directories and files, JSON/CSV writers, plots and reports."""

from wingopt.results.owned import OwnedDirectory
from wingopt.results.writer import (
    ResultDirectory,
    check_file_writable,
    check_new_file,
    check_writable,
    to_jsonable,
    write_arrays_atomic,
    write_atomic,
    write_csv,
    write_json,
    write_json_atomic,
    write_text_atomic,
)

__all__ = [
    "OwnedDirectory",
    "ResultDirectory",
    "check_file_writable",
    "check_writable",
    "to_jsonable",
    "write_arrays_atomic",
    "write_atomic",
    "write_csv",
    "write_json",
    "write_json_atomic",
    "write_text_atomic",
    "check_new_file",
]
