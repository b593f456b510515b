"""Results: atomic output directories and files, JSON/CSV writers, plots and reports."""

from wingopt.results.writer import (
    ResultDirectory,
    check_file_writable,
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
]
